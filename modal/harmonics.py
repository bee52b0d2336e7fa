"""Motor and gear harmonics in the response of a moving arm: orders of a joint's speed, and the
amplitude statistics that tell a sinusoid from a mode's random response.

A harmonic of order ``o`` of a joint turning at ``v`` rev/s sits at ``f = o v`` Hz: as the joint speeds
up and slows down its frequency sweeps, while a mode's follows the pose.  The kurtosis
``E[x^4] / E[x^2]^2`` of a signal band-passed around a peak is 1.5 for a sinusoid (constant envelope)
and 3 for the Gaussian random response of a mode to broadband excitation (Brincker & Ventura,
*Introduction to Operational Modal Analysis*, 2015, §10.4; Jacobsen, Andersen & Brincker 2006, IMAC
XXIV, "Using EFDD as a robust technique for deterministic excitation in OMA").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.fft

MIN_POLES = 5            # an order is found from at least this many poles ...
MIN_SPEED_RATIO = 1.2    # ... spanning at least this ratio of joint speeds (a mode's f does not follow v)
MIN_SPEED_SHARE = 0.2    # poles of windows slower than this share of the fastest are left out
MAX_GAP_SHARE = 1 / 3    # a harmonic's frequencies fill their span: no gap wider than this share of it


def is_order(freq_hz: np.ndarray, speed_rev_per_s: float, orders: Sequence[float], tol: float) -> np.ndarray:
    """For each frequency [Hz], the order (of ``orders``, per revolution) within relative ``tol`` of
    ``freq_hz / speed_rev_per_s``, else 0.

    Examples
    --------
    >>> is_order(np.array([30.0, 45.0]), 0.5, (60.0, 80.0), 0.02).tolist()
    [60.0, 0.0]
    """
    f = np.asarray(freq_hz, float)
    out = np.zeros(f.size)
    if speed_rev_per_s <= 0 or not len(orders):
        return out
    o = np.asarray(orders, float)
    err = np.abs(f[:, None] / (o[None, :] * speed_rev_per_s) - 1.0)
    best = np.argmin(err, axis=1)
    hit = err[np.arange(f.size), best] < tol
    out[hit] = o[best[hit]]
    return out


def find_orders(freq_hz: np.ndarray, speed_rev_per_s: np.ndarray, tol: float) -> tuple[float, ...]:
    """Orders (per revolution) that poles ``freq_hz`` [Hz] seen at joint speeds ``speed_rev_per_s``
    follow: groups of at least ``MIN_POLES`` poles whose ``f / v`` agree within ``tol`` while their
    speeds span a ratio of at least ``MIN_SPEED_RATIO`` and their frequencies fill that span
    (:func:`_follows`); poles slower than ``MIN_SPEED_SHARE`` of the fastest are left out.  Each
    order is its group's median.

    Examples
    --------
    >>> v = np.linspace(0.5, 1.0, 8)
    >>> f = np.concatenate([120.0 * v, np.full(8, 37.0)])
    >>> [round(o, 6) for o in find_orders(f, np.concatenate([v, v]), 0.02)]
    [120.0]
    """
    f, v = np.asarray(freq_hz, float), np.asarray(speed_rev_per_s, float)
    ok = (v > MIN_SPEED_SHARE * v.max(initial=0.0)) & (f > 0)
    if ok.sum() < MIN_POLES:
        return ()
    lo, vv, ff = np.log(f[ok] / v[ok]), v[ok], f[ok]
    idx = np.argsort(lo)
    lo, vv, ff = lo[idx], vv[idx], ff[idx]
    left = np.ones(lo.size, bool)
    found = []
    while True:   # a loop over orders found: the fullest band of width 2 tol in log order, then the next
        ends = np.searchsorted(lo, lo + 2 * tol, side="right")
        cum = np.concatenate([[0], np.cumsum(left)])
        count = cum[ends] - cum[:-1]
        best = -1
        for i in np.argsort(-count, kind="stable"):   # the fullest band whose speeds span enough
            members = np.flatnonzero(left[i:ends[i]]) + i
            if count[i] < MIN_POLES:
                break
            if _follows(ff[members], vv[members], tol):
                best = i
                break
        if best < 0:
            break
        members = np.flatnonzero(left[best:ends[best]]) + best
        found.append(float(np.exp(np.median(lo[members]))))
        left[members] = False
    return tuple(sorted(found))


def _follows(freq_hz: np.ndarray, speed: np.ndarray, tol: float) -> bool:
    """Poles of one order band follow the speed: their speeds span ``MIN_SPEED_RATIO`` and their
    frequencies fill that span without a gap wider than ``MAX_GAP_SHARE`` of it (poles of different
    modes that share an order by coincidence sit at a few far-apart frequencies)."""
    if speed.max() < MIN_SPEED_RATIO * speed.min():
        return False
    lf = np.sort(np.log(freq_hz))
    return float(np.diff(lf).max()) <= max(3 * tol, MAX_GAP_SHARE * float(lf[-1] - lf[0]))


def sinusoid_kurtosis(y: np.ndarray, sample_rate_hz: float, freq_hz: np.ndarray, damping_ratio: np.ndarray,
                      window_s: float, shapes: np.ndarray | None = None) -> np.ndarray:
    """Kurtosis [n_poles] of the record ``y`` [n, n_channels] projected on each pole's shape (or summed
    over channels) and band-passed (ideal, by FFT) to ``f +- max(3 zeta f, 4 / window_s)``; the outer
    tenth at each end is left out (the circular filter's edges).  1.5 for a sinusoid, 3 for Gaussian
    noise (module docstring).

    Examples
    --------
    >>> t = np.arange(4096) / 1024.0
    >>> y = np.sin(2 * np.pi * 50.25 * t)[:, None]
    >>> round(float(sinusoid_kurtosis(y, 1024.0, np.array([50.25]), np.array([0.0]), 4.0)[0]), 2)
    1.5
    """
    f = np.asarray(freq_hz, float)
    if f.size == 0:
        return np.zeros(0)
    n = y.shape[0]
    w = np.ones((y.shape[1], f.size)) if shapes is None else np.real(shapes)
    Y = scipy.fft.rfft(y - y.mean(axis=0), axis=0) @ w                       # [n_freq, n_poles]
    lines = scipy.fft.rfftfreq(n, 1.0 / sample_rate_hz)
    half = np.maximum(3 * np.asarray(damping_ratio, float) * f, 4.0 / window_s)
    mask = np.abs(lines[:, None] - f[None, :]) <= half[None, :]
    x = scipy.fft.irfft(Y * mask, n, axis=0)[n // 10: n - n // 10]
    m2 = np.mean(x**2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(m2 > 0, np.mean(x**4, axis=0) / m2**2, 3.0)
