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
import scipy.ndimage
import scipy.optimize
import scipy.signal

from flexmodal.checked_io.blas import one_blas_thread

MIN_POLES = 5            # orders are looked for in at least this many windows ...
MIN_SPEED_SHARE = 0.2    # ... where the joint turns faster than this share of its fastest
WHITEN_LINES = 31        # each window's order power is divided by its running median over this many lines
ORDER_PROMINENCE = 10.0  # an order peak stands this many times above its surroundings (10 dB)
REMOVE_BLOCK_S = 1.0     # harmonics are fitted over blocks this long and taken out of their middle half


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


def angle_resampled(y: np.ndarray, sample_rate_hz: float, angle_deg: np.ndarray) -> tuple[np.ndarray, float]:
    """The window ``y`` [n, n_channels] resampled at ``n`` equal steps of joint angle (computed order
    tracking, Fyfe & Munck 1997, Mech. Syst. Signal Process. 11(2)): the angle is the least-squares
    quadratic through the encoder samples ``angle_deg`` [n] (sub-count resolution), monotone over a
    window where the joint does not reverse.  Returns the resampled window and its angle span [rev]."""
    n = y.shape[0]
    t = np.arange(n) / sample_rate_hz
    fit = np.polyval(np.polyfit(t, angle_deg, 2), t)
    if fit[-1] < fit[0]:
        fit = -fit
    fit = np.maximum.accumulate(fit)
    grid = np.linspace(fit[0], fit[-1], n)
    at = np.interp(grid, fit, t) * sample_rate_hz
    i = np.clip(at.astype(int), 0, n - 2)
    w = (at - i)[:, None]
    return (1 - w) * y[i] + w * y[i + 1], float(fit[-1] - fit[0]) / 360.0


def order_spectrum(windows: Sequence[tuple[np.ndarray, np.ndarray]], sample_rate_hz: float,
                   orders: np.ndarray) -> np.ndarray:
    """Mean whitened order spectrum on ``orders`` [per revolution] of the ``windows`` (each a record
    [n, n_channels] and its joint angle [n] in degrees): every window resampled in angle
    (:func:`angle_resampled`), its Hann-windowed power summed over channels and divided by its running
    median over ``WHITEN_LINES`` lines (a line stands out of it, a mode's broad peak much less),
    interpolated onto ``orders`` (log-linear); NaN where fewer than ``MIN_POLES`` windows reach.  A
    harmonic adds up at its order in every window; a mode, whose frequency does not follow the speed,
    spreads over many orders."""
    total = np.zeros(orders.size)
    count = np.zeros(orders.size)
    for y, angle in windows:   # a loop over windows
        x, revs = angle_resampled(y - y.mean(axis=0), sample_rate_hz, angle)
        if revs <= 0:
            continue
        power = np.sum(np.abs(scipy.fft.rfft(x * np.hanning(x.shape[0])[:, None], axis=0)) ** 2, axis=1)
        o = np.arange(power.size) / revs
        inside = (orders >= o[1]) & (orders <= o[-1])
        white = power / scipy.ndimage.median_filter(power, WHITEN_LINES, mode="nearest")
        total[inside] += np.interp(np.log(orders[inside]), np.log(o[1:]), white[1:])
        count[inside] += 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count >= MIN_POLES, total / np.maximum(count, 1), np.nan)


