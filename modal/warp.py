"""Time warping that holds a drifting mode at one frequency: the record is resampled at equal steps of
``tau = integral f(t) / f_c dt``, so a mode whose natural frequency follows ``f(t)`` oscillates at the
constant ``f_c`` in ``tau``.

For a slowly varying oscillator ``q'' + 2 zeta w(t) q' + w(t)^2 q = p`` the free response is
``q ~ w^(-1/2) exp(-integral zeta w dt) cos(integral w_d dt)`` (WKB; Nayfeh, *Perturbation Methods*,
1973, §7.1): in ``tau`` (``d tau = w / w_c dt``) its phase advances at ``w_c sqrt(1 - zeta^2)`` and its
envelope decays at ``zeta w_c`` — a constant-parameter mode of the same damping ratio.  So SSI on the
warped record finds the mode's frequency at ``f_c`` (the centre of the window) and its damping ratio
without the spread that the drift adds to the spectral peak.  This is the structural counterpart of
computed order tracking (Fyfe & Munck 1997), which resamples at equal steps of shaft angle.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline


def warp(y: np.ndarray, sample_rate_hz: float, freq_hz: np.ndarray, centre: int | None = None) -> np.ndarray:
    """The window ``y`` [n, n_channels] resampled (cubic spline) at steps of ``1 / sample_rate_hz`` in
    warped time for the instantaneous frequency ``freq_hz`` [n] (Hz, > 0), centred so that sample
    ``centre`` (default the middle one) keeps its time and cut to the warped span (about ``n`` rows): a
    mode following ``freq_hz`` is at ``freq_hz[centre]`` in the result.

    Examples
    --------
    >>> fs, n = 1000.0, 4000
    >>> t = np.arange(n) / fs
    >>> f = 50.0 + 5.0 * (t - t[n // 2])                     # a 5 Hz/s drift through 50 Hz
    >>> y = np.sin(2 * np.pi * np.cumsum(f) / fs)[:, None]
    >>> w = warp(y, fs, f)[:, 0]
    >>> spectrum = np.abs(np.fft.rfft(w * np.hanning(w.size), 8 * n))
    >>> round(float(np.fft.rfftfreq(8 * n, 1 / fs)[np.argmax(spectrum)]), 1)
    50.0
    """
    n = y.shape[0]
    c = n // 2 if centre is None else int(centre)
    t = np.arange(n) / sample_rate_hz
    g = np.asarray(freq_hz, float)
    tau = np.concatenate([[0.0], np.cumsum(0.5 * (g[1:] + g[:-1]))]) / (g[c] * sample_rate_hz)
    tau -= tau[c] - t[c]
    grid = t[c] + (np.arange(n) - c) / sample_rate_hz
    grid = grid[(grid >= tau[0]) & (grid <= tau[-1])]
    at = np.interp(grid, tau, t)
    return CubicSpline(t, y, axis=0)(at)
