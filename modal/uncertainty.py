"""Uncertainty of identified natural frequencies and damping ratios from the FRF's own random error.

``with_uncertainty(modes, freq_hz, H, coherence, n_averages, quantity="accelerance") -> Modes``
    the hook of the identification (modal/sources.py ``identify_frf``, the demo): ``modes`` with
    ``freq_std_hz``/``damping_std`` set and its frequencies and damping ratios refined to the
    maximum-likelihood estimates below (their standard deviations belong to those: a pLSCF pole
    itself scatters about four times more, tests/test_modal_uncertainty.py); a mode whose refined
    pole leaves its half-power band keeps its pLSCF values and gets NaN.

``modal_uncertainty(freq_hz, H, coherence, n_averages, fn_hz, zeta, quantity="accelerance",
overlap_correlation=HANN_50_CORRELATION, enbw_bins=HANN_ENBW_BINS) -> ModalUncertainty``
    ``freq_std_hz`` [Hz], ``damping_std`` [-] one per mode (NaN where the bands hold too few lines),
    and the refined ``local_freq_hz``/``local_damping`` they belong to.

1. Random error of the FRF estimate (Bendat & Piersol 2010, eq. 9.90): the normalised random error of
   |H| and the standard deviation of its phase [rad] are both ``sqrt(1 - g2) / (|g| sqrt(2 n_d))``
   with ``g2`` the (ordinary or multiple) coherence and ``n_d`` the number of independent averages, so
   the real and imaginary parts of H carry ``sigma = |H| sqrt(1 - g2) / sqrt(2 n_d g2)`` each.  Welch
   segments with 50 % overlap of a Hann window are correlated (``overlap_correlation`` = 0.167,
   Harris 1978, Table 1); ``n_d = n_averages / (1 + 2 rho^2)`` (Welch 1967).  Neighbouring lines of a
   windowed estimate are correlated: treating them as independent, the variance is widened by the
   window's equivalent noise bandwidth in lines (``enbw_bins``, 1.5 for Hann).
2. On the lines within ``BAND_HALF_WIDTHS`` half-power bandwidths of any mode (at least
   ``MIN_LINES`` per mode), the receptance of every FRF column is the modal model
   ``sum_r A_r / (i w - lambda_r) + B_r / (i w - conj(lambda_r)) + R - S / w^2`` (upper and lower
   residuals R, S), with the poles ``lambda_r = -zeta_r w_r + i w_r sqrt(1 - zeta_r^2)`` shared by
   all columns and residues per column (rational-fraction modal model, Richardson & Formenti 1982).
   A few Gauss-Newton steps of variable projection (Golub & Pereyra 1973; Kaufman's Jacobian) from
   the identified poles give their weighted least-squares (maximum-likelihood under 1.) estimates;
   the covariance is the inverse of the Fisher information ``J_p^T (I - P) J_p`` of the poles' real
   and imaginary parts with the residues projected out (``P`` the projection onto their columns;
   Pintelon, Guillaume & Schoukens 2007).
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

from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import convert
from flexmodal.modal.identify import Modes

HANN_50_CORRELATION = 0.167
"""Correlation of consecutive Hann-windowed segments at 50 % overlap (Harris 1978, Table 1)."""
HANN_ENBW_BINS = 1.5
"""Equivalent noise bandwidth of the Hann window in lines (Harris 1978, Table 1): neighbouring lines of
a windowed estimate are correlated, so a band of K lines carries the information of K / 1.5."""
BAND_HALF_WIDTHS = 3.0
"""Half-width of the local fit band in half-power bandwidths (2 zeta f_n)."""
MIN_LINES = 7
GAUSS_NEWTON_STEPS = 8
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


def _information(w: np.ndarray, h: np.ndarray, s: np.ndarray, lam: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Fisher information [2M, 2M] of (Re, Im) of the poles ``lam`` [M] with the residues and residual
    terms projected out, and the Gauss-Newton step [2M] towards the weighted least-squares poles
    (``h`` [K, m] FRF columns in receptance at ``w`` [K] rad/s, ``s`` [K, m] their standard deviations)."""
    a = 1.0 / (1j * w[:, None] - lam[None])                     # [K, M]
    b = 1.0 / (1j * w[:, None] - np.conj(lam)[None])
    phi = np.concatenate([a, b, np.ones((w.size, 1)), -1.0 / w[:, None] ** 2], axis=1)   # [K, 2M + 2]
    M = lam.size
    info = np.zeros((2 * M, 2 * M))
    grad = np.zeros(2 * M)
    for j in range(h.shape[1]):                       # a loop over FRF columns (few), not lines
        wt = 1.0 / s[:, j]
        A = _real(np.concatenate([phi, 1j * phi], axis=1) * wt[:, None])     # [2K, 2P] real columns
        y = _real(h[:, j] * wt)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        P = phi.shape[1]
        c = coef[:P] + 1j * coef[P:]
        ca, cb = c[:M], c[M:2 * M]
        d_re = a**2 * ca + b**2 * cb                                 # [K, M]
        d_im = 1j * a**2 * ca - 1j * b**2 * cb
        J = _real(np.concatenate([d_re, d_im], axis=1) * wt[:, None])   # [2K, 2M]
        Q, _ = np.linalg.qr(A)
        Jp = J - Q @ (Q.T @ J)
        info += Jp.T @ Jp
        grad += Jp.T @ (y - A @ coef)
    return info, grad


