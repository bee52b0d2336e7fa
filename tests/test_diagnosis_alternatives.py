"""A candidate equal within noise held out is cross-validated and listed even when its in-sample score
loses (compare/diagnosis.py ``_cross_validate_promising``): blind draw 947 case 7, stored."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from flexmodal.compare.diagnosis import diagnose
from flexmodal.contract.table import ModalTable
from flexmodal.models.rig import parse_rig

CASE = Path(__file__).parent / "data" / "blind_cases" / "draw947_case07"


@pytest.mark.slow   # 6.1 s CPU, 8.4 s wall (whole pytest run): above the ~3 s of a default test
def test_a_pair_that_loses_only_by_its_penalty_is_an_alternative():
    """Blind draw 947 #7 (pusher arm, a base joint mass with a sensor mass, 8 configurations x 4 modes,
    the independent truth model's frequencies with 0.39 % scatter): the hidden pair (3 parameters)
    predicts held-out poses as well as a link-1 mass with the sensor mass (2 parameters), 0.44 %
    against 0.45 % frequency-equivalent, but its in-sample score, one parameter more, lost to the
    best held-out score, so it was never cross-validated and the verdict was not flagged.  Now every
    candidate whose in-sample error is within the noise margin of the lowest held-out one (and not
    nested in it) is cross-validated.  What that promises, and what is asserted: the hidden pair is in the
    ranking with a held-out score, and the verdict is right by issue 26's rule, the hidden pair itself
    or an ambiguous verdict listing it among its alternatives.  (Which of the two pairs comes first is
    not asserted: an ideal fit on noise-free data cannot tell them apart, 0.17 % against 0.25 %, margin
    0.14 %; this version picks the link-1 pair, flagged ambiguous.)"""
    doc = json.loads(CASE.with_suffix(".json").read_text())
    truth = (doc["truth"]["effect"], doc["truth"]["location"])
    assert truth == ("joint_mass+sensor_mass", "base+sensors")
    d = diagnose(parse_rig(doc["rig"], "<draw 947 case 7>"), ModalTable.read_csv(CASE.with_suffix(".csv")))
    held_out = {(c.effect, c.location): c.heldout_rms_rel_error for c in d.ranking}
    assert math.isfinite(held_out.get(truth, math.nan)), sorted(held_out)
    v = d.verdict
    assert truth == (v.effect, v.location) or (v.ambiguous and truth in {(a.effect, a.location)
                                                                          for a in v.alternatives}), v
