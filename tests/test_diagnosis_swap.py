"""A pair of which the chosen combination holds one part is found by replacing the other part with
every single (compare/diagnosis.py ``_swapped``): blind draw 1475 case 24 (counted from 0),
regenerated from its seed."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from flexmodal.compare.diagnosis import diagnose
from flexmodal.fixtures.blind import CATEGORIES, KINDS, make_case


@pytest.mark.slow   # ~45 s: generating the draw's first 25 cases
def test_pair_with_a_part_chosen_is_completed_by_any_single():
    """Blind draw 1475 case 24 (axial rig, a base stiffness with a grounded spring at link1@0.75): the
    pair search formed the spring one slot off (link1@1) with the base stiffness, held out 0.95 %,
    within 3 times the scatter (0.84 %), so ``_relocated`` was not asked and the hidden pair was never
    fitted (main c660f62).  Replacing each part of the chosen pair by every single finds it: top-1
    right, held out 0.45 %."""
    rng = np.random.default_rng(1475)
    for i in range(25):                      # the draw's first 25 cases, as fixtures.blind.run_blind
        with threadpool_limits(limits=1, user_api="blas"):
            case = make_case(rng, CATEGORIES[i % len(CATEGORIES)], KINDS[i % len(KINDS)])
    assert (case.effect, case.location) == ("base_stiffness+grounded_spring", "base+link1@0.75")
    v = diagnose(case.rig, case.table).verdict
    assert (v.effect, v.location) == (case.effect, case.location)
    assert v.heldout_rms_rel_error_after < case.scatter
