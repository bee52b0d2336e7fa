"""A pair whose parts are each weak alone is found by moving a component of the chosen pair
(compare/diagnosis.py ``_relocated``): blind draw 845 #3, regenerated from its seed."""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from flexmodal.compare.diagnosis import diagnose
from flexmodal.fixtures.blind import CATEGORIES, KINDS, make_case


def test_pair_one_slot_off_is_moved_to_the_hidden_pair():
    """Blind draw 845 #3 (payload arm, a grounded spring at link1@0.75 and an elbow mass, 10
    configurations x 2 modes): the pair search formed the spring one slot off (link1@1) and chose a
    link mass with it, 9 times the scatter left; the hidden pair was never fitted (the joint mass is
    16th of the singles).  Moving each component of the leading pairs finds it: top-1 right and the
    gap explained (held out 0.30 % against 2.4 % before the change; the ideal fit on noise-free data
    separates them by 1.1 %, margin 0.07 %)."""
    rng = np.random.default_rng(845)
    for i in range(4):                       # the draw's first four cases, as fixtures.blind.run_blind
        with threadpool_limits(limits=1, user_api="blas"):
            case = make_case(rng, CATEGORIES[i], KINDS[i % len(KINDS)])
    assert (case.effect, case.location) == ("grounded_spring+joint_mass", "link1@0.75+elbow")
    v = diagnose(case.rig, case.table).verdict
    assert (v.effect, v.location) == (case.effect, case.location)
    assert v.heldout_rms_rel_error_after < 3 * case.scatter
