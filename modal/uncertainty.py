"""Uncertainty of identified natural frequencies and damping ratios from the FRF's own random error.

``with_uncertainty(modes, freq_hz, H, coherence, n_averages, quantity="accelerance", decay_rate_per_s=0,
welch=None) -> Modes``
    the hook of the identification (modal/sources.py ``identify_frf``, the demo): ``modes`` with
    ``freq_std_hz``/``damping_std`` set and its frequencies and damping ratios refined to the
    maximum-likelihood estimates below (their standard deviations belong to those: a pLSCF pole
    itself scatters about four times more, tests/test_modal_uncertainty.py); a mode whose refined
    pole leaves its half-power band keeps its pLSCF values and gets NaN.  ``welch``
    (:func:`welch_noise`) describes Welch-averaged FRFs (random excitation); None for FRFs without
    leakage (impact records) or of unknown processing.

``modal_uncertainty(freq_hz, H, coherence, n_averages, fn_hz, zeta, quantity="accelerance", ...,
welch=None) -> ModalUncertainty``
    ``freq_std_hz`` [Hz], ``damping_std`` [-] one per mode (NaN where the bands hold too few lines),
    and the refined ``local_freq_hz``/``local_damping`` they belong to.

1. Random error of the FRF estimate (Bendat & Piersol 2010, eq. 9.90): the normalised random error of
   |H| and the standard deviation of its phase [rad] are both ``sqrt(1 - g2) / (|g| sqrt(2 n_d))``
   with ``g2`` the (ordinary or multiple) coherence and ``n_d`` the number of independent averages, so
   the real and imaginary parts of H carry ``sigma = |H| sqrt(1 - g2) / sqrt(2 n_d g2)`` each.
   Overlapping segments are correlated: ``n_d = n_averages / (1 + 2 sum_j c(j D)^2)`` with ``c`` the
   window's normalised autocorrelation at the segment step D (Welch 1967; 0.167 for Hann at 50 %,
   Harris 1978, Table 1).  The errors of lines j apart are correlated by ``|W2[j]|^2``, W2 the
   normalised DFT of the squared window (Hann: 4/9, 1/36): the fit below is whitened by the banded
   Cholesky factor of that correlation.  Without ``welch`` (impact records, stored FRFs) the lines are
   taken as independent with the variance widened by ``enbw_bins`` (1.5, the Hann window's equivalent
   noise bandwidth).
2. On the lines within ``BAND_HALF_WIDTHS`` half-power bandwidths of any mode (at least
   ``MIN_LINES`` per mode), the receptance of every FRF column is the modal model
   ``sum_r A_r / (i w - lambda_r) + B_r / (i w - conj(lambda_r)) + R - S / w^2`` (upper and lower
   residuals R, S), with the poles ``lambda_r = -zeta_r w_r + i w_r sqrt(1 - zeta_r^2)`` shared by
   all columns and residues per column (rational-fraction modal model, Richardson & Formenti 1982).
   A Welch estimate is not that model but its expectation under averaging: for white input
   ``E[G_xy] / G_xx`` is the transform of the impulse response times the window's lag window ``c``
   (Bendat & Piersol 2010 §8.5; Schmidt 1985), so with ``welch`` each pole term is
   ``dt sum_n c[n] exp((lambda - i w) n dt)`` (one FFT per pole) -- the leakage that otherwise biases
   every damping ratio high by several sigma at a few lines per half-power band.
   The residual terms R, S stand for the modes outside the local model, which are no single
   ``R - S / w^2`` across bands far apart when a mode lies between them (a broad mode between two
   light ones; modes beyond the data's band): each run of consecutive lines whose modes have at least
   ``MIN_LINES_PER_BANDWIDTH`` (8) lines in their half-power band carries its own pair (one offset per
   band, as a circle fit's; beam_ring_two_inputs: one pair over 11-58 Hz moved 28.12 Hz to 28.10 Hz,
   where a circle fit of each FRF gives 28.121-28.125 Hz); the runs of coarser modes share one pair
   (over a mode's three half-power bands of 2-8 lines a pair of its own trades off against the mode:
   0.73 % -> 2.3 % damping at 15.94 Hz on lvm_impact_two_hits).
   A few Gauss-Newton steps of variable projection (Golub & Pereyra 1973; Kaufman's Jacobian) from
   the identified poles give their weighted least-squares (maximum-likelihood under 1.) estimates;
   the covariance is the inverse of the Fisher information ``J_p^T (I - P) J_p`` of the poles' real
   and imaginary parts with the residues projected out (``P`` the projection onto their columns;
   Pintelon, Guillaume & Schoukens 2007).
   With ``welch`` and one input, the errors are not the white noise step 1 takes them for: part of
   the coherence loss is the window's leakage (the response to input outside the segment, cut by
   the window), an error the same at every output up to the mode's shape and correlated with a phase
   across neighbouring lines and overlapping segments, which the residues largely absorb.  Its
   covariance and pseudo-covariance across lines and outputs follow exactly from the fitted poles and
   residues (modal/welch_leakage.py); the rest of the coherence loss is output noise (white, lines
   correlated by ``|W2[j]|^2``); with finite averages the residual power has ``n_d - 1`` degrees of
   freedom and ``E[1/sum|X|^2] = 1/((n_d - 1) G_xx)``.  The poles' covariance is then the sandwich
   ``I^-1 J_p^T W C W^T J_p I^-1`` (W the fit's whitening, C that covariance), times
   ``(n_d - 1)/(n_d - 3)`` for weights from a coherence of n_d averages rather than the true
   variances (Schoukens, Pintelon, Vandersteen & Guillaume 1997, Automatica 33:1073) and times the
   fit's residual sum of squares over the one C predicts where that exceeds 1 (the Birge ratio:
   noise larger than the coherence says, or a band the local model does not fit).  Beyond
   ``LEAKAGE_BUDGET`` or with several inputs the inverse information alone, times chi^2 per degree of
   freedom where that exceeds 1 (the leakage counted as white noise: conservative at a few lines per
   half-power band).
3. ``f_n = |lambda| / 2 pi`` and ``zeta = -Re(lambda) / |lambda|``: their standard deviations by the
   delta method.

The model-order and pole-selection choices of the identification are not part of this error (they are
deterministic given the data); ``tests/test_modal_uncertainty.py`` checks the coverage of the
resulting 95 % intervals by Monte-Carlo on simulated records (independent noise realisations of a
two-mode system, H1 estimates, pLSCF identification).

Examples
--------
>>> import numpy as np
>>> f = np.linspace(5.0, 15.0, 201)
>>> w, wn, z = 2 * np.pi * f, 2 * np.pi * 10.0, 0.02
>>> H = (1.0 / (wn**2 - w**2 + 2j * z * wn * w))[None, None]
>>> u = modal_uncertainty(f, H, np.full((1, f.size), 0.99), 50, np.array([10.0]), np.array([0.02]),
...                       quantity="receptance")
>>> bool(0 < u.freq_std_hz[0] < 0.01 and 0 < u.damping_std[0] < 0.002)
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg

from flexmodal.checked_io.blas import one_blas_thread
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import convert
from flexmodal.modal.identify import MIN_LINES_PER_BANDWIDTH, Modes, restated
from flexmodal.modal.windows import window

HANN_50_CORRELATION = 0.167
"""Correlation of consecutive Hann-windowed segments at 50 % overlap (Harris 1978, Table 1)."""
HANN_ENBW_BINS = 1.5
"""Equivalent noise bandwidth of the Hann window in lines (Harris 1978, Table 1): neighbouring lines of
a windowed estimate are correlated, so a band of K lines carries the information of K / 1.5."""
BAND_HALF_WIDTHS = 3.0
"""Half-width of the local fit band in half-power bandwidths (2 zeta f_n)."""
MIN_LINES = 7
MAX_CORRELATED_LINES = 8
LINE_CORRELATION_FLOOR = 1e-4
GAUSS_NEWTON_STEPS = 8
LEAKAGE_BUDGET = 4e6
"""Largest max(outputs, 2 x modes) x band lines x nfft for which the leakage error's covariance is
computed (16 bytes each, a few such arrays); beyond it the lines' errors are the coherence's white noise."""
COHERENCE_MAX = 1.0 - 1e-6


@dataclass(frozen=True)
class ModalUncertainty:
    """One standard deviation of each mode's natural frequency [Hz] and damping ratio [-], and the local
    weighted least-squares estimates they belong to (``local_freq_hz``, ``local_damping``)."""

    freq_std_hz: np.ndarray
    damping_std: np.ndarray
    local_freq_hz: np.ndarray
    local_damping: np.ndarray


def frf_std(H: np.ndarray, coherence: np.ndarray, n_averages: int,
            overlap_correlation: float = HANN_50_CORRELATION) -> np.ndarray:
    """Standard deviation of the real (and of the imaginary) part of each FRF line, same shape as ``H``
    [n_out, n_in, n_freq], from the coherence [n_out, n_freq] (module docstring, step 1)."""
    if n_averages < 1:
        raise ModalError(f"FRF uncertainty: {n_averages} averages (need >= 1)")
    n_d = n_averages / (1.0 + 2.0 * overlap_correlation**2)
    g2 = np.clip(np.asarray(coherence, float), 1e-12, COHERENCE_MAX)[:, None, :]
    return np.abs(H) * np.sqrt((1.0 - g2) / (2.0 * n_d * g2))


def _real(z: np.ndarray) -> np.ndarray:
    """Complex rows [K, ...] stacked as real rows [2K, ...]."""
    return np.concatenate([z.real, z.imag], axis=0)


@dataclass(frozen=True)
class WelchNoise:
    """What Welch averaging with one window does to an H1 estimate (module docstring, steps 1-2):
    ``lag`` [nfft] the lag window (the window's autocorrelation, ``lag[0] = 1``), ``overlap_factor`` the
    variance factor of overlapping segments ``1 + 2 sum_j lag[j D]^2`` (D the segment step; Welch 1967),
    ``line_correlation`` [p + 1] the correlation of the errors of lines j apart (``|W2[j]|^2`` with W2
    the normalised DFT of the squared window: 1, 4/9, 1/36 for Hann))."""

    lag: np.ndarray
    overlap_factor: float
    line_correlation: np.ndarray
    window: np.ndarray
    step: int


def welch_noise(spec: str, nfft: int, overlap: float = 0.5) -> WelchNoise:
    """:class:`WelchNoise` of Welch averaging with window ``spec`` over segments of ``nfft`` samples
    overlapping by ``overlap`` (fraction).

    Examples
    --------
    >>> u = welch_noise("hann", 1024)
    >>> round(float(u.lag[512]), 4), round(u.overlap_factor, 4), u.line_correlation.round(4).tolist()
    (0.1667, 1.0556, [1.0, 0.4444, 0.0278])
    """
    w = window(spec, nfft)
    r = np.fft.irfft(np.abs(np.fft.rfft(w, 2 * nfft)) ** 2, 2 * nfft)[:nfft]
    lag = r / r[0]
    step = max(1, int(round(nfft * (1.0 - overlap))))
    factor = 1.0 + 2.0 * float(np.sum(lag[step::step] ** 2))
    w2 = np.abs(np.fft.fft(w**2)[:MAX_CORRELATED_LINES + 1] / np.sum(w**2)) ** 2
    keep = np.flatnonzero(w2 >= LINE_CORRELATION_FLOOR)
    return WelchNoise(lag, factor, w2[: keep[-1] + 1], w, step)


def _basis(w: np.ndarray, lam: np.ndarray, lag: np.ndarray | None, df_hz: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pole terms at ``w`` [K] rad/s of the poles ``lam`` [M] and of their conjugates, [K, M] each, and
    their derivatives with respect to the pole: ``1/(i w - lam)`` without ``lag``; with the lag window
    ``lag`` [N] of Welch averaging at line spacing ``df_hz`` (lines on bins k df_hz) their expected
    Welch estimate ``dt sum_n lag[n] exp((lam - i w) n dt)``, dt = 1 / (N df_hz) (module docstring)."""
    if lag is None:
        a = 1.0 / (1j * w[:, None] - lam[None])
        b = 1.0 / (1j * w[:, None] - np.conj(lam)[None])
        return a, b, a**2, b**2
    n = lag.size
    dt = 1.0 / (n * df_hz)
    t = np.arange(n) * dt
    k = np.rint(w / (2 * np.pi * df_hz)).astype(int)
    e = np.exp(np.outer(t, lam)) * lag[:, None]                       # [N, M]
    terms = np.concatenate([e, np.conj(e), t[:, None] * e, t[:, None] * np.conj(e)], axis=1)
    g = np.fft.fft(terms, axis=0)[k] * dt                             # [K, 4M]
    return np.split(g, 4, axis=1)