def find_orders(windows: Sequence[tuple[np.ndarray, np.ndarray]], sample_rate_hz: float,
                speed_rev_per_s: np.ndarray, band_hz: tuple[float, float], tol: float) -> tuple[float, ...]:
    """Harmonic orders [per revolution] of a joint: the windows where it turns (``speed_rev_per_s``
    [n_windows] above ``MIN_SPEED_SHARE`` of the fastest) are split in thirds by speed, and the
    orders are the peaks of the smaller of the slowest and fastest thirds' :func:`order_spectrum` standing
    ``ORDER_PROMINENCE`` times above their surroundings (a harmonic stands at its order at every speed; a
    mode's apparent order ``f / v`` differs between the thirds), between ``band_hz`` [Hz] at the fastest
    speed and at the slowest; an order that only one third reaches (NaN in the other) is never one.  The
    order grid is log-spaced in steps of ``tol / 4``; each order found there is refined off the grid, within
    one step, on all the windows where the joint turns (:func:`refine_order`)."""
    v = np.asarray(speed_rev_per_s, float)
    keep = np.flatnonzero(v > MIN_SPEED_SHARE * v.max(initial=0.0))
    if keep.size < MIN_POLES:
        return ()
    lo, hi = max(band_hz[0], 1.0) / v.max(), band_hz[1] / v[keep].min()
    orders = np.exp(np.arange(np.log(lo), np.log(hi), tol / 4))
    third, two_thirds = np.percentile(v[keep], [100 / 3, 200 / 3])
    slow, fast = keep[v[keep] <= third], keep[v[keep] >= two_thirds]
    s_slow = order_spectrum([windows[k] for k in slow], sample_rate_hz, orders)
    s_fast = order_spectrum([windows[k] for k in fast], sample_rate_hz, orders)
    spec = np.minimum(s_slow, s_fast)
    good = np.isfinite(spec)
    level = np.log10(np.where(good, spec, 1.0))
    peaks, _ = scipy.signal.find_peaks(level, prominence=np.log10(ORDER_PROMINENCE))
    turning = [windows[k] for k in keep]
    return tuple(refine_order(turning, sample_rate_hz, float(orders[p]), tol / 4) for p in peaks
                 if good[p] and _peaks_near(s_slow, p) and _peaks_near(s_fast, p))


def refine_order(windows: Sequence[tuple[np.ndarray, np.ndarray]], sample_rate_hz: float, order: float,
                 span: float) -> float:
    """The order [per revolution] within relative ``span`` of ``order`` where the ``windows``' (each a
    record [n, n_channels] and its joint angle [n] in degrees) summed whitened power is largest: the
    maximiser of ``sum_k |X_k(o)|^2 / (N_k + P_k)`` with ``X_k(o) = sum_n h_n y_kn exp(-2 pi i o theta_kn)``
    (summed over channels), ``h`` a Hann window, ``theta`` the angle [rev] a cubic through the encoder
    samples, ``N_k`` the window's power level around the order (median over ``WHITEN_LINES`` lines) and
    ``P_k`` its largest ``|X_k|^2`` within the span.  This is the maximum-likelihood estimate of the
    order of a harmonic with its own amplitude and phase in each window (Rife & Boorstyn 1974, IEEE
    Trans. Inf. Theory 20(5): the periodogram maximum, here summed over windows and channels) over a
    noise of level ``N_k + P_k``: besides the window's broadband power, an error as large as the
    harmonic itself, as its response is a constant-phase sinusoid only away from the modes (sweeping
    through a resonance its phase turns by up to 180 degrees within a window: on the Modbus-polled sweep
    of tests/test_track_streams.py the two windows at the crossing, weighted ``1 / N_k`` alone, outweighed
    the 83 others and pulled 3600 to 3592.6).  Each window where the harmonic stands above its
    broadband power thus counts about equally; with equal windows, amplitudes and noise this is the
    plain maximum-likelihood estimate.  Found by a scan in steps of at most one
    line of the longest window (``1 / revolutions``; its Hann main lobe is four lines wide) and Brent's
    method between the best step's neighbours: not limited to a grid.  Windows where the order lies
    beyond Nyquist take no part; with none, ``order`` is returned.

    Examples
    --------
    >>> fs, t = 1024.0, np.arange(2048) / 1024.0
    >>> rng = np.random.default_rng(0)
    >>> wins = [(np.cos(2 * np.pi * 3603.7 * v * t)[:, None] + rng.standard_normal((t.size, 1)), 360 * v * t)
    ...         for v in (0.05, 0.08, 0.11)]
    >>> round(refine_order(wins, fs, 3600.0, 0.005), 1)
    3603.7
    """
    data, theta, bounds, noise, revs = _order_terms(windows, sample_rate_hz, order)
    if not noise.size:
        return order

    def power(o: float) -> np.ndarray:   # [n_windows]
        x = np.add.reduceat(data * np.exp(-2j * np.pi * o * theta)[:, None], bounds, axis=0)
        return np.sum(np.abs(x) ** 2, axis=1)

    lo, hi = order * np.exp(-span), order * np.exp(span)
    scan = np.linspace(lo, hi, max(3, int(np.ceil((hi - lo) * revs)) + 1))   # steps <= one line
    each = np.array([power(o) for o in scan])   # [n_scan, n_windows]: a loop over candidate orders
    weight = 1.0 / (noise + each.max(axis=0))
    level = each @ weight
    b = int(np.argmax(level))
    best = scipy.optimize.minimize_scalar(lambda o: -float(power(o) @ weight), method="bounded",
                                          bounds=(scan[max(b - 1, 0)], scan[min(b + 1, scan.size - 1)]),
                                          options={"xatol": 1e-3 / revs})
    return float(best.x) if -best.fun >= level[b] else float(scan[b])


