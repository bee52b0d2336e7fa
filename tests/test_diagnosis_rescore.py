"""A relocated combination (compare/diagnosis.py ``_relocated``) whose fit lowers the shape-noise floor
makes every cross-validated candidate (the ranking, the moved fits and the sub-candidates the pruning
validated) be scored again at the lowered floor before the verdict is chosen again (main 62751cc
re-scored the ranking and the moved fits; before it the moved fits were compared with scores of the
older, higher floor): blind draw 1053 #7, stored."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import flexmodal.compare.diagnosis as diagnosis
from flexmodal.compare.next_measurement import SHAPE_SCATTER_MIN
from flexmodal.contract.table import ModalTable
from flexmodal.models.rig import parse_rig

CASE = Path(__file__).parent / "data" / "blind_cases" / "draw1053_case07"


def _score_at(floor: float, entry: dict, shape_dof: int, scatter: float) -> float:
    """The held-out score of ``entry`` at the shape-noise ``floor`` (mean 1 - MAC per degree of
    freedom), written out from docs/diagnosis.md: frequencies and shapes as one chi-square, each over
    its noise -- ``(e / scatter)^2`` per relative frequency error, ``(1 - MAC) / var`` per shape with
    ``shape_dof`` degrees of freedom, ``var = max(floor / shape_dof, 0.001^2)`` -- the frequency RMS
    as unlikely, ``scatter * sqrt(chi2 / dof)``, then ``hypot(that, scatter) * (1 + PENALTY * n)``."""
    err, shape = entry["_held_err"], entry["_held_shape"]
    var = max(floor / shape_dof, SHAPE_SCATTER_MIN**2)
    chi2 = float(np.sum(np.square(err))) / scatter**2 + float(np.sum(shape)) / var
    equivalent = scatter * math.sqrt(chi2 / (err.size + shape_dof * shape.size))
    return math.hypot(equivalent, scatter) * (1 + diagnosis.PENALTY * entry["n_params"])


@pytest.mark.slow   # ~3.5 s CPU (the full search and the relocations): above the ~3 s of a default test
def test_a_relocation_that_lowers_the_shape_floor_rescores_every_candidate(monkeypatch):
    """Blind draw 1053 #7 (pusher rig, an end restraint at the pusher and a sensor mass hidden, 5
    configurations x 2 modes with shapes at 4 sensors, 0.75 % scatter): the chosen pair leaves more than
    3x the scatter, its components are moved, and a moved fit (in-sample mean 1 - MAC 0.00115) lowers
    the shape floor from 0.00137.  Asserted against the closed form above: the floor is the smallest
    in-sample mean 1 - MAC of the fits (Mallows), every cross-validated candidate (the ranking and
    those the pruning validated) is scored at that final floor, and the candidates ranked before the
    relocation score differently at the old floor (so the test fails where they keep those scores).
    Against the hidden truth: the verdict keeps the true end restraint at the pusher.

    Measured (27 Nov): with every candidate at the final floor the verdict is end_restraint+joint_mass+
    tip_mass at pusher+base+tip (held out 1.88 %), as without any re-scoring; main f7b862e re-scored the
    ranking and the moved fits only, and pruned that verdict to joint_mass+tip_mass at base+tip (4.37 %) by
    comparing its held-out error at the new floor with the sub-candidate's at the old one (score 5.64 %
    where the final floor gives 5.82 %): the only verdict the re-scoring changed on the paired draws
    1051-1054, away from the truth."""
    doc = json.loads(CASE.with_suffix(".json").read_text())
    truth = (doc["truth"]["effect"], doc["truth"]["location"])
    assert truth == ("end_restraint+sensor_mass", "pusher+sensors")
    relocations, final = [], {}
    relocated, verdict = diagnosis._relocated, diagnosis._verdict

    def spy_relocated(ctx, best, screened, scatter):
        before = ctx.shape_floor
        moved = relocated(ctx, best, screened, scatter)
        relocations.append((before, moved, screened))
        return moved

    def spy_verdict(ctx, best, ranking, baseline, before, nominal, scatter, *rest):
        final.update(ctx=ctx, ranking=list(ranking), scatter=scatter)
        return verdict(ctx, best, ranking, baseline, before, nominal, scatter, *rest)

    monkeypatch.setattr(diagnosis, "_relocated", spy_relocated)
    monkeypatch.setattr(diagnosis, "_verdict", spy_verdict)
    rig = parse_rig(doc["rig"], "<draw 1053 case 7>")
    v = diagnosis.diagnose(rig, ModalTable.read_csv(CASE.with_suffix(".csv"))).verdict

    ctx, ranking, scatter = final["ctx"], final["ranking"], final["scatter"]
    old_floor, screened = relocations[0][0], relocations[-1][2]     # screened: every fit, moved ones too
    assert ctx.shape_floor < old_floor                               # a relocation lowered the floor
    assert ctx.shape_floor == min(float(np.mean(e["_fit_shape"])) for e in screened if e["_fit_shape"].size)
    validated = [e for e in screened if "score" in e]
    assert len(ranking) >= 5 and all(any(e is r for r in validated) for e in ranking)
    now = {id(e): _score_at(ctx.shape_floor, e, ctx.shape_dof, scatter) for e in validated}
    stale = [f"{e['effect']} at {e['location']}" for e in validated
             if not math.isclose(e["score"], now[id(e)], rel_tol=1e-12)]
    assert not stale, stale                                          # every one at the final floor
    moved = [m for _, ms, _ in relocations for m in ms]
    earlier = [e for e in ranking if not any(e is m for m in moved)]
    assert any(abs(_score_at(old_floor, e, ctx.shape_dof, scatter) / e["score"] - 1) > 1e-3 for e in earlier)
    parts = zip(v.effect.split("+"), v.location.split("+"), strict=True)
    assert ("end_restraint", "pusher") in parts, v.summary
