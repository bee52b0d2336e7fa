"""Sim-to-real effects (docs/formats.md): a registry of named augmentations of a nominal rig.

Each effect is one :class:`Effect` entry that knows everything the rest of flexmodal needs about it: the
locations where it applies on a :class:`~models.rig.Rig`, its parameters with units and bounds, how it
turns the rig into a new one (``apply``), the fit parameters of the gap diagnosis (bounds and start grid
scaled to the rig, each driving one *handle*), the handles it brings to the fast parameter-linear solver
(compare/parametric.py) with their matrices (``rows``: ``K_h = R^T R``, or a unit change of the rig) and
the zero-valued slots it needs in that solver's super rig.  The diagnosis, its candidates, the parametric
model and the simulators all read :data:`REGISTRY`; a new effect is one :func:`register_effect` call.

The built-in library (SI units):

==========================  ================================  ==========================================
effect                      locations                         params
==========================  ================================  ==========================================
``joint_stiffness``         rigid/spring joints               ``k_Nm_per_rad``
``joint_stiffness_pose``    rigid/spring joints with a pose   ``k_Nm_per_rad`` (at pose 0) and the log-law
                            variable                          ``log_slope_per_rad``, ``log_curv_per_rad2``
``joint_mass``              joints (+ ``base`` when the base  ``mass_kg``, ``inertia_kgm2``
                            is not clamped: the hub)
``tip_mass``                ``tip``                           ``mass_kg``, ``inertia_kgm2``
``base_stiffness``          ``base`` (clamped/pinned/spring)  ``k_Nm_per_rad``
``end_restraint``           members with a pinned end         ``k_Nm_per_rad`` (each pinned end)
``sensor_mass``             ``sensors`` (all, equal masses)   ``mass_kg`` (per sensor)
``grounded_spring``         ``<link>@<fraction>`` points      ``k_N_per_m`` (transverse to the link)
``link_stiffness``          link names                        ``scale`` (on EI and EA)
``link_mass``               link names                        ``scale`` (on mass and rotary inertia per m)
==========================  ================================  ==========================================

Added masses, springs and sensor masses are *added* to what the rig already has; link scales multiply the
rig's own scales; spring joints and the base spring *replace* the nominal connection.  The pose-dependent
joint stiffness follows ``k(q) = k0 exp(a1 q + a2 q^2)`` with ``q`` the joint angle in radians, a smooth
positive law (log-quadratic) that reduces to a constant stiffness when ``a1 = a2 = 0``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from flexmodal.checked_io.registry import Registry
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import Mass, Point, Rig, Spring

if TYPE_CHECKING:
    from flexmodal.models.frame import FrameSystem

GROUNDED_SPRING_FRACTIONS = (0.25, 0.5, 0.75, 1.0)
"""Candidate points along every link where a grounded spring is tried."""
POSE_LAW_BOUND = 3.0
"""Bound on the pose law's log-slope [1/rad] and log-curvature [1/rad^2] in the diagnosis fit."""
LINK_SCALE_MIN = 1 / 3
"""Link stiffness/mass scales are searched in [1/3, 3]: a parameter error, not a different link."""
RIGID_FACTOR = 1e7
"""A rigid joint or clamp is a spring of ``RIGID_FACTOR * EI / L`` in the fast solver's super rig."""


@dataclass(frozen=True)
class EffectParam:
    """One parameter of an effect: name, SI unit, admissible range and default (None: required)."""

    name: str
    unit: str
    lower: float = 0.0
    upper: float = math.inf
    default: float | None = None


@dataclass(frozen=True)
class Handle:
    """One linear parameter of the fast frame model: ``kind`` is ``K`` (stiffness) or ``M`` (mass).

    ``nominal`` is its value in the nominal rig (SI; link scales are multipliers, nominal 1), ``slot`` its
    value in the super rig (compare/parametric.py) and ``effect`` the registry entry that builds its
    matrices.
    """

    name: str          # e.g. "k@elbow", "m@tip", "EI@link2"
    kind: str          # "K" or "M"
    nominal: float
    effect: str = ""
    slot: float = 0.0

    @property
    def location(self) -> str:
        return self.name.partition("@")[2]


