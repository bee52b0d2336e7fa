"""The blind self-check's case generator and a short blind run (the 30-case run is benchmarks/)."""

from __future__ import annotations

import numpy as np

from flexmodal.compare.selftest import N_MODES, POSES_DEG, _modes, format_summary, make_case, run_selftest


def test_cases_hide_an_effect_with_a_gap_above_the_noise():
    rng = np.random.default_rng(3)
    rig, table, effect, location, params, scatter = make_case(rng, with_effect=True)
    assert 0.003 <= scatter <= 0.009 and effect != "none" and params
    nominal = np.array([f for f, _ in _modes(rig, "none", "", {})])          # sensor-visible modes
    measured = np.array([table.freq_hz(f"theta{t:g}") for t in POSES_DEG])
    assert measured.shape == nominal.shape == (len(POSES_DEG), N_MODES)
    assert table.sensors == [s.name for s in rig.sensors]
    gap = np.sqrt(np.mean((nominal / measured - 1) ** 2))
    assert 0.03 - 3 * scatter < gap < 0.25 + 3 * scatter


def test_short_blind_run_reports_accuracy():
    s = run_selftest(2, seed=7, progress=False)
    assert s["n_cases"] == 2 and s["n_with_effect"] == 2
    assert s["top1_effect_accuracy"] == 1.0 and s["location_accuracy"] == 1.0
    assert s["heldout_after_mean"] < s["heldout_before_mean"] / 5
    assert "top-1 effect accuracy: 100.0%" in format_summary(s)