def _band_cholesky(lines: np.ndarray, line_correlation: np.ndarray) -> np.ndarray | None:
    """Lower banded Cholesky factor (scipy.linalg.cholesky_banded layout) of the correlation matrix of
    the errors at the FFT lines ``lines`` [K] (ascending integers); None when the lines are independent."""
    p = line_correlation.size - 1
    if p == 0:
        return None
    ab = np.zeros((p + 1, lines.size))
    ab[0] = 1.0
    for d in range(1, p + 1):                            # a loop over the few correlated offsets
        gap = lines[d:] - lines[:-d]
        ab[d, :-d] = np.where(gap <= p, line_correlation[np.minimum(gap, p)], 0.0)
    return scipy.linalg.cholesky_banded(ab, lower=True)


def _residual_runs(lines: np.ndarray, fn_hz: np.ndarray, zeta: np.ndarray, df_hz: float) -> np.ndarray:
    """[K, G] which residual terms each of the fit's ``lines`` [K] (ascending FFT line numbers at
    ``df_hz``) carries: a run of consecutive lines whose modes (``fn_hz``, ``zeta``) all have at least
    MIN_LINES_PER_BANDWIDTH lines in their half-power band its own, the others one shared pair
    (module docstring, step 2)."""
    run = np.concatenate([[0], np.cumsum(np.diff(lines) > 1)])
    f = lines * df_hz
    own = np.zeros(run[-1] + 1, bool)
    for g in range(own.size):            # a loop over the runs (one per mode or group of close modes)
        inside = (fn_hz >= f[run == g].min()) & (fn_hz <= f[run == g].max())
        own[g] = inside.any() and bool(np.all(2 * zeta[inside] * fn_hz[inside] >= MIN_LINES_PER_BANDWIDTH
                                              * df_hz))
    label = np.where(own[run], run + 1, 0)
    return (label[:, None] == np.unique(label)[None, :]).astype(float)