@dataclass(frozen=True)
class Param:
    """One fitted parameter: its reported name, the handle it drives, bounds of theta and start grid.

    ``power`` 0: theta is log h; 1/2: a pose-law slope/curvature multiplying q^power (q: the angle of the
    handle's joint in rad).
    """

    effect: str
    name: str             # an EffectParam name, e.g. "k_Nm_per_rad"
    handle: str           # handle name, e.g. "k@elbow"
    power: int
    lower: float          # bounds on theta
    upper: float
    grid: tuple[float, ...]


def _no_slots(rig: Rig, srig: Rig) -> Rig:
    return srig


def _always(rig: Rig, location: str, pose_values: Mapping[str, Sequence[float]]) -> bool:
    return True


@dataclass(frozen=True)
class Effect:
    """A registry entry: everything flexmodal knows about one unmodelled effect.

    * ``locations(rig)``: where it applies (empty: not on this rig);
    * ``apply(rig, location, values, pose)``: the augmented rig, ``values`` checked against ``params``;
    * ``fit(rig, location)``: the diagnosis' fit parameters (:class:`Param`, bounds scaled to the rig);
    * ``handles(rig)``: the fast solver's handles it owns (a handle another entry owns is shared by name);
    * ``rows(system, srig, handle)``: R with ``K_h`` (or ``M_h``) ``= R^T R`` on the super rig's system, or
      None with ``unit_change`` set: then ``K_h`` is the assembly of ``unit_change(srig, location)`` minus the
      super rig's;
    * ``slots(rig, srig)``: the super rig with this effect's slots added at the handles' ``slot`` values;
    * ``region``: the ``where.region`` kind of its locations (``""``: the kind of the named part);
    * ``offered(rig, location, pose_values)``: whether the diagnosis tries it there for these poses;
    * ``refines``: an effect this one generalises at the same location; it is ranked below that one
      unless better held out;
    * ``per_config(rig, location, values, pose)``: pose-dependent values the verdict lists per config;
    * ``draw(rig, location, strength, rng)``: parameters of a hidden instance for the blind self-check
      (fixtures/blind.py), ``strength`` in [0, 1] from a weak to a strong change; None: not hidden there.
    """

    name: str
    params: tuple[EffectParam, ...]
    locations: Callable[[Rig], list[str]]
    apply: Callable[[Rig, str, Mapping[str, float], Mapping[str, float] | None], Rig]
    fit: Callable[[Rig, str], tuple[Param, ...]]
    handles: Callable[[Rig], list[Handle]] = lambda rig: []
    rows: Callable[[FrameSystem, Rig, Handle], np.ndarray | None] = lambda system, srig, handle: None
    unit_change: Callable[[Rig, str], Rig] | None = None
    slots: Callable[[Rig, Rig], Rig] = _no_slots
    region: str = ""
    offered: Callable[[Rig, str, Mapping[str, Sequence[float]]], bool] = _always
    refines: str = ""
    per_config: Callable[[Rig, str, Mapping[str, float], Mapping[str, float]], dict[str, float]] | None = None
    draw: Callable[[Rig, str, float, np.random.Generator], dict[str, float]] | None = None


REGISTRY: Registry[Effect] = Registry("effect", ModelError)
"""Effects by name, in registration order (the order of candidates, handles and ``all``)."""


def register_effect(effect: Effect) -> Effect:
    """Add ``effect`` to :data:`REGISTRY` (a name already registered is replaced in place)."""
    return REGISTRY.register(effect.name, effect)


def unregister_effect(name: str) -> None:
    """Remove the effect ``name`` from :data:`REGISTRY`."""
    REGISTRY.unregister(name)


def registered_effects() -> tuple[str, ...]:
    """Names of every registered effect, in registration order."""
    return REGISTRY.names()


def get_effect(name: str) -> Effect:
    """The registry entry of ``name``; ModelError naming the known effects otherwise."""
    return REGISTRY.entry(name)


