"""Reduce a rig at a pose to one uniform straight beam with end supports (for closed-form models).

The beam models (Blevins' table, assumed modes) only describe a uniform, straight, serial arm: every
joint rigid and straight at the pose, every link of the same section, no members or grounded springs,
and lumped masses only at the base (hub inertia) or the tip (payload).  Anything else raises a
ModelError naming the first item the model cannot represent.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from flexmodal.models.assumed_modes import CLAMPED, FREE, INF, PINNED, Beam, End
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import Rig, Section


@dataclass(frozen=True)
class StraightBeam:
    """The arm as one beam: ``condition`` is the base-tip name when both ends are plain supports."""

    beam: Beam
    left: End
    right: End
    condition: str | None
    sensor_x_m: tuple[float, ...]        # distance of each rig sensor from the base along the beam
    sensor_transverse: tuple[bool, ...]  # False for axial sensors (no transverse motion to report)


def _same(a: Section, b: Section, scale_a: tuple[float, float], scale_b: tuple[float, float]) -> bool:
    ea = (a.EI_Nm2 * scale_a[0], a.mass_per_m_kg * scale_a[1])
    eb = (b.EI_Nm2 * scale_b[0], b.mass_per_m_kg * scale_b[1])
    return all(math.isclose(x, y, rel_tol=1e-9) for x, y in zip(ea, eb, strict=True))


def straight_beam(rig: Rig, pose: Mapping[str, float], model: str) -> StraightBeam:
    """The uniform straight beam equivalent to ``rig`` at ``pose``; ModelError if there is none."""
    rig.check_pose(pose)
    where = f"{rig.source}: model {model!r}"
    first = rig.links[0]
    scales0 = (first.stiffness_scale, first.mass_scale)
    for lk in rig.links:
        if lk.segments and any(not _same(s.section, first.section, (1, 1), (1, 1)) for s in lk.segments):
            raise ModelError(f"{where} needs a uniform beam; link {lk.name!r} has non-uniform segments")
        if not _same(lk.section, first.section, (lk.stiffness_scale, lk.mass_scale), scales0):
            raise ModelError(f"{where} needs a uniform beam but link {lk.name!r} differs from {first.name!r}")
    for j in rig.joints:
        angle = float(pose[j.angle]) if j.angle else j.angle_deg
        if j.kind != "rigid":
            raise ModelError(f"{where} handles rigid joints only; joint {j.name!r} is {j.kind!r} "
                             "(use --model fe)")
        if abs(angle) > 1e-9:
            raise ModelError(f"{where} handles straight arms only; joint {j.name!r} is at {angle:g} deg "
                             "(use --model fe)")
    if rig.members:
        raise ModelError(f"{where} cannot represent member {rig.members[0].name!r} (use --model fe)")
    if rig.springs:
        raise ModelError(f"{where} cannot represent a grounded spring at {rig.springs[0].at} "
                         "(use --model fe)")
    rig.check_euler_bernoulli(where)
    lengths = [lk.length_m for lk in rig.links]
    offsets = [sum(lengths[:i]) for i in range(len(lengths))]
    total = sum(lengths)
    index = {lk.name: i for i, lk in enumerate(rig.links)}

    def x_of(p) -> float:
        return offsets[index[p.link]] + p.fraction * lengths[index[p.link]]

    base_m = base_J = tip_m = tip_J = 0.0
    for m in rig.masses:
        x = x_of(m.at)
        value = float(pose[m.mass_kg]) if isinstance(m.mass_kg, str) else m.mass_kg
        if x < 1e-12 * total:
            base_m, base_J = base_m + value, base_J + m.inertia_kgm2
        elif x > total * (1 - 1e-12):
            tip_m, tip_J = tip_m + value, tip_J + m.inertia_kgm2
        else:
            raise ModelError(f"{where} takes lumped masses only at the base or the tip, not at {m.at}")
    for s in rig.sensors:
        if s.mass_kg > 0:
            raise ModelError(f"{where} cannot represent the mass of sensor {s.name!r} (use --model fe)")
    support = rig.base.support
    left = {"clamped": CLAMPED, "pinned": PINNED, "free": FREE,
            "spring": End(INF, rig.base.k_Nm_per_rad or 0.0)}[support]
    if support != "clamped":  # a clamped base holds its masses still
        left = End(left.k_t_N_per_m, left.k_r_Nm_per_rad, base_m if support == "free" else 0.0, base_J)
    right = End(0.0, 0.0, tip_m, tip_J)
    plain = right == FREE and left in (CLAMPED, PINNED, FREE)
    condition = f"{support}-free" if plain else None
    beam = Beam(total, first.section.EI_Nm2 * first.stiffness_scale,
                first.section.mass_per_m_kg * first.mass_scale)
    return StraightBeam(beam, left, right, condition, tuple(x_of(s.at) for s in rig.sensors),
                        tuple(s.direction == "transverse" for s in rig.sensors))
