"""Output-only identification uncertainty (modal/oma_uncertainty.py, the sigma of modal/ssi.py and
modal/fdd.py): the jackknife against its closed form, the SSI bootstrap's replicate statistic against
the estimate and its sigma against the jackknife where that is exact, sigma on and off, the decay-time
guard, and a Monte-Carlo coverage under -m slow (the 150-record figures are in docs/diagnosis.md)."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
import scipy.linalg
from threadpoolctl import threadpool_limits

from flexmodal.fixtures.modal_coverage import SAMPLE_RATE_HZ, oma_coverage, two_mode_record
from flexmodal.modal import oma_uncertainty, ssi
from flexmodal.modal.fdd import fdd
from flexmodal.modal.oma_uncertainty import N_BLOCKS
from flexmodal.modal.ssi import ssi_cov


def test_doctests() -> None:
    assert doctest.testmod(oma_uncertainty).failed == 0


def _jackknife_std(estimates: np.ndarray) -> np.ndarray:
    """Delete-one jackknife standard deviation [...] of estimates [n_b, ...] each made without one
    block, ``sqrt((n_b - 1) / n_b sum_j (theta_(-j) - mean)^2)`` (Efron & Stein 1981): the independent
    reference of the bootstrap below."""
    n_b = estimates.shape[0]
    return np.sqrt((n_b - 1) / n_b * np.sum((estimates - estimates.mean(axis=0)) ** 2, axis=0))


def test_jackknife_of_the_mean_is_the_standard_error_and_the_bootstrap_draws_blocks() -> None:
    """For the mean, the delete-one jackknife is exactly the standard error s / sqrt(n) (Efron & Stein
    1981), here for 13 values and two columns; the bootstrap's weights draw n blocks per replicate,
    each block with probability 1/n (mean count 1), the same for the same seed."""
    x = np.random.default_rng(1).normal(size=(13, 2)) * [1.0, 3.0]
    replicates = (x.sum(axis=0) - x) / (x.shape[0] - 1)
    np.testing.assert_allclose(_jackknife_std(replicates), x.std(axis=0, ddof=1) / np.sqrt(x.shape[0]),
                               rtol=1e-12)
    w = oma_uncertainty.bootstrap_weights(13, 4000)
    assert np.all(w.sum(axis=1) == 13)
    np.testing.assert_allclose(w.mean(axis=0), 1.0, atol=0.06)      # sd of the mean count ~0.015
    np.testing.assert_array_equal(w, oma_uncertainty.bootstrap_weights(13, 4000))


def test_sigma_leaves_the_modes_alone_and_follows_the_record_length() -> None:
    """The standard deviations do not change the identified modes; with ``uncertainty_blocks=0`` (the
    default of ssi_cov and fdd; ``identify`` asks for N_BLOCKS) there is none.  FDD: a record four
    times longer gives roughly half the sigma (1/sqrt(T): between 0.3x and 0.8x for this draw).  SSI
    at its default orders does not scale so (0.057 Hz at 480 s and at 120 s here; the estimates'
    own scatter hardly does either, docs/diagnosis.md), so no such check is made for it."""
    rng = np.random.default_rng(2)
    long = two_mode_record(rng, 480.0, np.array([0.02, 0.016]))[:, 1:]
    short = long[: long.shape[0] // 4]
    for run, options in ((ssi_cov, {}), (fdd, {"nfft": 1024})):    # FDD: the same lines for both
        plain = run(long, SAMPLE_RATE_HZ, fmin=10.0, fmax=40.0, uncertainty_blocks=0, **options).modes
        assert plain.freq_std_hz is None
        a = run(long, SAMPLE_RATE_HZ, fmin=10.0, fmax=40.0, uncertainty_blocks=N_BLOCKS, **options).modes
        np.testing.assert_array_equal(a.freq_hz, plain.freq_hz)
        np.testing.assert_array_equal(a.damping_ratio, plain.damping_ratio)
        assert np.all(np.isfinite(a.freq_std_hz[:1])) and np.all(a.freq_std_hz > 0)
    b = fdd(short, SAMPLE_RATE_HZ, fmin=10.0, fmax=40.0, uncertainty_blocks=N_BLOCKS, nfft=1024).modes
    ratio = a.freq_std_hz[0] / b.freq_std_hz[int(np.argmin(np.abs(b.freq_hz - a.freq_hz[0])))]
    assert 0.3 < ratio < 0.8, ratio


def test_a_mode_decaying_over_more_than_half_a_block_gets_no_sigma() -> None:
    """Damping 0.1 % at 20 Hz decays over 8 s; 20 blocks of 60 s record are 3 s each: no sigma."""
    y = two_mode_record(np.random.default_rng(3), 60.0, np.array([0.001, 0.02]))[:, 1:]
    m = ssi_cov(y, SAMPLE_RATE_HZ, fmin=10.0, fmax=40.0, uncertainty_blocks=N_BLOCKS).modes
    k = int(np.argmin(np.abs(m.freq_hz - 20.0)))
    assert np.isnan(m.freq_std_hz[k]) and np.isnan(m.damping_std[k])


def _block_hankels(y: np.ndarray, s: int, n_b: int) -> np.ndarray:
    """The block Hankel matrices [n_b, s n_ch, s n_ch] of ``n_b`` contiguous blocks of ``y`` (as
    modal/ssi.py's sigma builds them; references: all channels)."""
    lag = np.arange(s)[:, None] + np.arange(s)[None, :] + 1
    n_ch, length = y.shape[1], y.shape[0] // n_b
    return np.stack([ssi.covariances(y[j * length:(j + 1) * length], range(n_ch), 2 * s)[lag]
                     .transpose(0, 2, 1, 3).reshape(s * n_ch, s * n_ch) for j in range(n_b)])


def test_ssi_replicate_statistic_is_the_estimate_and_its_bootstrap_matches_the_jackknife() -> None:
    """The SSI sigma's replicate statistic (ssi._medians: each stable pole re-identified at its order,
    the medians of modal.lscf.chain_medians) gives back the reported frequencies and damping ratios
    exactly from the record's own Hankel matrix; and at the system's true order (4), where a pole is a
    smooth function of the covariances and the delete-one-block jackknife is right (Monte-Carlo in
    modal/oma_uncertainty.py), the bootstrap's sigma of that pole agrees with the jackknife's from the
    same 15 blocks within 25 % (both carry ~20 % random error, mostly shared)."""
    y = two_mode_record(np.random.default_rng(4), 240.0, np.array([0.02, 0.016]))[:, 1:]
    kept: dict = {}

    def spy(modes, y_, refs, s, n_blocks, max_order, members, fs):
        kept.update(modes=modes, s=s, max_order=max_order, members=members)
        return modes

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ssi, "_with_std", spy)
        ssi_cov(y, SAMPLE_RATE_HZ, fmin=10.0, fmax=40.0, uncertainty_blocks=N_BLOCKS)
    s, members = kept["s"], kept["members"]
    lag = np.arange(s)[:, None] + np.arange(s)[None, :] + 1
    H = ssi.covariances(y, (0, 1), 2 * s)[lag].transpose(0, 2, 1, 3).reshape(2 * s, 2 * s)
    same = ssi._medians(H, 2, 2, kept["max_order"], members, SAMPLE_RATE_HZ)
    np.testing.assert_allclose(same[:, 0], kept["modes"].freq_hz, rtol=1e-12)
    np.testing.assert_allclose(same[:, 1], kept["modes"].damping_ratio, rtol=1e-10)

    n_b = y.shape[0] // (40 * s)
    blocks = _block_hankels(y, s, n_b)
    U, sv, Vt = scipy.linalg.svd(blocks.mean(axis=0), full_matrices=False)
    mu = scipy.linalg.eigvals(ssi._Realisations(U, sv, Vt, 2, 2, 4).X(4)).astype(complex)
    lam = np.log(mu[mu.imag > 0]) * SAMPLE_RATE_HZ
    order4 = [(np.array([4]), np.array([p])) for p in lam]          # one member each, at order 4

    def stat(weights: np.ndarray) -> np.ndarray:
        return ssi._medians(np.tensordot(weights, blocks, 1) / weights.sum(), 2, 2, 4, order4,
                            SAMPLE_RATE_HZ)

    with threadpool_limits(1, "blas"):                   # small SVDs: threads only spin on them
        boot = np.std([stat(w) for w in oma_uncertainty.bootstrap_weights(n_b, 60)], axis=0, ddof=1)
        jack = _jackknife_std(np.array([stat(1.0 - np.eye(n_b)[j]) for j in range(n_b)]))
    boot *= np.sqrt(n_b / (n_b - 1.0))
    np.testing.assert_allclose(boot, jack, rtol=0.25)