def effect_locations(rig: Rig, effect: str) -> list[str]:
    """Locations (docs/formats.md) where ``effect`` applies on ``rig``; empty when it does not apply."""
    return list(get_effect(effect).locations(rig))


def effect_values(effect: Effect, params: Mapping[str, float]) -> dict[str, float]:
    """``params`` checked against ``effect.params`` (defaults filled in); ModelError naming a bad one."""
    out = {}
    for p in effect.params:
        if p.name not in params:
            if p.default is None:
                raise ModelError(f"effect {effect.name!r}: missing parameter {p.name!r} [{p.unit}]")
            out[p.name] = p.default
            continue
        value = float(params[p.name])
        if not (math.isfinite(value) and p.lower <= value <= p.upper):
            span = f">= {p.lower:g}" if p.upper == math.inf else f"in [{p.lower:g}, {p.upper:g}]"
            raise ModelError(f"effect {effect.name!r}: parameter {p.name!r} must be finite and {span} "
                             f"(got {value!r})")
        out[p.name] = value
    return out


def apply_effect(rig: Rig, effect: str, location: str, params: Mapping[str, float],
                 pose: Mapping[str, float] | None = None) -> Rig:
    """Return a copy of ``rig`` with ``effect`` added at ``location`` (see the module table).

    ``pose`` is needed only by ``joint_stiffness_pose`` with a non-zero law slope/curvature: the
    stiffness is evaluated at the joint's angle in that pose.  Raises ModelError naming a location the
    effect does not apply to or a missing/invalid parameter.
    """
    entry = get_effect(effect)
    where = entry.locations(rig)
    if location not in where:
        raise ModelError(f"effect {effect!r} does not apply at {location!r} on {rig.source} "
                         f"(locations: {', '.join(where) or 'none'})")
    return entry.apply(rig, location, effect_values(entry, params), pose)


def pose_stiffness(params: Mapping[str, float], angle_deg: float) -> float:
    """Joint stiffness [N m/rad] of the ``joint_stiffness_pose`` law at a joint angle in degrees."""
    q = math.radians(angle_deg)
    a1 = params.get("log_slope_per_rad", 0.0)
    a2 = params.get("log_curv_per_rad2", 0.0)
    return float(params["k_Nm_per_rad"]) * math.exp(a1 * q + a2 * q * q)


# ---- helpers shared by the entries -----------------------------------------------------------------


def _joint_index(rig: Rig, location: str) -> int:
    return [j.name for j in rig.joints].index(location)


def _replace_at(items: tuple, index: int, new: object) -> tuple:
    return items[:index] + (new,) + items[index + 1:]


def _arm_mass_kg(rig: Rig) -> float:
    return sum(lk.section.mass_per_m_kg * lk.mass_scale * lk.length_m for lk in rig.links)


def log_range(ref: float, lo: float, hi: float, n: int) -> tuple[float, float, tuple[float, ...]]:
    """Bounds ``log(ref*lo)``, ``log(ref*hi)`` of a log-space fit parameter and ``n`` inner start values."""
    a, b = math.log(ref * lo), math.log(ref * hi)
    inner = np.linspace(a, b, n + 2)[1:-1]
    return a, b, tuple(float(x) for x in inner)


def _ei_over_l(rig: Rig, link_name: str) -> float:
    lk = rig.link(link_name)
    return lk.section.EI_Nm2 * lk.stiffness_scale / lk.length_m


def _rigid(rig: Rig, link_name: str) -> float:
    """The stiffness [N m/rad] standing in for a rigid joint or clamp: ``RIGID_FACTOR`` EI/L of the link."""
    link = rig.link(link_name)
    return RIGID_FACTOR * link.section.EI_Nm2 * link.stiffness_scale / link.length_m



K_PARAM = EffectParam("k_Nm_per_rad", "N m/rad")
MASS_PARAMS = (EffectParam("mass_kg", "kg"), EffectParam("inertia_kgm2", "kg m^2", default=0.0))


# ---- joint stiffness (constant and pose law) ---------------------------------------------------------