def modal_uncertainty(freq_hz: np.ndarray, H: np.ndarray, coherence: np.ndarray, n_averages: int,
                      fn_hz: np.ndarray, zeta: np.ndarray, *, quantity: str = "accelerance",
                      overlap_correlation: float = HANN_50_CORRELATION,
                      enbw_bins: float = HANN_ENBW_BINS, decay_rate_per_s: float = 0.0) -> ModalUncertainty:
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
    wn = 2 * np.pi * fn
    lam = -zeta * wn + 1j * wn * np.sqrt(np.clip(1.0 - zeta**2, 0.0, None))
    h, s = cols[band], sds[band]
    for _ in range(GAUSS_NEWTON_STEPS):
        info, grad = _information(w, h, s, lam)
        try:
            step = np.linalg.solve(info, grad)
        except np.linalg.LinAlgError:
            break
        lam = lam + step[:fn.size] + 1j * step[fn.size:]
        if np.all(np.abs(step) < 1e-10 * np.abs(np.concatenate([lam, lam]))):
            break
    info, _ = _information(w, h, s, lam)
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return ModalUncertainty(nan, nan.copy(), nan.copy(), nan.copy())
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
                     n_averages: int, quantity: str = "accelerance", decay_rate_per_s: float = 0.0) -> Modes:
    """``modes`` (identified from ``H``) with refined poles and their standard deviations (module
    docstring); ``modes`` unchanged but for NaN standard deviations when there are no modes or
    fewer than two averages."""
    n = modes.freq_hz.size
    if n == 0 or n_averages < 2 or coherence is None:
        return replace(modes, freq_std_hz=np.full(n, np.nan), damping_std=np.full(n, np.nan))
    u = modal_uncertainty(freq_hz, H, coherence, n_averages, modes.freq_hz, modes.damping_ratio,
                          quantity=quantity, decay_rate_per_s=decay_rate_per_s)
    ok = (np.abs(u.local_freq_hz - modes.freq_hz) <= modes.damping_ratio * modes.freq_hz) & \
        (u.local_damping > 0) & np.isfinite(u.freq_std_hz)
    return replace(modes, freq_hz=np.where(ok, u.local_freq_hz, modes.freq_hz),
                   damping_ratio=np.where(ok, u.local_damping, modes.damping_ratio),
                   freq_std_hz=np.where(ok, u.freq_std_hz, np.nan),
                   damping_std=np.where(ok, u.damping_std, np.nan))