@pytest.mark.slow
def test_monte_carlo_coverage_of_the_ssi_intervals() -> None:
    """60 output-only records (240 s, damping 2 %): the SSI intervals of both modes cover the true
    frequency and damping in 85-100 % of runs (binomial sd ~2.8 % at 60 runs), and the normalised
    errors' sd is between 0.75 and 1.3 (1 when the sigma is right; the 150-record figures of every
    setting are in docs/diagnosis.md)."""
    c = oma_coverage(60, seed=9, zeta=0.02, seconds=240.0, method="ssi")
    assert min(c["found"]) >= 0.9
    for value in c["freq"] + c["damping"]:
        assert 0.85 <= value <= 1.0
    for value in c["z_sd_freq"] + c["z_sd_damping"]:
        assert 0.75 <= value <= 1.3


def test_interval_factor_is_the_student_quantile_of_the_sigmas_degrees_of_freedom() -> None:
    """With replicates enough to leave only the blocks' scatter, the factor times 1.96 is Student's
    t_0.975 of n_b - 1 degrees of freedom (tabulated: 2.776, 2.262, 2.045 for 4, 9, 29); with as many
    replicates as blocks, 20, the degrees of freedom are 2 / (a + b + ab), a = b = 2/19: 9.03 (t 2.261)."""
    z = 1.959963984540054
    for n_b, t in ((5, 2.776), (10, 2.262), (30, 2.045)):
        assert oma_uncertainty.interval_factor(n_b, 10**12) * z == pytest.approx(t, abs=5e-4)
    assert oma_uncertainty.interval_factor(20, 20) * z == pytest.approx(2.261, abs=1e-3)