def _spring_joint(rig: Rig, location: str, values: Mapping[str, float], pose: Mapping[str, float] | None,
                  effect: str) -> Rig:
    i = _joint_index(rig, location)
    joint = rig.joints[i]
    k = values["k_Nm_per_rad"]
    if values.get("log_slope_per_rad") or values.get("log_curv_per_rad2"):
        if pose is None or joint.angle not in pose:
            raise ModelError(f"effect {effect!r} at {location!r} needs the pose value of {joint.angle!r}")
        k = pose_stiffness(values, float(pose[joint.angle]))
    return replace(rig, joints=_replace_at(rig.joints, i, replace(joint, kind="spring", k_Nm_per_rad=k)))


def _joint_k_param(rig: Rig, effect: str, location: str) -> Param:
    k = log_range(_ei_over_l(rig, rig.joint(location).child), 1e-3, 1e5, 9)
    return Param(effect, "k_Nm_per_rad", f"k@{location}", 0, *k)


def _joint_handles(rig: Rig) -> list[Handle]:
    out = []
    for name in effect_locations(rig, "joint_stiffness"):
        j = rig.joint(name)
        k = float(j.k_Nm_per_rad) if j.kind == "spring" else _rigid(rig, j.child)
        out.append(Handle(f"k@{name}", "K", k, "joint_stiffness"))
    return out


def _joint_slots(rig: Rig, srig: Rig) -> Rig:
    return replace(srig, joints=tuple(replace(j, kind="spring", k_Nm_per_rad=0.0) if j.kind != "pin" else j
                                      for j in srig.joints))


register_effect(Effect(
    "joint_stiffness", (K_PARAM,),
    locations=lambda rig: [j.name for j in rig.joints if j.kind != "pin"],
    apply=lambda rig, loc, v, pose: _spring_joint(rig, loc, v, pose, "joint_stiffness"),
    fit=lambda rig, loc: (_joint_k_param(rig, "joint_stiffness", loc),),
    handles=_joint_handles,
    rows=lambda system, srig, h: system.joint_rotation(h.location)[None],
    slots=_joint_slots,
    draw=lambda rig, loc, s, rng: {"k_Nm_per_rad": _ei_over_l(rig, rig.links[-1].name)
                                   * 10 ** (2.0 - 2.5 * s)},
))


def _pose_fit(rig: Rig, location: str) -> tuple[Param, ...]:
    law = [Param("joint_stiffness_pose", name, f"k@{location}", p, -POSE_LAW_BOUND, POSE_LAW_BOUND, (0.0,))
           for p, name in ((1, "log_slope_per_rad"), (2, "log_curv_per_rad2"))]
    return (_joint_k_param(rig, "joint_stiffness_pose", location), *law)


def _pose_offered(rig: Rig, location: str, pose_values: Mapping[str, Sequence[float]]) -> bool:
    """The pose law is only tried where the joint angle takes >= 3 distinct values."""
    return len(set(pose_values.get(rig.joint(location).angle, ()))) >= 3


register_effect(Effect(
    "joint_stiffness_pose",
    (K_PARAM, EffectParam("log_slope_per_rad", "1/rad", -math.inf, math.inf, 0.0),
     EffectParam("log_curv_per_rad2", "1/rad^2", -math.inf, math.inf, 0.0)),
    locations=lambda rig: [j.name for j in rig.joints if j.kind != "pin" and j.angle],
    apply=lambda rig, loc, v, pose: _spring_joint(rig, loc, v, pose, "joint_stiffness_pose"),
    fit=_pose_fit,                    # drives the joint_stiffness handle k@<joint>
    offered=_pose_offered,
    refines="joint_stiffness",
    per_config=lambda rig, loc, v, pose: {"k_Nm_per_rad": pose_stiffness(v, pose[rig.joint(loc).angle])},
))


# ---- added masses (joints, hub, tip) ----------------------------------------------------------------


def _mass_point(rig: Rig, location: str) -> Point:
    if location == "base":
        return Point(rig.links[0].name, 0.0)
    if location == "tip":
        return Point(rig.links[-1].name, 1.0)
    return Point(rig.joint(location).child, 0.0)


