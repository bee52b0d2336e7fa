"""Damping estimates: half-power bandwidth of a resonance peak (Ewins 2000 §4.3) and logarithmic
decrement of a free decay (Inman 2014 §1.6), with the quality information needed to trust them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal

from flexmodal.modal.errors import ModalError


@dataclass(frozen=True)
class HalfPower:
    """``fn_hz`` (interpolated peak), ``damping_ratio``, the -3 dB frequencies and warnings."""

    fn_hz: float
    damping_ratio: float
    f_low_hz: float
    f_high_hz: float
    warnings: tuple[str, ...]


def _crossing(f: np.ndarray, m: np.ndarray, k: int, level: float, step: int) -> tuple[float, int] | None:
    """Frequency where |H| first drops below ``level`` walking from line ``k`` by ``step`` (linear
    interpolation of |H|^2 between the two lines), and the number of lines walked."""
    j = k
    while 0 <= j + step < m.size:
        if m[j + step] < level:
            a, b = m[j] ** 2, m[j + step] ** 2
            x = (a - level ** 2) / (a - b)
            return float(f[j] + x * (f[j + step] - f[j])), abs(j - k) + 1
        if m[j + step] > 1.1 * m[k]:
            return None   # well above the peak before the -3 dB point: another mode is too close
        j += step
    return None


def half_power(freq_hz: np.ndarray, receptance_mag: np.ndarray, peak_index: int) -> HalfPower:
    """Half-power damping of the peak reached by climbing from line ``peak_index`` of a receptance
    magnitude.

    The peak is refined by a parabola through three lines; the -3 dB points are interpolated; the
    damping ratio is ``(f2^2 - f1^2) / (4 fn^2)`` (exact for a single-degree-of-freedom receptance
    to first order in zeta^2).  Warns when fewer than three lines fall inside the half-power band or
    another peak lies within three bandwidths; raises ModalError when a -3 dB point cannot be found.
    """
    f = np.asarray(freq_hz, float)
    m = np.asarray(receptance_mag, float)
    k = int(peak_index)
    k = max(1, min(m.size - 2, k))
    while 1 <= k - 1 and k + 1 < m.size - 1 and max(m[k - 1], m[k + 1]) > m[k]:   # climb to the top
        k += 1 if m[k + 1] > m[k - 1] else -1
    y0, y1, y2 = m[k - 1], m[k], m[k + 1]
    if y1 < max(y0, y2):   # still climbing at the band's edge: the parabola's top lay lines away (< 0 Hz)
        raise ModalError(f"half-power at {f[k]:.4g} Hz: the peak lies at the band edge (no -3 dB point on "
                         f"its {'lower' if y0 > y1 else 'upper'} side)")
    den = y0 - 2 * y1 + y2
    shift = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    df = f[1] - f[0]
    fn = f[k] + shift * df
    peak = y1 - 0.25 * (y0 - y2) * shift
    level = peak / np.sqrt(2)
    warnings = []
    lo, hi = _crossing(f, m, k, level, -1), _crossing(f, m, k, level, +1)
    if lo is None or hi is None:
        raise ModalError(f"half-power at {fn:.4g} Hz: no -3 dB point on both sides (modes too close "
                         "or band edge)")
    if lo[1] + hi[1] - 1 < 3:
        warnings.append(f"half-power at {fn:.4g} Hz: only {lo[1] + hi[1] - 1} lines in the -3 dB band "
                        "(resolution too coarse)")
    zeta = (hi[0] ** 2 - lo[0] ** 2) / (4 * fn ** 2)
    bw = hi[0] - lo[0]
    inner = (m[1:-1] > m[:-2]) & (m[1:-1] >= m[2:]) & (m[1:-1] > 0.25 * peak)
    near = np.flatnonzero(inner) + 1
    near = near[(np.abs(f[near] - fn) < 3 * bw) & (np.abs(near - k) > 1)]
    if near.size:
        warnings.append(f"half-power at {fn:.4g} Hz: modes too close (another peak at {f[near[0]]:.4g} Hz "
                        "within three bandwidths)")
    return HalfPower(float(fn), float(zeta), lo[0], hi[0], tuple(warnings))


@dataclass(frozen=True)
class LogDecrement:
    """``damping_ratio`` from the fitted decrement, ``fn_hz`` (damped, from peak spacing), the number
    of cycles fitted and ``r2`` of the straight-line fit of log amplitude against cycles."""

    damping_ratio: float
    fn_hz: float
    n_cycles: float
    r2: float


def log_decrement(signal: np.ndarray, sample_rate_hz: float, fn_hz: float, *,
                  highpass_hz: float | None = None, band: tuple[float, float] = (0.6, 1.5),
                  floor: float = 0.02, skip_cycles: float = 1.0) -> LogDecrement:
    """Logarithmic decrement of a free decay dominated by a mode near ``fn_hz``.

    As seed 000 did, the record is high-pass filtered (``highpass_hz``, default fn/4) to remove drift;
    then band-passed to ``band`` x fn to isolate the mode (zero-phase Butterworth filters).  Positive
    and negative peaks (refined by a parabola) from the largest one on, after ``skip_cycles`` cycles and
    down to ``floor`` times the largest, are fitted by a straight line ln|a| = c - delta n / 2 over
    half-cycles n; ``zeta = delta / sqrt(4 pi^2 + delta^2)``.
    """
    x = np.asarray(signal, float)
    if x.ndim != 1 or x.size < 16 or not np.all(np.isfinite(x)):
        raise ModalError("log decrement: the record must be a finite 1-D signal of 16 samples or more")
    nyq = 0.5 * sample_rate_hz
    if not 0 < fn_hz * band[1] < nyq:
        raise ModalError(f"log decrement: {fn_hz} Hz is outside the record's bandwidth ({nyq} Hz)")
    hp = fn_hz / 4 if highpass_hz is None else highpass_hz
    sos = scipy.signal.butter(2, hp / nyq, "highpass", output="sos")
    y = scipy.signal.sosfiltfilt(sos, x)
    sos = scipy.signal.butter(2, [band[0] * fn_hz / nyq, band[1] * fn_hz / nyq], "bandpass", output="sos")
    y = scipy.signal.sosfiltfilt(sos, y)
    dist = max(1, int(0.35 * sample_rate_hz / fn_hz))
    idx = np.sort(np.concatenate([scipy.signal.find_peaks(y, distance=dist)[0],
                                  scipy.signal.find_peaks(-y, distance=dist)[0]]))
    idx = idx[(idx > 0) & (idx < y.size - 1)]
    a0, a1, a2 = np.abs(y[idx - 1]), np.abs(y[idx]), np.abs(y[idx + 1])
    den = a0 - 2 * a1 + a2
    with np.errstate(divide="ignore", invalid="ignore"):
        sh = np.where(den < 0, 0.5 * (a0 - a2) / den, 0.0)
    amp = a1 - 0.25 * (a0 - a2) * sh
    t = (idx + sh) / sample_rate_hz
    start = int(np.argmax(amp)) + int(round(2 * skip_cycles))
    amp, t = amp[start:], t[start:]
    keep = np.flatnonzero(amp < floor * amp.max()) if amp.size else np.array([], int)
    stop = keep[0] if keep.size else amp.size
    amp, t = amp[:stop], t[:stop]
    if amp.size < 4:
        raise ModalError(f"log decrement at {fn_hz} Hz: fewer than 4 peaks above the noise floor")
    n = np.arange(amp.size, dtype=float)
    coef = np.polyfit(n, np.log(amp), 1)
    resid = np.log(amp) - np.polyval(coef, n)
    r2 = 1 - resid.var() / np.log(amp).var()
    delta = -2 * coef[0]
    zeta = delta / np.sqrt(4 * np.pi ** 2 + delta ** 2)
    fd = 0.5 * (amp.size - 1) / (t[-1] - t[0])
    return LogDecrement(float(zeta), float(fd), 0.5 * (amp.size - 1), float(r2))
