"""Candidate model augmentations for the diagnosis: effect + location, their fit parameters and bounds.

A candidate is one effect at one location (models/effects.py) or a combination of two.  Its parameters
are fitted in log space, ``log h = D theta`` (a design over configurations), which covers constant
parameters (``D = 1``) and the pose law of ``joint_stiffness_pose``, ``log k(q) = t0 + t1 q + t2 q^2`` with
``q`` the joint angle in rad.  Each effect's registry entry scales its bounds and starting grid to the
rig (EI/L for rotational springs, 3EI/L^3 for grounded springs, the arm's mass and mass times length^2 for
added masses).
"""

from __future__ import annotations

from argparse import ArgumentTypeError
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from flexmodal.checked_io.options import names as comma_names
from flexmodal.models.effects import REGISTRY, Param, get_effect, registered_effects
from flexmodal.models.rig import Rig


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


def single_candidates(rig: Rig, effects: Sequence[str], pose_values: Mapping[str, Sequence[float]]
                      ) -> list[Candidate]:
    """Every effect of ``effects`` at every location where it applies and its registry entry offers it
    for these pose values (e.g. ``joint_stiffness_pose`` needs >= 3 distinct joint angles)."""
    out = []
    for name in effects:
        effect = get_effect(name)
        out += [Candidate((name,), (loc,), effect.fit(rig, loc)) for loc in effect.locations(rig)
                if effect.offered(rig, loc, pose_values)]
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
    """``all`` (every registered effect) or a comma-separated list of effect names (models/effects.py);
    a name given twice counts once (each candidate is fitted once)."""
    from flexmodal.compare.errors import CompareError

    if spec.strip() == "all":
        return registered_effects()
    try:
        names = tuple(dict.fromkeys(comma_names(spec)))
    except ArgumentTypeError:   # "joint_stiffness," or "a,,b": an empty name was a slip, not "nothing"
        raise CompareError(f"--effects {spec!r}: expected 'all' or EFFECT[,EFFECT...] with no empty "
                           f"name (effects: {', '.join(REGISTRY)})") from None
    bad = [n for n in names if n not in REGISTRY]
    if bad or not names:
        raise CompareError(f"--effects: unknown effect {bad[0] if bad else spec!r} "
                           f"(expected 'all' or names from {', '.join(REGISTRY)})")
    return names