def _add_mass(effect: str) -> Callable[[Rig, str, Mapping[str, float], Mapping[str, float] | None], Rig]:
    def apply(rig: Rig, location: str, values: Mapping[str, float], pose: Mapping[str, float] | None) -> Rig:
        mass = Mass(_mass_point(rig, location), values["mass_kg"], values["inertia_kgm2"],
                    name=f"{effect}@{location}")
        return replace(rig, masses=rig.masses + (mass,))
    return apply


def _mass_fit(effect: str) -> Callable[[Rig, str], tuple[Param, ...]]:
    def fit(rig: Rig, location: str) -> tuple[Param, ...]:
        arm_m = _arm_mass_kg(rig)
        arm_L = sum(lk.length_m for lk in rig.links)
        m = log_range(arm_m, 1e-4, 10.0, 7)
        J = log_range(arm_m * arm_L**2, 1e-7, 1.0, 4)
        return (Param(effect, "mass_kg", f"m@{location}", 0, *m),
                Param(effect, "inertia_kgm2", f"J@{location}", 0, *J))
    return fit


def _mass_handles(effect: str) -> Callable[[Rig], list[Handle]]:
    return lambda rig: [Handle(f"{q}@{loc}", "M", 0.0, effect) for loc in effect_locations(rig, effect)
                        for q in ("m", "J")]


def _mass_rows(system: FrameSystem, srig: Rig, handle: Handle) -> np.ndarray:
    loc = handle.location
    at = f"{srig.links[0].name}@0" if loc == "base" else loc
    if handle.name.startswith("m@"):
        return np.array([system.observe(at, "x"), system.observe(at, "y")])
    return system.observe(at, "rotation")[None]


def _mass_slots(effect: str) -> Callable[[Rig, Rig], Rig]:
    def slots(rig: Rig, srig: Rig) -> Rig:
        new = tuple(Mass(rig.point_of(loc) if loc != "base" else rig.point_of(f"{rig.links[0].name}@0"), 0.0,
                         0.0, name=f"slot@{loc}") for loc in effect_locations(rig, effect))
        return replace(srig, masses=srig.masses + new)
    return slots


def _mass_draw(rig: Rig, location: str, strength: float, rng: np.random.Generator) -> dict[str, float]:
    m = _arm_mass_kg(rig) * 10 ** (-1.5 + 1.5 * strength)
    return {"mass_kg": m, "inertia_kgm2": m * 0.02**2}


def _mass_effect(effect: str, locations: Callable[[Rig], list[str]]) -> Effect:
    return Effect(effect, MASS_PARAMS, locations=locations, apply=_add_mass(effect), fit=_mass_fit(effect),
                  handles=_mass_handles(effect), rows=_mass_rows, slots=_mass_slots(effect), draw=_mass_draw)


register_effect(_mass_effect(
    "joint_mass",
    lambda rig: (["base"] if rig.base.support != "clamped" else []) + [j.name for j in rig.joints]))
register_effect(_mass_effect("tip_mass", lambda rig: ["tip"]))


# ---- base and member end springs ---------------------------------------------------------------------


def _base_handles(rig: Rig) -> list[Handle]:
    if not effect_locations(rig, "base_stiffness"):
        return []
    b = rig.base
    nominal = {"clamped": _rigid(rig, rig.links[0].name), "pinned": 0.0}.get(
        b.support, b.k_Nm_per_rad or 0.0)
    return [Handle("k@base", "K", float(nominal), "base_stiffness")]


