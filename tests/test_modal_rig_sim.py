"""Identification on the simulated demo arm (fixtures.rig_sim, FE modes): impact and random tests at
40 dB SNR against the simulator's exact natural frequencies, damping ratios and shapes."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.contract.mac import mac
from flexmodal.fixtures.rig_sim import simulate
from flexmodal.modal.compute import frf_of_record
from flexmodal.modal.identify import identify
from flexmodal.models.rig import load_rig

ZETA = [0.005, 0.01, 0.02, 0.05, 0.01, 0.02, 0.01, 0.02, 0.01, 0.02, 0.01, 0.02]


def _check(test, res):
    modes = identify(res.freq_hz, res.H, fmin=2, fmax=150, decay_rate_per_s=res.decay_rate_per_s,
                     max_order=60)
    true = test.natural_freq_hz < 140
    assert true.sum() >= 2
    for k in np.flatnonzero(true):
        j = int(np.argmin(np.abs(modes.freq_hz - test.natural_freq_hz[k])))
        assert abs(modes.freq_hz[j] / test.natural_freq_hz[k] - 1) < 1e-3
        assert abs(modes.damping_ratio[j] / test.damping_ratio[k] - 1) < 0.05
        assert mac(modes.shapes[:, j], test.shapes[:, k])[0, 0] >= 0.99


@pytest.mark.parametrize("excitation", ["impact", "random"])
def test_rig_sim_modes_within_acceptance(rigs_dir, excitation):
    rig = load_rig(rigs_dir / "demo_arm.toml")
    nfft = 16384
    duration = 16.0 if excitation == "impact" else nfft * 25.6 / 512
    test = simulate(rig, {"theta_deg": 30.0}, excitation=excitation, duration_s=duration,
                    sample_rate_hz=512.0, damping_ratio=ZETA, snr_db=40, seed=1, hit_period_s=4.0)
    triggers = [e.sample_index for e in test.events if e.kind == "trigger"] or None
    res = frf_of_record(test.samples, test.sample_rate_hz, [c.name for c in test.channels],
                        [c.kind for c in test.channels], excitation=excitation, triggers=triggers,
                        nfft=nfft, window="force:0.02,exponential:0.05" if excitation == "impact" else None)
    assert res.n_averages >= (2 if excitation == "impact" else 50)   # the simulator may double-hit
    _check(test, res)
