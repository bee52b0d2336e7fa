"""Leakage error of a Welch-averaged H1 estimate of a modal system: its covariance across lines and outputs.

``leakage_covariance(lam, residues, lines, window, df_hz, n_segments, step) -> (cov, pseudo, per_segment)``
    the covariance ``E[dH dH^H]`` and pseudo-covariance ``E[dH dH^T]`` [m, K, m, K] of the random error
    ``dH`` of H1 (single input, white over the band) at the FFT ``lines`` [K] of the ``m`` outputs whose
    impulse responses are ``h_j(t) = sum_p residues[j, p] exp(lam[p] t)``, averaged over
    ``n_segments`` segments windowed by ``window`` [nfft] that advance by ``step`` samples (the output
    noise-free; output noise adds its own term, modal/uncertainty.py), and ``per_segment`` [m, K] the
    leakage error's share of one segment, ``E|e_j(k)|^2 / sum w^2`` (what it takes from the coherence).

Why: within one segment the windowed response is not H times the windowed input -- the response to the
input before the segment and the window's cut of the response within it leak.  Its part correlated
with the input at the same line is the expected estimate (the lag-window transform, Bendat & Piersol
2010 §8.5; modal/uncertainty.py fits it); the rest, ``e(k) = Y(k) - E[H1](k) X(k)``, is a random error
that lowers the coherence like output noise but, unlike noise, is nearly the same function of
frequency at every output (the mode's shape times one transient) and correlated across neighbouring
lines with a phase: the pole-residue model absorbs most of it into the residues.  Counting it as
white noise over-states the poles' variance (at 3-6 lines per half-power band by 1.2-1.5x).

Every term is exact for a white Gaussian input (Isserlis' theorem for circular complex Gaussians):
one segment's ``Y_j(k) = sum_s x_s a_jk(s)`` with ``a_jk(s) = sum_t w_t exp(-2 pi i k t / N)
h_j((t - s) dt) dt`` over the input samples ``s < N``, ``X(k) = sum_s x_s w_s exp(-2 pi i k s / N)``;
to first order ``dH_j(k) = sum_a e_aj(k) X_a(k)^* / (n P)`` over the n segments a, ``P = sum w^2``,
and ``E[dH dH^H] = sum_d (1 - |d| / n) C_d / (n P^2)`` over the offsets d of segments that overlap,
with, for segment 0 and the segment D = d step samples later,

    C_d[j k1, l k2] = E[e_0j(k1) e_Dl(k2)^*] E[X_D(k2) X_0(k1)^*]
    P_d[j k1, l k2] = E[e_0j(k1) X_D(k2)^*] E[e_Dl(k2) X_0(k1)^*]      (pseudo-covariance)

(C_-d = C_d^H, P_-d = P_d^T; ``E[X_D X_0^*]`` vanishes beyond a few lines: two for Hann at d = 0).
The sums over ``s`` are a backward first-order recursion per pole within the segment
(scipy.signal.lfilter) and a geometric series before it.  Overlapping segments' leakage errors are not
correlated as white noise's are (Welch 1967's factor): at 50 % overlap with Hann the variance of H1 at
a lightly damped peak is ~0.8 of what that factor gives.

Examples
--------
>>> import numpy as np
>>> lam = np.array([-0.5 + 2j * np.pi * 10, -0.5 - 2j * np.pi * 10])
>>> res = np.array([[-0.5j, 0.5j]]) / (2 * np.pi * 10)
>>> w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(256) / 256)
>>> cov, pseudo, share = leakage_covariance(lam, res, np.arange(36, 45), w, 0.25, 40, 128)
>>> cov.shape, bool(np.all(np.diagonal(cov[0, :, 0, :]).real > 0)), share.shape
((1, 9, 1, 9), True, (1, 9))
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

XX_FLOOR = 1e-3
"""Input-spectrum correlations ``|E[X_D(k2) X_0(k1)^*]|`` below this fraction of ``sum w^2`` are left out of
the covariance (beyond a few lines of the window's spectral width: relative terms below 1e-3)."""


def _functionals(lam: np.ndarray, residues: np.ndarray, lines: np.ndarray, window: np.ndarray,
                 df_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``a_jk(s)`` [m, K, 2N] for the input samples s in [-N, N) (``Y_j(k) = sum_s x_s a_jk(s)``), ``g``
    [m, K, P] with ``a_jk(s) = sum_p g[j, k, p] z_p^-s`` for s < 0 (z_p = exp(lam_p dt)), and ``b_k(s)``
    [K, N] with ``X(k) = sum_s x_s b_k(s)`` (module docstring)."""
    n = window.size
    dt = 1.0 / (n * df_hz)
    b = window[None] * np.exp(-2j * np.pi * np.outer(lines, np.arange(n)) / n)      # [K, N]
    z = np.exp(lam * dt)
    r = np.empty((lam.size, lines.size, n), complex)
    for p, zp in enumerate(z):      # a loop over poles (few): r(s) = b(s) + z_p r(s + 1), backwards
        r[p] = lfilter([1.0], [1.0, -zp], b[:, ::-1], axis=1)[:, ::-1]
    g = dt * residues[:, None, :] * r[:, :, 0].T[None]                              # [m, K, P]
    before = np.einsum("jkp,pq->jkq", g, z[:, None] ** np.arange(n, 0, -1)[None])  # s = -N .. -1
    return np.concatenate([before, dt * np.einsum("jp,pks->jks", residues, r)], axis=-1), g, b


def expected_h1(lam: np.ndarray, residues: np.ndarray, lines: np.ndarray, window: np.ndarray,
                df_hz: float) -> np.ndarray:
    """The expected H1 [m, K] at ``lines`` (arguments as :func:`leakage_covariance`):
    ``E[Y X^*] / E|X|^2``."""
    a, _, b = _functionals(lam, residues, np.asarray(lines, int), window, df_hz)
    n = window.size
    return np.einsum("jks,ks->jk", a[:, :, n:], np.conj(b)) / np.sum(window**2)


def leakage_covariance(lam: np.ndarray, residues: np.ndarray, lines: np.ndarray, window: np.ndarray,
                       df_hz: float, n_segments: int, step: int
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Covariance and pseudo-covariance [m, K, m, K] of H1's leakage error, and its per-segment share
    [m, K] (module docstring).

    ``lam`` [P] poles [rad/s] (each conjugate listed as its own pole), ``residues`` [m, P] of the
    outputs' receptances, ``lines`` [K] ascending FFT line indices (frequency ``lines * df_hz``),
    ``window`` [nfft] the Welch window, ``n_segments`` averaged, ``step`` samples apart."""
    lines = np.asarray(lines, int)
    n = window.size
    m, K = residues.shape[0], lines.size
    a, g, b = _functionals(lam, residues, lines, window, df_hz)
    z = np.exp(lam / (n * df_hz))
    zz = np.outer(z, np.conj(z))
    power = float(np.sum(window**2))
    hexp = np.einsum("jks,ks->jk", a[:, :, n:], np.conj(b)) / power               # [m, K]
    cov = np.zeros((m, K, m, K), complex)
    pseudo = np.zeros((m, K, m, K), complex)
    share = np.zeros((m, K))
    for d in range(0, -(-n // step)):  # a loop over the offsets of overlapping segments (few)
        D = d * step
        shifted = np.zeros(n)                                      # w(s - D) on the first segment's samples
        shifted[D:] = window[: n - D]
        turn = np.exp(-2j * np.pi * lines * D / n)
        xx = np.fft.fft(shifted * window)[(lines[:, None] - lines[None, :]) % n] * np.conj(turn)[:, None]
        y0xd = n * np.fft.ifft(a[:, :, n:] * shifted, axis=-1)[:, :, lines % n] * turn   # E[Y_0 X_D^*]
        ydx0 = n * np.fft.ifft(a[:, :, n - D: 2 * n - D] * window, axis=-1)[:, :, lines % n]  # E[Y_D X_0^*]
        e0xd = y0xd - hexp[:, :, None] * np.conj(xx.T)[None]       # E[e_0j(k1) X_D(k2)^*]
        edx0 = ydx0 - hexp[:, :, None] * xx[None]                  # E[e_Dl(k2) X_0(k1)^*]
        p_d = np.einsum("jab,lba->jalb", e0xd, edx0)
        c_d = np.zeros((m, K, m, K), complex)
        big = np.abs(xx) > XX_FLOOR * power
        gap = lines[:, None] - lines[None, :]                      # [k2, k1]
        for off in np.unique(gap[big]):  # a loop over the line offsets the segments correlate (few)
            i2, i1 = np.nonzero(big & (gap == off))
            eyy = np.einsum("jis,lis->jli", a[:, i1, n:], np.conj(a[:, i2, n - D: 2 * n - D])) + \
                np.einsum("jip,pq,liq->jli", g[:, i1], zz / (1.0 - zz) * np.conj(z)[None] ** D,
                          np.conj(g[:, i2]))
            eee = (eyy - np.conj(hexp[None, :, i2]) * y0xd[:, None, i1, i2]
                   - hexp[:, None, i1] * np.conj(ydx0[None, :, i2, i1])
                   + hexp[:, None, i1] * np.conj(hexp[None, :, i2]) * np.conj(xx[i2, i1]))
            c_d[:, i1, :, i2] = np.moveaxis(eee * xx[i2, i1], -1, 0)
            if D == 0 and off == 0:
                share = np.real(np.einsum("jji->ji", eee)) / power
        weight = 1.0 if D == 0 else 1.0 - d / n_segments
        if D == 0:
            cov += c_d
            pseudo += p_d
        else:
            cov += weight * (c_d + np.conj(np.transpose(c_d, (2, 3, 0, 1))))
            pseudo += weight * (p_d + np.transpose(p_d, (2, 3, 0, 1)))
    scale = 1.0 / (n_segments * power**2)
    return cov * scale, pseudo * scale, share
