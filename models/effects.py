"""Sim-to-real effects (docs/formats.md): named augmentations of a nominal rig and where each applies.

Each effect turns the frozen :class:`~models.rig.Rig` into a new one with an added physical feature and
its own parameters (SI units):

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
from collections.abc import Mapping
from dataclasses import replace

from flexmodal.models.errors import ModelError
from flexmodal.models.rig import Mass, Point, Rig, Spring

EFFECTS = (
    "joint_stiffness",
    "joint_stiffness_pose",
    "joint_mass",
    "tip_mass",
    "base_stiffness",
    "end_restraint",
    "sensor_mass",
    "grounded_spring",
    "link_stiffness",
    "link_mass",
)

EFFECT_PARAMS: dict[str, tuple[str, ...]] = {
    "joint_stiffness": ("k_Nm_per_rad",),
    "joint_stiffness_pose": ("k_Nm_per_rad", "log_slope_per_rad", "log_curv_per_rad2"),
    "joint_mass": ("mass_kg", "inertia_kgm2"),
    "tip_mass": ("mass_kg", "inertia_kgm2"),
    "base_stiffness": ("k_Nm_per_rad",),
    "end_restraint": ("k_Nm_per_rad",),
    "sensor_mass": ("mass_kg",),
    "grounded_spring": ("k_N_per_m",),
    "link_stiffness": ("scale",),
    "link_mass": ("scale",),
}

GROUNDED_SPRING_FRACTIONS = (0.25, 0.5, 0.75, 1.0)
"""Candidate points along every link where a grounded spring is tried."""


def _check_effect(effect: str) -> None:
    if effect not in EFFECTS:
        raise ModelError(f"unknown effect {effect!r} (expected one of {', '.join(EFFECTS)})")


def effect_locations(rig: Rig, effect: str) -> list[str]:
    """Locations (docs/formats.md) where ``effect`` applies on ``rig``; empty when it does not apply."""
    _check_effect(effect)
    if effect == "joint_stiffness":
        return [j.name for j in rig.joints if j.kind != "pin"]
    if effect == "joint_stiffness_pose":
        return [j.name for j in rig.joints if j.kind != "pin" and j.angle]
    if effect == "joint_mass":
        hub = ["base"] if rig.base.support != "clamped" else []
        return hub + [j.name for j in rig.joints]
    if effect == "tip_mass":
        return ["tip"]
    if effect == "base_stiffness":
        return ["base"] if rig.base.support in ("clamped", "pinned", "spring") else []
    if effect == "end_restraint":
        return [m.name for m in rig.members if "pin" in m.ends]
    if effect == "sensor_mass":
        return ["sensors"] if rig.sensors else []
    if effect == "grounded_spring":
        points = []
        for i, link in enumerate(rig.links):
            fractions = GROUNDED_SPRING_FRACTIONS
            if i == 0 and rig.base.support == "clamped":
                fractions = tuple(f for f in fractions if f > 0)
            points += [f"{link.name}@{f:g}" for f in fractions]
        return points
    return [lk.name for lk in rig.links]  # link_stiffness, link_mass


def pose_stiffness(params: Mapping[str, float], angle_deg: float) -> float:
    """Joint stiffness [N m/rad] of the ``joint_stiffness_pose`` law at a joint angle in degrees."""
    q = math.radians(angle_deg)
    a1 = params.get("log_slope_per_rad", 0.0)
    a2 = params.get("log_curv_per_rad2", 0.0)
    return float(params["k_Nm_per_rad"]) * math.exp(a1 * q + a2 * q * q)


def _param(params: Mapping[str, float], name: str, effect: str, default: float | None = None) -> float:
    if name not in params:
        if default is not None:
            return default
        raise ModelError(f"effect {effect!r}: missing parameter {name!r}")
    value = float(params[name])
    if not math.isfinite(value) or value < 0:
        raise ModelError(f"effect {effect!r}: parameter {name!r} must be finite and >= 0 (got {value!r})")
    return value


def _joint_index(rig: Rig, location: str, effect: str) -> int:
    for i, j in enumerate(rig.joints):
        if j.name == location:
            return i
    raise ModelError(f"effect {effect!r}: {location!r} is not a joint of {rig.source} "
                     f"(joints: {', '.join(j.name for j in rig.joints) or 'none'})")


def _replace_at(items: tuple, index: int, new: object) -> tuple:
    return items[:index] + (new,) + items[index + 1:]


def apply_effect(rig: Rig, effect: str, location: str, params: Mapping[str, float],
                 pose: Mapping[str, float] | None = None) -> Rig:
    """Return a copy of ``rig`` with ``effect`` added at ``location`` (see the module table).

    ``pose`` is needed only by ``joint_stiffness_pose`` with a non-zero law slope/curvature: the
    stiffness is evaluated at the joint's angle in that pose.  Raises ModelError naming a location the
    effect does not apply to or a missing/invalid parameter.
    """
    _check_effect(effect)
    if location not in effect_locations(rig, effect):
        raise ModelError(f"effect {effect!r} does not apply at {location!r} on {rig.source} "
                         f"(locations: {', '.join(effect_locations(rig, effect)) or 'none'})")
    if effect in ("joint_stiffness", "joint_stiffness_pose"):
        i = _joint_index(rig, location, effect)
        joint = rig.joints[i]
        k = _param(params, "k_Nm_per_rad", effect)
        varies = params.get("log_slope_per_rad") or params.get("log_curv_per_rad2")
        if effect == "joint_stiffness_pose" and varies:
            if pose is None or joint.angle not in pose:
                raise ModelError(f"effect {effect!r} at {location!r} needs the pose value of {joint.angle!r}")
            k = pose_stiffness(params, float(pose[joint.angle]))
        return replace(rig, joints=_replace_at(rig.joints, i, replace(joint, kind="spring", k_Nm_per_rad=k)))
    if effect in ("joint_mass", "tip_mass"):
        if location == "base":
            at = Point(rig.links[0].name, 0.0)
        elif location == "tip":
            at = Point(rig.links[-1].name, 1.0)
        else:
            at = Point(rig.joints[_joint_index(rig, location, effect)].child, 0.0)
        mass = Mass(at, _param(params, "mass_kg", effect), _param(params, "inertia_kgm2", effect, 0.0),
                    name=f"{effect}@{location}")
        return replace(rig, masses=rig.masses + (mass,))
    if effect == "base_stiffness":
        return replace(rig, base=replace(rig.base, support="spring",
                                         k_Nm_per_rad=_param(params, "k_Nm_per_rad", effect)))
    if effect == "end_restraint":
        i = next(n for n, m in enumerate(rig.members) if m.name == location)
        member = replace(rig.members[i], end_k_Nm_per_rad=_param(params, "k_Nm_per_rad", effect))
        return replace(rig, members=_replace_at(rig.members, i, member))
    if effect == "sensor_mass":
        m = _param(params, "mass_kg", effect)
        return replace(rig, sensors=tuple(replace(s, mass_kg=s.mass_kg + m) for s in rig.sensors))
    if effect == "grounded_spring":
        spring = Spring(rig.point_of(location), _param(params, "k_N_per_m", effect), "transverse",
                        name=f"{effect}@{location}")
        return replace(rig, springs=rig.springs + (spring,))
    i = next(n for n, lk in enumerate(rig.links) if lk.name == location)
    link, scale = rig.links[i], _param(params, "scale", effect)
    if effect == "link_stiffness":
        new = replace(link, stiffness_scale=link.stiffness_scale * scale)
    else:
        new = replace(link, mass_scale=link.mass_scale * scale)
    return replace(rig, links=_replace_at(rig.links, i, new))