register_effect(Effect(
    "base_stiffness", (K_PARAM,),
    locations=lambda rig: ["base"] if rig.base.support in ("clamped", "pinned", "spring") else [],
    apply=lambda rig, loc, v, pose: replace(rig, base=replace(rig.base, support="spring",
                                                                 k_Nm_per_rad=v["k_Nm_per_rad"])),
    fit=lambda rig, loc: (Param("base_stiffness", "k_Nm_per_rad", "k@base", 0,
                                *log_range(_ei_over_l(rig, rig.links[0].name), 1e-3, 1e5, 9)),),
    handles=_base_handles,
    rows=lambda system, srig, h: system.observe(f"{srig.links[0].name}@0", "rotation")[None],
    slots=lambda rig, srig: replace(srig, base=replace(srig.base, support="spring", k_Nm_per_rad=0.0))
    if effect_locations(rig, "base_stiffness") else srig,
    draw=lambda rig, loc, s, rng: {"k_Nm_per_rad": _ei_over_l(rig, rig.links[0].name)
                                   * 10 ** (2.0 - 2.0 * s)},
))


def _member_index(rig: Rig, name: str) -> int:
    return [m.name for m in rig.members].index(name)


def _end_restraint(rig: Rig, location: str, values: Mapping[str, float], pose: Mapping[str, float] | None
                   ) -> Rig:
    i = _member_index(rig, location)
    member = replace(rig.members[i], end_k_Nm_per_rad=values["k_Nm_per_rad"])
    return replace(rig, members=_replace_at(rig.members, i, member))


def _end_rows(system: FrameSystem, srig: Rig, handle: Handle) -> np.ndarray:
    """Each pinned end's rotation relative to its host."""
    m = srig.members[_member_index(srig, handle.location)]
    ends = {"pin-pin": (0, 1), "clamped-pin": (1,), "clamped-clamped": ()}[m.ends]
    rows = []
    for e in ends:
        host = (m.start, m.end)[e]
        own = system.observe(f"{m.name}@{e}", "rotation")
        rows.append(own - (system.observe(str(host), "rotation") if host.link else 0.0))
    return np.array(rows).reshape(-1, system.n_dof)


register_effect(Effect(
    "end_restraint", (K_PARAM,),
    locations=lambda rig: [m.name for m in rig.members if "pin" in m.ends],
    apply=_end_restraint,
    # member length changes with the pose: the scale is the member's EI over one metre
    fit=lambda rig, loc: (Param("end_restraint", "k_Nm_per_rad", f"k@{loc}", 0,
                                *log_range(rig.members[_member_index(rig, loc)].section.EI_Nm2,
                                           1e-4, 1e4, 9)),),
    handles=lambda rig: [Handle(f"k@{m}", "K", rig.members[_member_index(rig, m)].end_k_Nm_per_rad,
                                "end_restraint") for m in effect_locations(rig, "end_restraint")],
    rows=_end_rows,
    slots=lambda rig, srig: replace(srig, members=tuple(replace(m, end_k_Nm_per_rad=0.0)
                                                        for m in srig.members)),
    draw=lambda rig, loc, s, rng: {"k_Nm_per_rad": rig.members[0].section.EI_Nm2 * 10 ** (-1.0 + 2.0 * s)},
))


# ---- sensor masses and grounded springs --------------------------------------------------------------


register_effect(Effect(
    "sensor_mass", (EffectParam("mass_kg", "kg"),),
    locations=lambda rig: ["sensors"] if rig.sensors else [],
    apply=lambda rig, loc, v, pose: replace(rig, sensors=tuple(replace(s, mass_kg=s.mass_kg + v["mass_kg"])
                                                               for s in rig.sensors)),
    fit=lambda rig, loc: (Param("sensor_mass", "mass_kg", "m@sensors", 0,
                                *log_range(_arm_mass_kg(rig) / max(len(rig.sensors), 1), 1e-5, 3.0, 7)),),
    handles=lambda rig: [Handle("m@sensors", "M", 0.0, "sensor_mass")] if rig.sensors else [],
    rows=lambda system, srig, h: np.array([system.observe(str(s.at), q) for s in srig.sensors
                                           for q in ("x", "y")]),
    draw=lambda rig, loc, s, rng: {"mass_kg": _arm_mass_kg(rig) / len(rig.sensors) * 10 ** (-2.0 + 1.5 * s)},
))