def _information(w: np.ndarray, h: np.ndarray, s: np.ndarray, lam: np.ndarray,
                 noise: WelchNoise | None = None, df_hz: float = 0.0, chol: np.ndarray | None = None,
                 runs: np.ndarray | None = None, parts: list | None = None
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """Fisher information [2M, 2M] of (Re, Im) of the poles ``lam`` [M] with the residues and residual
    terms projected out, the Gauss-Newton step [2M] towards the weighted least-squares poles and the
    residual variance factor (chi^2 / degrees of freedom)
    (``h`` [K, m] FRF columns in receptance at ``w`` [K] rad/s, ``s`` [K, m] their standard deviations;
    ``noise``, ``df_hz`` as :func:`_basis`; ``chol`` the lines' correlation, :func:`_band_cholesky`;
    ``runs`` [K, G] the residual terms of each line, :func:`_residual_runs`; None: one pair;
    ``parts``, if given, receives each column's projected Jacobian [2K, 2M], coefficients [2M + 2G]
    and orthonormal basis [2K, 4M + 4G] of the residue columns)."""
    a, b, da, db = _basis(w, lam, None if noise is None else noise.lag, df_hz)
    runs = np.ones((w.size, 1)) if runs is None else runs
    phi = np.concatenate([a, b, runs, -runs / w[:, None] ** 2], axis=1)   # [K, 2M + 2G]
    M, P = lam.size, phi.shape[1]
    info = np.zeros((2 * M, 2 * M))
    grad = np.zeros(2 * M)
    rss = 0.0
    for j in range(h.shape[1]):                       # a loop over FRF columns (few), not lines
        x = np.concatenate([phi, h[:, j:j + 1]], axis=1) / s[:, j:j + 1]
        if chol is not None:                             # whitened: L^-1 D^-1 (D the standard deviations)
            x = scipy.linalg.solve_banded((chol.shape[0] - 1, 0), chol, x)
        A = _real(np.concatenate([x[:, :P], 1j * x[:, :P]], axis=1))         # [2K, 2P] real columns
        y = _real(x[:, P])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        c = coef[:P] + 1j * coef[P:]
        ca, cb = c[:M], c[M:2 * M]
        d = np.concatenate([da * ca + db * cb, 1j * da * ca - 1j * db * cb], axis=1) / s[:, j:j + 1]
        if chol is not None:
            d = scipy.linalg.solve_banded((chol.shape[0] - 1, 0), chol, d)
        J = _real(d)                                     # [2K, 2M]
        Q, _ = np.linalg.qr(A)
        Jp = J - Q @ (Q.T @ J)
        if parts is not None:
            parts.append((Jp, c, Q))
        info += Jp.T @ Jp
        grad += Jp.T @ (y - A @ coef)
        rss += float(np.sum((y - A @ coef) ** 2))
    dof = y.size * h.shape[1] - A.shape[1] * h.shape[1] - 2 * M
    return info, grad, rss / dof if dof > 0 else 1.0


def _refine(w: np.ndarray, h: np.ndarray, s: np.ndarray, lam: np.ndarray, noise: WelchNoise | None,
            df_hz: float, chol: np.ndarray | None, runs: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray, float, list]:
    """Gauss-Newton steps of variable projection from ``lam``: the weighted least-squares poles, their
    information, residual variance factor and columns' parts there (arguments as :func:`_information`).
    A step that raises the residual variance factor, or leaves the numbers finite no more, is not taken: on
    coarsely quantised records (integer ADC counts) the steps diverged, the poles ran to 1e25 and the
    next evaluation raised ValueError."""
    info, grad, factor = _information(w, h, s, lam, noise, df_hz, chol, runs)
    for _ in range(GAUSS_NEWTON_STEPS):
        try:
            step = np.linalg.solve(info, grad)
        except np.linalg.LinAlgError:
            break
        trial = lam + step[:lam.size] + 1j * step[lam.size:]
        if not np.all(np.isfinite(trial)):
            break
        with np.errstate(over="ignore", invalid="ignore"):
            try:
                at_trial = _information(w, h, s, trial, noise, df_hz, chol, runs)
            except ValueError:   # non-finite numbers met by a solver that checks them
                break
        if not (np.isfinite(at_trial[2]) and at_trial[2] <= factor * (1 + 1e-9)):
            break
        lam, (info, grad, factor) = trial, at_trial
        if np.all(np.abs(step) < 1e-10 * np.abs(np.concatenate([lam, lam]))):
            break
    parts: list = []
    info, _, factor = _information(w, h, s, lam, noise, df_hz, chol, runs, parts)
    return lam, info, factor, parts


def _error_moment(lam: np.ndarray, parts: list, lines: np.ndarray, s: np.ndarray, welch: WelchNoise,
                  n_averages: int, df_hz: float, chol: np.ndarray | None
                  ) -> tuple[np.ndarray, float] | None:
    """``J_p^T W Cov W^T J_p`` [2M, 2M], the weighted least-squares poles' score covariance under the
    H1 errors' actual covariance ``Cov`` (leakage of the modes ``lam`` [M] with the columns' fitted
    residues in ``parts``, :func:`modal.welch_leakage.leakage_covariance`, plus output noise: what the
    coherence loses beyond the leakage, white, lines correlated by ``welch.line_correlation``), W the
    fit's whitening (``s`` [K, m] standard deviations, ``chol``); and the fit's expected residual sum
    of squares under ``Cov`` without the residue terms' share (the Birge ratio's denominator, in place
    of the degrees of freedom); None beyond ``LEAKAGE_BUDGET``."""
    from flexmodal.modal.welch_leakage import leakage_covariance

    M, K, m = lam.size, lines.size, s.shape[1]
    if max(m, 2 * M) * K * welch.window.size > LEAKAGE_BUDGET:
        return None
    residues = np.array([np.concatenate([c[:M], c[M:2 * M]]) for _, c, _ in parts])   # [m, 2M]
    cov, pseudo, share = leakage_covariance(np.concatenate([lam, np.conj(lam)]), residues, lines,
                                            welch.window, df_hz, n_averages, welch.step)
    # finite averages (Gaussian regression of n_d complex samples on one): the coherence's residual
    # power has n_d - 1 degrees of freedom, and E[1 / sum |X|^2] = 1 / ((n_d - 1) G_xx)
    n_d = n_averages / welch.overlap_factor
    if n_d <= 4.0:
        return None
    small = n_d / (n_d - 1.0)
    cov, pseudo = cov * small, pseudo * small
    noise = np.sqrt(np.clip(2.0 * s.T**2 * n_d * small - share, 0.0, None) / (n_d - 1.0))   # [m, K]
    p = welch.line_correlation.size - 1
    gap = np.abs(lines[:, None] - lines[None, :])
    rho = np.where(gap <= p, welch.line_correlation[np.minimum(gap, p)], 0.0)
    for j in range(m):                                  # a loop over FRF columns (few)
        cov[j, :, j, :] += noise[j][:, None] * noise[j][None, :] * rho
    cov, pseudo = cov.reshape(m * K, m * K), pseudo.reshape(m * K, m * K)
    # the real errors [Re dH; Im dH] of every column, their covariance, whitened as the fit is
    real = np.block([[np.real(cov + pseudo), np.imag(pseudo - cov)],
                     [np.imag(cov + pseudo), np.real(cov - pseudo)]]) / 2.0
    rows = (np.arange(2)[:, None, None] * m * K + np.arange(m)[None, :, None] * K
            + np.arange(K)[None, None, :])                       # [re/im, column, line] -> row of real
    order = rows.transpose(1, 0, 2).reshape(-1)                  # column by column, Re then Im
    scale = np.tile(s.T, (1, 2)).reshape(-1)
    white = real[np.ix_(order, order)] / np.outer(scale, scale)
    if chol is not None:                                # L^-1 (.) L^-T on each column's Re and Im halves
        band = (chol.shape[0] - 1, 0)
        x = scipy.linalg.solve_banded(band, chol, white.reshape(2 * m, K, -1).transpose(1, 0, 2)
                                      .reshape(K, -1))
        x = x.reshape(K, 2 * m, 2 * m, K).transpose(3, 2, 1, 0).reshape(K, -1)
        x = scipy.linalg.solve_banded(band, chol, x)
        white = x.reshape(K, 2 * m, 2 * m, K).transpose(2, 3, 1, 0).reshape(2 * m * K, 2 * m * K)
    jp = np.concatenate([Jp for Jp, _, _ in parts], axis=0)     # [2 K m, 2M]
    expected = 0.0
    for j, (_, _, Q) in enumerate(parts):               # a loop over FRF columns (few)
        block = white[2 * K * j:2 * K * (j + 1), 2 * K * j:2 * K * (j + 1)]
        expected += float(np.trace(block) - np.trace(Q.T @ block @ Q))
    return jp.T @ white @ jp, expected


def modal_uncertainty(freq_hz: np.ndarray, H: np.ndarray, coherence: np.ndarray, n_averages: int,
                      fn_hz: np.ndarray, zeta: np.ndarray, *, quantity: str = "accelerance",
                      overlap_correlation: float = HANN_50_CORRELATION,
                      enbw_bins: float = HANN_ENBW_BINS, decay_rate_per_s: float = 0.0,
                      welch: WelchNoise | None = None) -> ModalUncertainty:
    """Standard deviations of the identified ``fn_hz`` [Hz] and ``zeta`` [-] (module docstring).

    ``H`` [n_out, n_in, n_freq] the FRFs the modes were identified from (``quantity`` of H),
    ``coherence`` [n_out, n_freq], ``n_averages`` the Welch segments (or impacts) averaged;
    ``decay_rate_per_s`` [1/s] of an exponential window applied to the records, whose damping is
    removed from the refined poles (as modal.damping.remove_added_damping does)."""
    f = np.asarray(freq_hz, float)
    H = np.asarray(H)
    if H.ndim != 3 or H.shape[-1] != f.size or np.shape(coherence) != (H.shape[0], f.size):
        raise ModalError(f"FRF uncertainty: FRFs {H.shape} and coherence {np.shape(coherence)} do not "
                         f"match {f.size} lines")
    if welch is not None:        # the window's own overlap factor and line correlation (no ENBW widening)
        overlap_correlation = math.sqrt((welch.overlap_factor - 1.0) / 2.0)
        enbw_bins = 1.0
    sd = frf_std(H, coherence, n_averages, overlap_correlation)
    pos = f > 0
    rec = np.zeros_like(H, dtype=complex)
    rec[..., pos] = convert(H[..., pos], f[pos], quantity, "receptance")
    scale = np.ones_like(f)
    scale[pos] = np.abs(2 * np.pi * f[pos]) ** (-float({"receptance": 0, "mobility": 1, "accelerance": 2}
                                                      [quantity]))
    sd = sd * scale * math.sqrt(enbw_bins)
    cols = rec.reshape(-1, f.size).T                 # [n_freq, m]
    sds = sd.reshape(-1, f.size).T
    fn = np.asarray(fn_hz, float)
    zeta = np.asarray(zeta, float)
    nan = np.full(fn.size, np.nan)
    near = np.zeros(f.size, bool)
    for fk, zk in zip(fn, zeta, strict=True):            # a loop over modes: lines near each
        half = max(BAND_HALF_WIDTHS * 2.0 * zk * fk, (MIN_LINES // 2) * float(np.median(np.diff(f))))
        near |= np.abs(f - fk) <= half
    band = np.flatnonzero(near & pos & np.all(np.isfinite(cols), axis=1) & np.all(sds > 0, axis=1))
    if fn.size == 0 or band.size < MIN_LINES * fn.size:
        return ModalUncertainty(nan, nan.copy(), nan.copy(), nan.copy())
    w = 2 * np.pi * f[band]
    df = float(np.median(np.diff(f)))
    wn = 2 * np.pi * fn
    lam = -zeta * wn + 1j * wn * np.sqrt(np.clip(1.0 - zeta**2, 0.0, None))
    h, s = cols[band], sds[band]
    lines = np.rint(f[band] / df).astype(int)
    chol = None if welch is None else _band_cholesky(lines, welch.line_correlation)
    # one BLAS thread: the matrices are a few columns wide (threads only spin on them; under load a
    # 1200 x 12 QR took 0.6 s with the default threads, 0.1 ms with one)
    with one_blas_thread():
        lam, info, birge, parts = _refine(w, h, s, lam, welch, df, chol, _residual_runs(lines, fn, zeta, df))
        try:
            inv = np.linalg.inv(info)
        except np.linalg.LinAlgError:
            return ModalUncertainty(nan, nan.copy(), nan.copy(), nan.copy())
        moment = None if welch is None or H.shape[1] != 1 else \
            _error_moment(lam, parts, lines, s, welch, n_averages, df, chol)
    if moment is None:
        cov = inv * (1.0 if welch is None else max(1.0, birge))
    else:           # the sandwich; the Birge ratio against the residual the error model expects
        middle, expected = moment
        cov = inv @ middle @ inv
        dof = 2 * w.size * h.shape[1] - sum(q.shape[1] for _, _, q in parts) - 2 * lam.size
        expected -= float(np.trace(inv @ middle))
        n_d = n_averages / welch.overlap_factor
        # weights from the coherence of n_d averages, not the true variances: the estimate's covariance
        # is (n_d - 1) / (n_d - 3) times larger (Schoukens, Pintelon, Vandersteen & Guillaume 1997)
        cov = cov * max(1.0, birge * dof / expected if expected > 0 else 1.0) * (n_d - 1.0) / (n_d - 3.0)
    lam = lam + decay_rate_per_s                          # the exponential window's decay removed
    p, q = lam.real, lam.imag
    wn = np.abs(lam)
    M = fn.size
    out_f, out_z = np.empty(M), np.empty(M)
    for k in range(M):
        i = [k, M + k]
        c = cov[np.ix_(i, i)]
        g_f = np.array([p[k], q[k]]) / (wn[k] * 2 * np.pi)                        # d f_n / d(p, q)
        g_z = np.array([-1.0 / wn[k] + p[k] ** 2 / wn[k] ** 3, p[k] * q[k] / wn[k] ** 3])  # d(-p/wn)
        out_f[k] = math.sqrt(max(g_f @ c @ g_f, 0.0))
        out_z[k] = math.sqrt(max(g_z @ c @ g_z, 0.0))
    loc_f, loc_z = wn / (2 * np.pi), -p / wn
    return ModalUncertainty(out_f, out_z, loc_f, loc_z)


def with_uncertainty(modes: Modes, freq_hz: np.ndarray, H: np.ndarray, coherence: np.ndarray | None,
                     n_averages: int, quantity: str = "accelerance", decay_rate_per_s: float = 0.0,
                     welch: WelchNoise | None = None) -> Modes:
    """``modes`` (identified from ``H``) with refined poles and their standard deviations (module
    docstring); ``modes`` unchanged but for NaN standard deviations when there are no modes or
    fewer than two averages."""
    n = modes.freq_hz.size
    if n == 0 or n_averages < 2 or coherence is None:
        return replace(modes, freq_std_hz=np.full(n, np.nan), damping_std=np.full(n, np.nan))
    u = modal_uncertainty(freq_hz, H, coherence, n_averages, modes.freq_hz, modes.damping_ratio,
                          quantity=quantity, decay_rate_per_s=decay_rate_per_s, welch=welch)
    ok = (np.abs(u.local_freq_hz - modes.freq_hz) <= modes.damping_ratio * modes.freq_hz) & \
        (u.local_damping > 0) & np.isfinite(u.freq_std_hz)
    refined = replace(modes, freq_hz=np.where(ok, u.local_freq_hz, modes.freq_hz),
                      damping_ratio=np.where(ok, u.local_damping, modes.damping_ratio),
                      freq_std_hz=np.where(ok, u.freq_std_hz, np.nan),
                      damping_std=np.where(ok, u.damping_std, np.nan))
    return restated(modes, refined, freq_hz, decay_rate_per_s)   # warnings quote the refined poles
