"""Known answers for the modal-superposition simulator (fixtures/modal_sim.py)."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.fixtures.errors import FixtureError
from flexmodal.fixtures.modal_sim import modal_frf, modal_response

FS = 1000.0
FN = np.array([10.0, 55.0])
ZETA = np.array([0.02, 0.01])
PHI_OUT = np.array([[1.0, 0.5], [0.3, -1.0]])
PHI_IN = np.array([[0.7, 0.2]])


def test_impulse_response_spectrum_equals_discrete_frf() -> None:
    n = 2**16
    impulse = np.zeros((n, 1))
    impulse[0] = 1.0
    for quantity in ("displacement", "velocity", "acceleration"):
        y = modal_response(impulse, FS, FN, ZETA, PHI_OUT, PHI_IN, quantity)
        freq = np.fft.rfftfreq(n, 1 / FS)
        expected = modal_frf(freq, FN, ZETA, PHI_OUT, PHI_IN, quantity, sample_rate_hz=FS)[:, 0, :]
        got = np.fft.rfft(y, axis=0).T
        assert np.max(np.abs(got - expected)) <= 1e-9 * np.max(np.abs(expected))


def test_first_order_hold_is_exact_for_a_ramp() -> None:
    """Steady-state displacement of an SDOF under u = t is (t - 2ζ/ω)/ω² exactly."""
    t = np.arange(20000) / FS
    w, z = 2 * np.pi * 10.0, 0.05
    x = modal_response(t[:, None], FS, np.array([10.0]), np.array([z]), np.ones((1, 1)), np.ones((1, 1)),
                       "displacement")
    assert x[-1, 0] == pytest.approx((t[-1] - 2 * z / w) / w**2, rel=1e-9)


def test_continuous_frf_matches_sdof_formula_and_sampled_one_at_low_frequency() -> None:
    f = np.array([2.0, 10.0, 30.0])
    w, wr = 2 * np.pi * f, 2 * np.pi * 10.0
    h = modal_frf(f, [10.0], [0.02], [[1.0]], [[1.0]], "displacement")[0, 0]
    np.testing.assert_allclose(h, 1 / (wr**2 - w**2 + 2j * 0.02 * wr * w), rtol=1e-12)
    hd = modal_frf(f, [10.0], [0.02], [[1.0]], [[1.0]], "displacement", sample_rate_hz=10_000.0)[0, 0]
    np.testing.assert_allclose(hd, h, rtol=2e-3)


def test_bad_modal_model_is_rejected() -> None:
    with pytest.raises(FixtureError, match="Nyquist"):
        modal_response(np.zeros((10, 1)), 100.0, [60.0], [0.01], [[1.0]], [[1.0]])
    with pytest.raises(FixtureError, match="quantity"):
        modal_frf([1.0], [10.0], [0.01], [[1.0]], [[1.0]], "jerk")


def test_block_wise_response_equals_scipy_lsim_across_block_boundaries(monkeypatch) -> None:
    """Blocks carry each mode's filter state: with blocks of 1000 samples, two inputs of random force
    give the response scipy's lsim computes over the whole record (linear interpolation of the input,
    i.e. first-order hold, of the continuous state-space system) to 1e-9 of its peak.  The simulator's
    record starts at rest with the force ramping from 0 over the sample before it, so lsim is given
    that zero sample first."""
    from scipy import signal

    from flexmodal.fixtures import modal_sim

    monkeypatch.setattr(modal_sim, "BLOCK_SAMPLES", 1000)
    n = 4321
    force = np.random.default_rng(4).standard_normal((n, 2))
    phi_in = np.vstack([PHI_IN, [[-0.4, 0.9]]])
    y = modal_response(force, FS, FN, ZETA, PHI_OUT, phi_in, "displacement")
    w = 2 * np.pi * FN
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.diag(w**2), -np.diag(2 * ZETA * w)]])
    B = np.vstack([np.zeros((2, 2)), phi_in.T])
    C = np.hstack([PHI_OUT, np.zeros((2, 2))])
    t = np.arange(n + 1) / FS
    _, expected, _ = signal.lsim((A, B, C, np.zeros((2, 2))), np.vstack([np.zeros(2), force]), t, interp=True)
    expected = expected[1:]
    assert np.max(np.abs(y - expected)) <= 1e-9 * np.max(np.abs(expected))
