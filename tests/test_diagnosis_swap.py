"""A hidden pair is found by replacing a part of the chosen combination with every single, or, when a
pair is chosen, by pairing every pooled single with every single (compare/diagnosis.py ``_swapped``):
blind draws 1475 case 24 and 1579 cases 24, 34 (counted from 0), regenerated from their seeds."""

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


@pytest.mark.slow   # ~30 s: generating the draw's first 35 cases
def test_pair_with_no_part_chosen_is_found_from_the_pool():
    """Blind draw 1579 cases 24 and 34 (axial rig, counted from 0): each hidden pair has one part in the
    pair search's pool that is no lead, the other outside the pool, and the chosen pair shares neither
    part, so neither the pair search nor the swap of a chosen part fitted it (main 305b8d3: a link-1 plus
    sensor mass, and a grounded spring at link2@0.5 plus an elbow stiffness).  Pairing every pooled
    single with every single, when a pair is chosen, finds both: top-1 right."""
    rng = np.random.default_rng(1579)
    cases = []
    for i in range(35):                      # the draw's first 35 cases, as fixtures.blind.run_blind
        with threadpool_limits(limits=1, user_api="blas"):
            cases.append(make_case(rng, CATEGORIES[i % len(CATEGORIES)], KINDS[i % len(KINDS)]))
    truths = [(cases[i].effect, cases[i].location) for i in (24, 34)]
    assert truths == [("base_stiffness+link_stiffness", "base+link2"),
                      ("grounded_spring+tip_mass", "link2@1+tip")]
    for i in (24, 34):
        v = diagnose(cases[i].rig, cases[i].table).verdict
        assert (v.effect, v.location) == (cases[i].effect, cases[i].location)
