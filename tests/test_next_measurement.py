"""Issue 26 item 5: the advised next measurement separates look-alike candidates where a pose inside the
measured range does not -- a constructed two-candidate case whose answer the FE model itself gives."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.compare.candidates import Candidate
from flexmodal.compare.diagnosis import diagnose
from flexmodal.compare.next_measurement import _resolve_chance, adds_to, next_measurements, trial_poses
from flexmodal.contract.table import ModalTable
from flexmodal.fixtures.blind import random_rig
from flexmodal.models.effects import apply_effect
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig

MEASURED = (60.0, 75.0, 90.0)
NOISE = 0.003
EFFECTS = "link_mass,tip_mass"


@pytest.fixture(scope="module")
def rig(rigs_dir):
    return load_rig(rigs_dir / "seed003_two_link.toml")


def _table(real, poses, seed):
    """The first mode of ``real`` at ``poses`` with 0.3 % noise (seeded)."""
    rng = np.random.default_rng(seed)
    rec = [{"config": f"c{i}", "mode": 1, "freq_hz": frame_modes(real, {"theta_deg": th}, 1).freq_hz[0]
            * (1 + NOISE * rng.standard_normal()), "pose.theta_deg": th} for i, th in enumerate(poses)]
    return ModalTable.from_records(rec, "<test>")


def test_trial_poses_reach_beyond_the_measured_range_and_combine_pose_variables(rig):
    """13 points over the measured range, on at the same step up to half the range beyond each end,
    angles within +-180 deg; several pose variables also in combination."""
    labels = list(trial_poses(rig, [{"theta_deg": x} for x in MEASURED]))
    assert labels == [f"theta_deg={45 + 2.5 * k:g}" for k in range(25)]
    wide = list(trial_poses(rig, [{"theta_deg": 0.0}, {"theta_deg": 150.0}]))
    assert wide[0] == "theta_deg=-75" and wide[-1] == "theta_deg=175"
    payload = random_rig(np.random.default_rng(1), "payload")        # theta_deg and payload_kg
    both = trial_poses(payload, [{"theta_deg": 0.0, "payload_kg": 0.3},
                                 {"theta_deg": 150.0, "payload_kg": 1.0}])
    corner = both["theta_deg=175,payload_kg=0.00833333"]
    assert corner == {"theta_deg": 175.0, "payload_kg": pytest.approx(0.3 - 5 * 0.7 / 12)}
    assert min(p["payload_kg"] for p in both.values()) >= 0 and len(both) == 21 + 24 + 9


def test_the_chance_to_decide_is_nil_for_equal_predictions_and_near_one_for_distant_ones():
    """Two candidates equally good held out (0.5 % over 6 degrees of freedom, scatter 0.5 %): predictions
    equal at a pose cannot decide (chance 0 to 1e-6); predictions 20 scatters apart decide (> 0.99)."""
    f = np.array([[[100.0], [100.0]], [[100.0], [110.0]]])          # [K=2, P=2, n=1]
    v = np.full(f.shape, 0.005**2)
    chance = _resolve_chance(f, v, np.array([0.005, 0.005]), np.array([6.0, 6.0]), 1.0, 0.005)
    assert chance[0] < 1e-6 and chance[1] > 0.99


@pytest.mark.timeout(600)            # seven diagnoses of two effects over 3-4 poses: a few seconds
def test_the_advised_pose_separates_two_look_alikes_where_a_pose_in_the_measured_range_does_not(rig):
    """A link2 mass x1.4 measured (first mode only) at 60/75/90 deg looks like a tip mass there: the
    verdict is ambiguous.  The FE model of the two fitted candidates says where they differ: by under
    the noise inside the measured range, by several times it beyond 90 deg.  The advice names such a
    pose; one more measurement there makes the verdict right and unambiguous, one at any of four
    untested poses inside the range leaves it ambiguous (of all 22 untested candidate poses, 12
    resolve it: the ones outside the range)."""
    real = apply_effect(rig, "link_mass", "link2", {"scale": 1.4})
    v = diagnose(rig, _table(real, MEASURED, 0), effects=EFFECTS).verdict
    assert (v.effect, v.location) == ("link_mass", "link2") and v.ambiguous
    alt = v.alternatives[0]
    assert (alt.effect, alt.location) == ("tip_mass", "tip")
    fitted_a = apply_effect(rig, "link_mass", "link2", dict(v.params))
    fitted_b = apply_effect(rig, "tip_mass", "tip", dict(alt.params))

    def apart(theta: float) -> float:                 # the model's answer: relative difference, mode 1
        pose = {"theta_deg": theta}
        return abs(frame_modes(fitted_b, pose, 1).freq_hz[0] / frame_modes(fitted_a, pose, 1).freq_hz[0] - 1)

    advised = float(v.next_measurements[0].pose.split("=")[1])
    assert advised > max(MEASURED) or advised < min(MEASURED)
    assert apart(advised) > 3 * NOISE and apart(82.5) < NOISE
    assert v.next_measurements[0].decide_chance > 0.5

    def after(theta: float):
        return diagnose(rig, _table(real, (*MEASURED, theta), 0), effects=EFFECTS).verdict

    there = after(advised)
    assert (there.effect, there.location) == ("link_mass", "link2") and not there.ambiguous
    assert all(after(theta).ambiguous for theta in (62.5, 70.0, 77.5, 85.0))     # inside the range


def test_a_rival_that_only_adds_a_component_gets_no_advice():
    """A tip mass with a base stiffness + tip mass alongside (nested: the extra component's gain is
    judged by the nested margin, and one more pose decides it by its noise) is not a rival a pose is
    advised against; a link mass is (another effect)."""
    tip = {"_cand": Candidate(("tip_mass",), ("tip",), ())}
    both = {"_cand": Candidate(("base_stiffness", "tip_mass"), ("base", "tip"), ())}
    link = {"_cand": Candidate(("link_mass",), ("link2",), ())}
    assert adds_to(tip, both) and not adds_to(both, tip) and not adds_to(tip, link) and not adds_to(tip, tip)
    assert next_measurements(None, tip, [both], 0.005) == []          # decided before any pose is tried
