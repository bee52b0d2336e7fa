"""The simulated rig against closed-form answers (Blevins 1979, clamped-free uniform beam)."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.fixtures.rig_sim import HiddenEffect, simulate
from flexmodal.models.rig import parse_rig

E, RHO, W, H, L = 70e9, 2700.0, 0.030, 0.010, 0.8
# Euler-Bernoulli (no rotary inertia) so that Blevins' formula is the exact answer.
BEAM = {
    "name": "cantilever",
    "link": [{"name": "beam", "length_m": L, "elements": 40,
              "section": {"shape": "custom", "EA_N": E * W * H, "EI_Nm2": E * W * H**3 / 12,
                          "mass_per_m_kg": RHO * W * H, "rotary_inertia_per_m_kgm": 0.0, "depth_m": H}}],
    "base": {"support": "clamped"},
    "sensor": [{"name": "tip", "at": "beam@1.0"}, {"name": "mid", "at": "beam@0.5"}],
}
LAMBDA = np.array([1.8751, 4.6941, 7.8548])


def blevins_hz() -> np.ndarray:
    EI, m = E * W * H**3 / 12, RHO * W * H
    return LAMBDA**2 / (2 * np.pi * L**2) * np.sqrt(EI / m)


def test_clamped_free_beam_frequencies_within_0p1_percent_of_blevins() -> None:
    test = simulate(parse_rig(BEAM), {}, excitation="impact", duration_s=2.0, sample_rate_hz=4096.0,
                    damping_ratio=0.0, snr_db=80.0)
    np.testing.assert_allclose(test.natural_freq_hz[:3], blevins_hz(), rtol=1e-3)


def test_driving_point_frf_peaks_at_blevins_frequencies_within_one_line() -> None:
    test = simulate(parse_rig(BEAM), {}, excitation="impact", duration_s=8.0, sample_rate_hz=2048.0,
                    damping_ratio=0.005, force_at="beam@1.0")
    df = 1.0 / 8.0
    freq = np.arange(0.0, 1024.0, df)
    h_tip = np.abs(test.exact_frf(freq)[0, 0])  # driving point: force and sensor at the tip
    for f_exact in blevins_hz():
        band = (freq > 0.8 * f_exact) & (freq < 1.2 * f_exact)
        peak = freq[band][np.argmax(h_tip[band])]
        assert abs(peak - f_exact) <= df


def test_simulated_record_matches_its_exact_frf() -> None:
    """The force-to-tip-acceleration spectrum ratio of a noise-free impact equals the exact FRF."""
    test = simulate(parse_rig(BEAM), {}, excitation="impact", duration_s=16.0, sample_rate_hz=2048.0,
                    damping_ratio=0.02, hit_period_s=20.0, snr_db=200.0, adc_bits=40)
    freq = np.fft.rfftfreq(test.clean.shape[0], 1 / test.sample_rate_hz)
    spectra = np.fft.rfft(test.clean, axis=0)
    ratio = spectra[:, 1] / spectra[:, 0]
    exact = test.exact_frf(freq)[0, 0]
    band = (freq > 5) & (freq < 300)
    np.testing.assert_allclose(ratio[band], exact[band], rtol=1e-6)


def test_hidden_joint_stiffness_lowers_frequencies_and_shows_on_the_encoder(rigs_dir) -> None:
    from flexmodal.models.rig import load_rig

    rig = load_rig(rigs_dir / "demo_arm.toml")
    nominal = simulate(rig, {"theta_deg": 30.0}, duration_s=2.0)
    soft = simulate(rig, {"theta_deg": 30.0}, duration_s=2.0,
                    effects=(HiddenEffect("joint_stiffness", "elbow", {"k_Nm_per_rad": 3000.0}),))
    assert np.all(soft.natural_freq_hz[:2] < nominal.natural_freq_hz[:2])
    assert "enc_elbow" not in [c.name for c in nominal.channels]
    enc = [c.name for c in soft.channels].index("enc_elbow")
    assert np.ptp(soft.samples[:, enc]) >= 1  # whole counts of elbow deflection under the hammer
    assert np.all(soft.samples[:, enc] == np.round(soft.samples[:, enc]))


def test_clipping_is_recorded_as_overload_events() -> None:
    test = simulate(parse_rig(BEAM), {}, duration_s=2.0, full_scale=[5.0, 1.0, 1.0])
    overloads = [e for e in test.events if e.kind == "overload"]
    assert overloads and all(e.count > 0 for e in overloads)
    assert np.max(np.abs(test.samples[:, 1])) <= 1.0


def test_bad_excitation_is_a_fixture_error() -> None:
    from flexmodal.fixtures.errors import FixtureError

    with pytest.raises(FixtureError, match="excitation"):
        simulate(parse_rig(BEAM), {}, excitation="earthquake")
