"""The free decay a sine sweep leaves behind each mode it passes: an estimate of damping independent
of flexmodal's identification and of sdypy-EMA's (scipy filters and a straight-line fit)."""

from __future__ import annotations

import numpy as np
import scipy.signal


def free_decay_damping(x: np.ndarray, fs: float, fn: float, half_band_hz: float) -> tuple[float, float]:
    """Damping ratio [-] of the mode near ``fn`` [Hz] from the free decay that follows a sine sweep's
    passage through it, and the rms residual [-] of the fit (natural log of the envelope: a clean
    exponential decay leaves ~0.01-0.1, a beat or a mode barely excited 0.15 and more).

    The log of the Hilbert envelope of the record band-passed to fn +- ``half_band_hz`` [Hz] (4th-order
    Butterworth, zero phase), fitted by a line from where it has fallen to half its maximum down to 5 %
    of it (logarithmic decrement: slope = -zeta 2 pi fn); ``fs`` is the sample rate [Hz]."""
    sos = scipy.signal.butter(4, [fn - half_band_hz, fn + half_band_hz], btype="band", fs=fs, output="sos")
    env = np.abs(scipy.signal.hilbert(scipy.signal.sosfiltfilt(sos, x)))
    top = int(np.argmax(env))
    start = top + int(np.argmax(env[top:] < 0.5 * env[top]))
    stop = start + int(np.argmax(env[start:] < 0.05 * env[top]))
    t = np.arange(start, stop) / fs
    line = np.polyfit(t, np.log(env[start:stop]), 1)
    residual = np.log(env[start:stop]) - np.polyval(line, t)
    return float(-line[0] / (2 * np.pi * fn)), float(np.sqrt(np.mean(residual ** 2)))
