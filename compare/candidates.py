"""Candidate model augmentations for the diagnosis: effect + location, their fit parameters and bounds.

A candidate is one effect at one location (models/effects.py) or a combination of two.  Its parameters
are fitted in log space, ``log h = D theta`` (a design over configurations), which covers constant
parameters (``D = 1``) and the pose law of ``joint_stiffness_pose``, ``log k(q) = t0 + t1 q + t2 q^2`` with
``q`` the joint angle in rad.  Bounds and starting grids are scaled to the rig (EI/L for rotational
springs, 3EI/L^3 for grounded springs, the arm's mass and mass times length^2 for added masses).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from flexmodal.models.effects import EFFECTS, effect_locations
from flexmodal.models.rig import Rig

POSE_LAW_BOUND = 3.0
LINK_SCALE_MIN = 1 / 3
"""Link stiffness/mass scales are searched in [1/3, 3]: a parameter error, not a different link."""
"""Bound on the pose law's log-slope [1/rad] and log-curvature [1/rad^2]."""


@dataclass(frozen=True)
class Param:
    """One fitted parameter: its reported name, the handle it drives, bounds of theta and start grid."""

    effect: str
    name: str             # EFFECT_PARAMS name, e.g. "k_Nm_per_rad"
    handle: str           # handle name, e.g. "k@elbow"
    power: int            # 0: theta is log h; 1/2: pose-law slope/curvature multiplying q^power
    lower: float          # bounds on theta
    upper: float
    grid: tuple[float, ...]


@dataclass(frozen=True)
class Candidate:
    """Effects (alphabetical) with their locations, e.g. ("joint_mass", "joint_stiffness") at the elbow."""

    effects: tuple[str, ...]
    locations: tuple[str, ...]
    params: tuple[Param, ...]

    @property
    def effect(self) -> str:
        return "+".join(self.effects)

    @property
    def location(self) -> str:
        return "+".join(dict.fromkeys(self.locations))

    @property
    def handles(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(p.handle for p in self.params))

    @property
    def n_params(self) -> int:
        return len(self.params)


def _arm_mass_kg(rig: Rig) -> float:
    return sum(lk.section.mass_per_m_kg * lk.mass_scale * lk.length_m for lk in rig.links)


def _log_range(ref: float, lo: float, hi: float, n: int) -> tuple[float, float, tuple[float, ...]]:
    a, b = math.log(ref * lo), math.log(ref * hi)
    inner = np.linspace(a, b, n + 2)[1:-1]
    return a, b, tuple(float(x) for x in inner)


def effect_params(rig: Rig, effect: str, location: str) -> tuple[Param, ...]:
    """Fit parameters of one effect at one location, with bounds scaled to ``rig``."""
    arm_m = _arm_mass_kg(rig)
    arm_L = sum(lk.length_m for lk in rig.links)

    def ei_over_l(link_name: str) -> float:
        lk = rig.link(link_name)
        return lk.section.EI_Nm2 * lk.stiffness_scale / lk.length_m

    def mass_pair(loc: str) -> tuple[Param, ...]:
        m = _log_range(arm_m, 1e-4, 10.0, 7)
        J = _log_range(arm_m * arm_L**2, 1e-7, 1.0, 4)
        return (Param(effect, "mass_kg", f"m@{loc}", 0, *m), Param(effect, "inertia_kgm2", f"J@{loc}", 0, *J))

    if effect in ("joint_stiffness", "joint_stiffness_pose"):
        k = _log_range(ei_over_l(rig.joint(location).child), 1e-3, 1e5, 9)
        first = Param(effect, "k_Nm_per_rad", f"k@{location}", 0, *k)
        if effect == "joint_stiffness":
            return (first,)
        law = [Param(effect, name, f"k@{location}", p, -POSE_LAW_BOUND, POSE_LAW_BOUND, (0.0,))
               for p, name in ((1, "log_slope_per_rad"), (2, "log_curv_per_rad2"))]
        return (first, *law)
    if effect in ("joint_mass", "tip_mass"):
        return mass_pair(location)
    if effect == "base_stiffness":
        k = _log_range(ei_over_l(rig.links[0].name), 1e-3, 1e5, 9)
        return (Param(effect, "k_Nm_per_rad", "k@base", 0, *k),)
    if effect == "end_restraint":
        m = next(x for x in rig.members if x.name == location)
        # member length changes with the pose: the scale is the member's EI over one metre
        k = _log_range(m.section.EI_Nm2, 1e-4, 1e4, 9)
        return (Param(effect, "k_Nm_per_rad", f"k@{location}", 0, *k),)
    if effect == "sensor_mass":
        ref = arm_m / max(len(rig.sensors), 1)
        return (Param(effect, "mass_kg", "m@sensors", 0, *_log_range(ref, 1e-5, 3.0, 7)),)
    if effect == "grounded_spring":
        lk = rig.link(location.partition("@")[0])
        ref = 3.0 * lk.section.EI_Nm2 * lk.stiffness_scale / lk.length_m**3
        return (Param(effect, "k_N_per_m", f"ks@{location}", 0, *_log_range(ref, 1e-3, 1e3, 7)),)
    handle = "EI" if effect == "link_stiffness" else "mu"
    scale = _log_range(1.0, LINK_SCALE_MIN, 1.0 / LINK_SCALE_MIN, 7)
    return (Param(effect, "scale", f"{handle}@{location}", 0, *scale),)


def single_candidates(rig: Rig, effects: Sequence[str], pose_values: Mapping[str, Sequence[float]]
                      ) -> list[Candidate]:
    """Every effect of ``effects`` at every location where it applies.

    ``joint_stiffness_pose`` is only offered for joints whose angle takes >= 3 distinct values.
    """
    out = []
    for effect in effects:
        for loc in effect_locations(rig, effect):
            if effect == "joint_stiffness_pose":
                angle = rig.joint(loc).angle
                if len(set(pose_values.get(angle, ()))) < 3:
                    continue
            out.append(Candidate((effect,), (loc,), effect_params(rig, effect, loc)))
    return out


def components(c: Candidate) -> list[tuple[str, str, tuple[Param, ...]]]:
    """(effect, location, params) of each effect in a candidate."""
    return [(e, loc, tuple(p for p in c.params if p.effect == e and p.handle.partition("@")[2] == loc))
            for e, loc in zip(c.effects, c.locations, strict=True)]


def combine(*cands: Candidate) -> Candidate | None:
    """The combination of candidates (effects in alphabetical order), or None if two share a handle."""
    handles = [h for c in cands for h in c.handles]
    if len(set(handles)) != len(handles):
        return None
    parts = sorted((part for c in cands for part in components(c)), key=lambda t: (t[0], t[1]))
    return Candidate(tuple(e for e, _, _ in parts), tuple(loc for _, loc, _ in parts),
                     tuple(p for _, _, ps in parts for p in ps))


def parse_effects(spec: str) -> tuple[str, ...]:
    """``all`` or a comma-separated list of effect names (validated against docs/formats.md)."""
    from flexmodal.compare.errors import CompareError

    if spec.strip() == "all":
        return EFFECTS
    names = tuple(s.strip() for s in spec.split(",") if s.strip())
    bad = [n for n in names if n not in EFFECTS]
    if bad or not names:
        raise CompareError(f"--effects: unknown effect {bad[0] if bad else spec!r} "
                           f"(expected 'all' or names from {', '.join(EFFECTS)})")
    return names
