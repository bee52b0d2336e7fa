"""Output-only identification (modal/ssi.py, modal/fdd.py) against the exact modes of a simulated
5-storey shear frame under white-noise floor forces (fixtures/shear_frame.py), plus the covariances
against direct sums and the cross-spectra against scipy."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.contract.mac import mac
from flexmodal.fixtures.shear_frame import shear_frame_modes, shear_frame_record
from flexmodal.modal.errors import ModalError
from flexmodal.modal.fdd import cross_spectra, fdd
from flexmodal.modal.ssi import covariances, ssi_cov

MASS = [3000.0, 2800.0, 2600.0, 2400.0, 2000.0]
STIFF = [9.6e7, 8.8e7, 8.0e7, 7.2e7, 6.4e7]
ZETA = [0.002, 0.005, 0.01, 0.015, 0.02]


@pytest.fixture(scope="module")
def frame():
    """10 min at 256 Hz, 5 % sensor noise: the acceptance record (modes 8.7 .. 52.5 Hz)."""
    return shear_frame_record(MASS, STIFF, ZETA, duration_s=600.0, sample_rate_hz=256.0,
                              noise_fraction=0.05, seed=0)


def _errors(modes, rec):
    assert modes.freq_hz.size == rec.freq_hz.size, modes.freq_hz
    m = mac(modes.shapes, rec.shapes)
    return (np.abs(modes.freq_hz / rec.freq_hz - 1), np.abs(modes.damping_ratio / rec.damping_ratio - 1),
            np.diag(m))


def test_shear_frame_modes_match_the_two_storey_closed_form():
    m, k = 2.0, 800.0   # two equal storeys: w^2 = (3 -+ sqrt 5)/2 k/m
    fn, phi = shear_frame_modes([m, m], [k, k])
    assert np.allclose((2 * np.pi * fn) ** 2, (3 - np.array([1, -1]) * np.sqrt(5)) / 2 * k / m, rtol=1e-12)
    assert np.allclose(phi.T @ np.diag([m, m]) @ phi, np.eye(2), atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1])
def test_ssi_cov_finds_all_five_modes_of_the_shear_frame(seed):
    rec = shear_frame_record(MASS, STIFF, ZETA, seed=seed)
    res = ssi_cov(rec.samples, rec.sample_rate_hz, max_order=100)
    df, dz, macs = _errors(res.modes, rec)
    assert df.max() < 0.002 and dz.max() < 0.25 and macs.min() >= 0.99, (df, dz, macs)
    assert not res.modes.mass_normalised
    assert np.allclose(np.abs(res.modes.complex_shapes).max(axis=0), 1.0)   # unscaled: unit maximum
    assert res.stabilisation.stable.sum() > 5 * 20


def test_ssi_cov_with_two_reference_channels_and_a_band(frame):
    res = ssi_cov(frame.samples, frame.sample_rate_hz, references=[0, 4], max_order=60, fmin=5, fmax=60)
    df, dz, macs = _errors(res.modes, frame)
    assert res.references == (0, 4) and res.sample_rate_hz == 256.0  # 2.5 x fmax > fs / 2: not decimated
    assert df.max() < 0.002 and dz.max() < 0.25 and macs.min() >= 0.99, (df, dz, macs)


def test_covariances_equal_the_direct_unbiased_sums():
    rng = np.random.default_rng(3)
    y = rng.standard_normal((500, 3))
    R = covariances(y, [2, 0], 7)
    yc = y - y.mean(axis=0)
    for i in (0, 1, 7):
        direct = yc[i:].T @ yc[: 500 - i, [2, 0]] / (500 - i)
        assert np.allclose(R[i], direct, rtol=1e-12, atol=1e-14)


def test_covariances_with_gaps_sum_over_valid_pairs_only():
    rng = np.random.default_rng(4)
    y = rng.standard_normal((400, 2))
    y[50:60] = np.nan
    y[200] = np.nan
    R = covariances(y, [0, 1], 5)
    valid = ~np.isnan(y).any(axis=1)
    yc = np.where(valid[:, None], y - y[valid].mean(axis=0), 0.0)
    for i in (0, 3, 5):
        both = valid[i:] & valid[: 400 - i]
        direct = (yc[i:][both]).T @ yc[: 400 - i][both] / both.sum()
        assert np.allclose(R[i], direct, rtol=1e-12, atol=1e-14)


def test_ssi_and_fdd_on_a_record_with_gaps(frame):
    y = frame.samples.copy()
    for start in range(10_000, y.shape[0], 30_000):   # 0.5 s lost every ~2 min
        y[start:start + 128] = np.nan
    for modes in (ssi_cov(y, 256.0).modes, fdd(y, 256.0).modes):
        df, _, macs = _errors(modes, frame)
        assert df.max() < 0.002 and macs.min() >= 0.99, (df, macs)


def test_fdd_finds_the_shear_frame_modes(frame):
    res = fdd(frame.samples, frame.sample_rate_hz)
    df, dz, macs = _errors(res.modes, frame)
    assert df.max() < 0.002 and macs.min() >= 0.99, (df, macs)
    # EFDD damping: the 0.2 % mode's bell holds ~1 line (Hann leakage); the others within 20 %
    assert dz[1:].max() < 0.2, dz
    assert res.singular_values.shape == (5, res.freq_hz.size)
    assert np.all(np.diff(res.singular_values, axis=0) <= 1e-12 * res.singular_values[0])


def test_cross_spectra_match_scipy_csd():
    import scipy.signal

    rng = np.random.default_rng(5)
    y = rng.standard_normal((4096, 3))
    f, G = cross_spectra(y, 100.0, [1], 256)   # G_jk = E[Y_j Y_k*]: scipy.signal.csd(y_k, y_j)
    f2, g = scipy.signal.csd(y[:, 1], y[:, 2], fs=100.0, nperseg=256, window="hann", detrend="constant")
    assert np.allclose(f, f2) and np.allclose(G[:, 2, 0], g, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("call, message", [
    (lambda y: ssi_cov(y, 256.0, references=[7]), "reference channels"),
    (lambda y: ssi_cov(y[:100], 256.0), "too few"),
    (lambda y: ssi_cov(np.where(np.arange(y.shape[0])[:, None] == 5, np.inf, y), 256.0), "infinite"),
    (lambda y: ssi_cov(np.where(np.arange(y.shape[0])[:, None] % 3 > 0, np.nan, y), 256.0), "gaps"),
    (lambda y: ssi_cov(y, 256.0, max_order=100, block_rows=10), "cannot hold"),
    (lambda y: fdd(y, 256.0, nfft=10 ** 7), "does not fit"),
])
def test_bad_input_is_one_clear_error(frame, call, message):
    with pytest.raises(ModalError, match=message):
        call(frame.samples[:20000])


def test_fdd_of_white_noise_finds_no_mode():
    y = np.random.default_rng(0).standard_normal((4096, 2))
    with pytest.raises(ModalError, match="a noise peak, not a mode"):
        fdd(y, 256.0)


def test_lowest_spectral_peak_is_the_lowest_line_above_the_drift():
    """The lowest frequency SSI is sized for when FDD validates no mode: a sinusoid on line 40 of FDD's
    spectrum, under a random-walk drift whose leakage peaks at line 1 (a measured record's did), is the
    lowest peak, exactly on its line."""
    from flexmodal.modal.oma import lowest_spectral_peak
    from flexmodal.modal.spectra import default_nfft

    fs, n = 10.0, 2**15
    f0 = 40 * fs / default_nfft(n)
    t = np.arange(n) / fs
    rng = np.random.default_rng(0)
    y = np.column_stack([np.sin(2 * np.pi * f0 * t), 0.5 * np.sin(2 * np.pi * f0 * t + 1)])
    y += 0.01 * rng.standard_normal((n, 2)) + 0.05 * np.cumsum(rng.standard_normal((n, 1)), axis=0)
    assert lowest_spectral_peak(y, fs, None, None) == pytest.approx(f0, rel=1e-12)
    assert lowest_spectral_peak(y, fs, [0], 0.5 * f0) is None          # nothing below fmax