def _order_terms(windows: Sequence[tuple[np.ndarray, np.ndarray]], sample_rate_hz: float, order: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """:func:`refine_order`'s terms: the Hann-weighted records stacked [sum n, n_channels], their angles
    [rev] (each window's centred on its Hann-weighted mean), the first row of each window, the power
    level ``N_k`` of each and the largest angle span [rev]; windows where ``order`` lies beyond Nyquist
    are left out."""
    data, theta, noise, spans = [], [], [], []
    for y, angle in windows:   # a loop over windows
        n = y.shape[0]
        tau = np.linspace(-1.0, 1.0, n)
        th = np.polyval(np.polyfit(tau, angle, 3), tau) / 360.0
        hann = np.hanning(n)
        th = th - hann @ th / hann.sum()
        g = hann[:, None] * (y - y.mean(axis=0))
        line = int(round(order * abs(th[-1] - th[0])))   # the harmonic's cycles in the window
        if not 0 < line < n // 2:
            continue
        power = np.sum(np.abs(scipy.fft.rfft(g, axis=0)) ** 2, axis=1)
        near = power[max(line - WHITEN_LINES // 2, 1):line + WHITEN_LINES // 2 + 1]
        data.append(g)
        theta.append(th)
        noise.append(np.median(near))
        spans.append(abs(th[-1] - th[0]))
    if not data:
        return np.zeros((0, 1)), np.zeros(0), np.zeros(0, int), np.zeros(0), 0.0
    bounds = np.cumsum([0] + [d.shape[0] for d in data[:-1]])
    return np.vstack(data), np.concatenate(theta), bounds, np.array(noise), max(spans)


def _peaks_near(spec: np.ndarray, p: int, lines: int = 4) -> bool:
    """Whether ``spec`` has a local maximum within ``lines`` grid lines (``tol`` on the grid of
    :func:`find_orders`) of line ``p``: a harmonic stands at its order in each speed third's own
    spectrum.  The minimum of the two can peak where neither does (one third's hump on the other's
    rising flank: the demo arm's 30 s sweep gave order 327.4 that way, with no harmonic in it)."""
    lo, hi = max(p - lines, 0), min(p + lines + 1, spec.size)
    j = lo + int(np.argmax(np.where(np.isfinite(spec[lo:hi]), spec[lo:hi], -np.inf)))
    return lo < j < hi - 1 or j in (0, spec.size - 1)


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


def remove_orders(y: np.ndarray, sample_rate_hz: float, angle_deg: np.ndarray,
                  orders: Sequence[Sequence[float]]) -> np.ndarray:
    """The record ``y`` [n, n_channels] without its harmonics of the joints whose encoder angles are
    the columns of ``angle_deg`` [n, n_joints] (degrees) and whose ``orders`` (per revolution, one
    sequence per joint) are known.

    A harmonic of order ``o`` has the phase ``2 pi o theta / 360`` of its joint's angle ``theta`` (it is
    locked to the motor's rotation), so over a block it is ``(a + b tau) cos(phase) + (c + d tau)
    sin(phase)`` with ``tau`` the block's time, amplitudes linear in it (the response to a harmonic changes
    as it sweeps past a mode): the least-squares fit of those four columns per harmonic, over blocks of
    ``REMOVE_BLOCK_S`` every half block (the angle a cubic through the encoder samples: sub-count
    resolution), is subtracted from the middle half of each block (a Vold-Kalman-like order
    extraction with known phase; Vold & Leuridan 1993, SAE 931288; Brandt, *Noise and Vibration
    Analysis*, 2011, §12.5).  A mode's random response is hardly touched: each harmonic takes four of the
    block's degrees of freedom.  Rows with a NaN (lost samples) take no part and stay NaN.

    Examples
    --------
    >>> fs, t = 1024.0, np.arange(4096) / 1024.0
    >>> angle = 2.0 * t + 0.1 * t**2                  # deg: a joint speeding up
    >>> hum = 0.5 * np.cos(2 * np.pi * 3600 * angle / 360 + 1.0)
    >>> noise = np.random.default_rng(0).standard_normal(t.size)
    >>> y = (noise + hum)[:, None]
    >>> clean = remove_orders(y, fs, angle[:, None], [(3600.0,)])
    >>> round(float(np.std(y[:, 0] - noise)), 2), round(float(np.std(clean[:, 0] - noise)), 2)
    (0.35, 0.06)

    What is left, 0.06, is the noise's own projection on the fitted columns (``sqrt(4 / 1024)``).
    """
    out = np.array(y, float)
    n = y.shape[0]
    if not any(len(o) for o in orders) or n < 8:
        return out
    block = min(n, max(8, int(round(REMOVE_BLOCK_S * sample_rate_hz))))
    hop = max(1, block // 2)
    starts = list(range(0, max(n - block, 0) + 1, hop))
    if starts[-1] + block < n:
        starts.append(n - block)
    tau = np.linspace(-1.0, 1.0, block)
    with one_blas_thread():   # small least-squares fits: more threads only spin on them
        _remove_blocks(out, y, angle_deg, orders, starts, block, hop, tau)
    return out


def _remove_blocks(out: np.ndarray, y: np.ndarray, angle_deg: np.ndarray, orders: Sequence[Sequence[float]],
                   starts: list[int], block: int, hop: int, tau: np.ndarray) -> None:
    """:func:`remove_orders`' fits, block by block, written into ``out``."""
    for k, a in enumerate(starts):   # a loop over blocks
        seg, ang = y[a:a + block], angle_deg[a:a + block]
        good = np.isfinite(seg).all(axis=1) & np.isfinite(ang).all(axis=1)
        cols = []
        for j, ords in enumerate(orders):   # a loop over joints
            if not len(ords) or good.sum() < 8:
                continue
            smooth = np.polyval(np.polyfit(tau[good], ang[good, j], 3), tau)
            phase = 2 * np.pi * np.outer(smooth - smooth[block // 2], np.asarray(ords, float)) / 360.0
            c, s = np.cos(phase), np.sin(phase)
            cols += [c, s, tau[:, None] * c, tau[:, None] * s]
        if not cols:
            continue
        X = np.hstack(cols)
        if good.sum() <= 2 * X.shape[1]:
            continue
        beta = np.linalg.lstsq(X[good], seg[good], rcond=1e-8)[0]
        lo = 0 if k == 0 else block // 4
        hi = block if k == len(starts) - 1 else block - block // 4
        if k < len(starts) - 1 and starts[k + 1] - a < hop:   # the last block starts early: no gap left
            hi = block
        fit = X[lo:hi] @ beta
        out[a + lo:a + hi] = seg[lo:hi] - fit