def test_fdd_gives_every_mode_it_finds_a_sigma() -> None:
    """A record (damping 0.5 %, 240 s) on which the replicates' own EFDD checks failed for the 27 Hz mode
    in more than a quarter of them (no sigma before): with the record's bell and no detection checks in
    the replicates, every mode FDD finds has a finite sigma, and the modes themselves are unchanged."""
    y = two_mode_record(np.random.default_rng(6), 240.0, np.array([0.005, 0.004]))[:, 1:]
    plain = fdd(y, SAMPLE_RATE_HZ, fmin=10.0, fmax=40.0).modes
    m = fdd(y, SAMPLE_RATE_HZ, fmin=10.0, fmax=40.0, uncertainty_blocks=N_BLOCKS).modes
    np.testing.assert_array_equal(m.freq_hz, plain.freq_hz)
    assert np.all(np.isfinite(m.freq_std_hz)) and np.all(m.freq_std_hz > 0)
    assert np.all(np.isfinite(m.damping_std)) and np.all(m.damping_std > 0)


@pytest.mark.slow
def test_monte_carlo_coverage_of_the_fdd_intervals() -> None:
    """60 output-only records (240 s, damping 2 %): every mode found has a sigma in at least 95 % of
    runs, and FDD's frequency intervals cover the truth in 85-100 % of them (binomial sd ~2.8 %; the
    150-record figures of every setting are in docs/diagnosis.md)."""
    c = oma_coverage(60, seed=9, zeta=0.02, seconds=240.0, method="fdd")
    assert min(c["found"]) >= 0.95
    for value in c["freq"]:
        assert 0.85 <= value <= 1.0
