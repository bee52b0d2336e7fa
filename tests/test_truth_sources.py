"""What the simulators and the blind self-check emit as "the real arm" comes from the independent truth
model (fixtures/truth_arm.py), not from the FE model the diagnosis fits (models/frame.py)."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.fixtures.demo import DEMO_EFFECTS
from flexmodal.fixtures.rig_sim import DEMO_RIG, simulate
from flexmodal.fixtures.sim_source import sim_source
from flexmodal.fixtures.truth_arm import TruthOptions, bench_arm, truth_modes
from flexmodal.modal.compute import frf_of_record
from flexmodal.modal.identify import identify
from flexmodal.modal.oma import identify_output_only
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig

POSE = {"theta_deg": 30.0}


def _truth_and_fe_hz(n: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """The first ``n`` natural frequencies of the demo arm with the demo's hidden elbow spring: the
    simulators' real arm and the diagnosis's FE model."""
    rig = load_rig(DEMO_RIG)
    real = simulate(rig, POSE, duration_s=0.1, effects=DEMO_EFFECTS, truth=bench_arm(rig)).natural_freq_hz
    fe = simulate(rig, POSE, duration_s=0.1, effects=DEMO_EFFECTS).natural_freq_hz
    return real[:n], fe[:n]


@pytest.mark.parametrize("test", ["impact", "random", "sweep", "operational"])
def test_sim_source_emits_the_bench_arm_for_every_test(test):
    """Every test type of ``sim serve``: the emitted record is the truth path's noise-free record of the
    same seed within 2 % RMS on every analog channel, the strain gauge included (sensor noise at 50 dB,
    16-bit steps; clipped samples left out), and within half a count on the encoder; the FE path's
    record is > 10 % away on some channel."""
    rig = load_rig(DEMO_RIG)
    src = sim_source(None, test, 1024.0, record_s=2.0, seed=4, effects=DEMO_EFFECTS)
    assert {"strain", "encoder"} <= {c.kind for c in src.channels}
    emitted = src.physical(0, src.counts.shape[0])
    ok = np.all(np.abs(src.counts) < 2**15 - 1, axis=1)
    assert ok.sum() > 200
    deg = np.array([360.0 / 4096 if c.kind == "encoder" else 1.0 for c in src.channels])

    enc = deg != 1.0

    def misfit(truth) -> tuple[np.ndarray, float]:
        sim = simulate(rig, POSE, excitation=test, duration_s=2.0, sample_rate_hz=1024.0, seed=4,
                       strain_gauges=("link1@0.1",), pulse_width_s=4 / 1024.0, effects=DEMO_EFFECTS,
                       truth=truth)
        assert [c.name for c in sim.channels] == [c.name for c in src.channels]
        clean, diff = sim.clean[ok] * deg, emitted[ok] - sim.clean[ok] * deg
        rel = np.sqrt(np.mean(diff[:, ~enc] ** 2, axis=0) / np.mean(clean[:, ~enc] ** 2, axis=0))
        return rel, float(np.max(np.abs(diff[:, enc]) / deg[enc]))

    rel, counts = misfit(bench_arm(rig))
    assert np.max(rel) < 0.02 and counts <= 0.5 + 1e-9, (rel, counts)
    assert np.max(misfit(None)[0]) > 0.1


def test_impact_from_the_serial_source_identifies_the_truth_not_the_fe_model():
    """pLSCF on the simulator's impact record at theta 30: the frequencies are the truth model's within
    0.1 %, and the diagnosis's FE model (with the same hidden spring) is > 0.5 % away on every mode."""
    real, fe = _truth_and_fe_hz()
    src = sim_source(None, "impact", 2048.0, seed=0, effects=DEMO_EFFECTS)
    x = src.physical(0, src.counts.shape[0])
    kinds = [c.kind for c in src.channels]
    keep = [i for i, k in enumerate(kinds) if k in ("force", "acceleration")]
    force = x[:, kinds.index("force")]
    triggers = list(np.flatnonzero((force[1:] > 5.0) & (force[:-1] <= 5.0)) + 1)
    res = frf_of_record(x[:, keep], 2048.0, [src.channels[i].name for i in keep], [kinds[i] for i in keep],
                        excitation="impact", triggers=triggers, nfft=4096,
                        window="force:0.02,exponential:0.05")
    modes = identify(res.freq_hz, res.H, fmin=5.0, fmax=450.0, decay_rate_per_s=res.decay_rate_per_s)
    found = np.array([modes.freq_hz[np.argmin(np.abs(modes.freq_hz - f))] for f in real])
    np.testing.assert_allclose(found, real, rtol=1e-3)
    assert np.min(np.abs(found / fe - 1)) > 5e-3, (found, fe)


def test_operational_source_identifies_the_truth_not_the_fe_model():
    """SSI on 30 s of ``sim serve --test operational`` at theta 30: the truth model's first three modes
    within 0.5 %, each > 0.5 % from the FE model's (the diagnosis's own)."""
    real, fe = _truth_and_fe_hz()
    src = sim_source(None, "operational", 2048.0, record_s=30.0, seed=2, effects=DEMO_EFFECTS)
    result, _ = identify_output_only(src.physical(0, src.counts.shape[0]), 2048.0,
                                     [c.name for c in src.channels], [c.kind for c in src.channels],
                                     fmin=20.0, fmax=450.0)
    found = np.array([result.modes.freq_hz[np.argmin(np.abs(result.modes.freq_hz - f))] for f in real])
    np.testing.assert_allclose(found, real, rtol=5e-3)
    assert np.min(np.abs(found / fe - 1)) > 5e-3, (found, fe)


def test_blind_self_check_measures_the_truth_model():
    """``diagnose --selftest`` (fixtures/blind.py) measures its arms with the Timoshenko truth model: a
    case's noise-free frequencies are ``truth_modes``'s, not models/frame.py's (> 0.1 % apart)."""
    from flexmodal.fixtures.blind import _measure, random_rig

    rig = random_rig(np.random.default_rng(5), "two_link")
    poses = [{"theta_deg": 0.0}, {"theta_deg": 90.0}]
    freq, _ = _measure(rig, poses, 3, TruthOptions(), ())
    for k, pose in enumerate(poses):
        np.testing.assert_array_equal(freq[k], truth_modes(rig, pose, 8).freq_hz[:3])
        fe = frame_modes(rig, pose, 6).freq_hz
        assert np.max(np.abs(freq[k] / fe[fe > 1e-3][:3] - 1)) > 1e-3


def test_full_scale_by_kind_names_a_missing_kind():
    """``simulate(full_scale={kind: value})`` (the simulators' ADC chain) refuses a record with a channel
    kind it does not cover, naming the kind."""
    from flexmodal.fixtures.errors import FixtureError

    rig = load_rig(DEMO_RIG)
    with pytest.raises(FixtureError, match="no value for channel kind 'acceleration'"):
        simulate(rig, POSE, duration_s=0.1, full_scale={"force": 500.0}, truth=bench_arm(rig))
    test = simulate(rig, POSE, duration_s=0.1, full_scale={"force": 500.0, "acceleration": 20.0})
    np.testing.assert_array_equal(test.full_scale, [500.0] + [20.0] * len(rig.sensors))