def _grounded_points(rig: Rig) -> list[str]:
    points = []
    for i, link in enumerate(rig.links):
        fractions = GROUNDED_SPRING_FRACTIONS
        if i == 0 and rig.base.support == "clamped":
            fractions = tuple(f for f in fractions if f > 0)
        points += [f"{link.name}@{f:g}" for f in fractions]
    return points


def _grounded_ref(rig: Rig, location: str) -> float:
    """3 EI / L^3 [N/m] of the link the point is on: its tip stiffness as a cantilever."""
    lk = rig.link(location.partition("@")[0])
    return 3.0 * lk.section.EI_Nm2 * lk.stiffness_scale / lk.length_m**3


def _grounded_fit(rig: Rig, location: str) -> tuple[Param, ...]:
    return (Param("grounded_spring", "k_N_per_m", f"ks@{location}", 0,
                  *log_range(_grounded_ref(rig, location), 1e-3, 1e3, 7)),)


register_effect(Effect(
    "grounded_spring", (EffectParam("k_N_per_m", "N/m"),),
    locations=_grounded_points,
    apply=lambda rig, loc, v, pose: replace(rig, springs=rig.springs + (
        Spring(rig.point_of(loc), v["k_N_per_m"], "transverse", name=f"grounded_spring@{loc}"),)),
    fit=_grounded_fit,
    handles=lambda rig: [Handle(f"ks@{p}", "K", 0.0, "grounded_spring") for p in _grounded_points(rig)],
    rows=lambda system, srig, h: system.observe(h.location, "transverse")[None],
    slots=lambda rig, srig: replace(srig, springs=srig.springs + tuple(
        Spring(rig.point_of(p), 0.0, "transverse", name=f"slot@{p}") for p in _grounded_points(rig))),
    region="point",
    draw=lambda rig, loc, s, rng: {"k_N_per_m": _grounded_ref(rig, loc) * 10 ** (-1.0 + 2.0 * s)},
))


# ---- link stiffness and mass scales ------------------------------------------------------------------


def _scale_link(field: str) -> Callable[[Rig, str, Mapping[str, float], Mapping[str, float] | None], Rig]:
    def apply(rig: Rig, location: str, values: Mapping[str, float], pose: Mapping[str, float] | None) -> Rig:
        i = [lk.name for lk in rig.links].index(location)
        link = rig.links[i]
        new = replace(link, **{field: getattr(link, field) * values["scale"]})
        return replace(rig, links=_replace_at(rig.links, i, new))
    return apply


def _double_link(srig: Rig, location: str) -> Rig:
    """The super rig with one link's stiffness and mass scales doubled (a unit change of EI@ and mu@)."""
    return replace(srig, links=tuple(
        replace(x, stiffness_scale=2 * x.stiffness_scale, mass_scale=2 * x.mass_scale) if x.name == location
        else x for x in srig.links))


def _link_effect(effect: str, field: str, handle: str, kind: str) -> Effect:
    scale = log_range(1.0, LINK_SCALE_MIN, 1.0 / LINK_SCALE_MIN, 7)
    return Effect(
        effect, (EffectParam("scale", "1"),),
        locations=lambda rig: [lk.name for lk in rig.links],
        apply=_scale_link(field),
        fit=lambda rig, loc: (Param(effect, "scale", f"{handle}@{loc}", 0, *scale),),
        handles=lambda rig: [Handle(f"{handle}@{lk.name}", kind, 1.0, effect, slot=1.0) for lk in rig.links],
        unit_change=_double_link,
        region="link",
        draw=lambda rig, loc, s, rng: {"scale": float(1.0 + 0.9 * s * rng.choice([-0.7, 1.0]))},
    )


register_effect(_link_effect("link_stiffness", "stiffness_scale", "EI", "K"))
register_effect(_link_effect("link_mass", "mass_scale", "mu", "M"))

EFFECTS = registered_effects()
"""The built-in library (docs/formats.md); :func:`registered_effects` also lists effects registered later."""
EFFECT_PARAMS: dict[str, tuple[str, ...]] = {e.name: tuple(p.name for p in e.params)
                                             for e in REGISTRY.values()}
"""Parameter names of the built-in effects."""
