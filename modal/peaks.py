"""Peak picking guided by a mode indicator function and the coherence, with quadrature (imaginary
part) shapes as seed 001 measured them (Ewins 2000 §4.2; Shih et al. 1988 for the CMIF)."""

from __future__ import annotations

import numpy as np
import scipy.signal


def cmif(H: np.ndarray) -> np.ndarray:
    """Complex mode indicator function [min(n_out, n_in), n_freq]: singular values of H at each line,
    largest first (for one reference: the root sum of squares over the outputs)."""
    return np.linalg.svd(np.moveaxis(H, -1, 0), compute_uv=False).T


def pick_peaks(freq_hz: np.ndarray, H: np.ndarray, *, coherence: np.ndarray | None = None,
               min_coherence: float = 0.8, prominence_db: float = 3.0, fmin: float = 0.0,
               fmax: float = np.inf) -> np.ndarray:
    """Line indices of resonance peaks of the first CMIF inside [fmin, fmax]: local maxima standing
    ``prominence_db`` above their surroundings, where the mean coherence over the outputs is at least
    ``min_coherence``."""
    f = np.asarray(freq_hz)
    ind = 20 * np.log10(cmif(H)[0] + 1e-300)
    band = (f >= fmin) & (f <= fmax)
    ind = np.where(band, ind, ind[band].min() if band.any() else 0.0)
    peaks, _ = scipy.signal.find_peaks(ind, prominence=prominence_db)
    peaks = peaks[band[peaks]]
    if coherence is not None:
        peaks = peaks[np.mean(coherence, axis=0)[peaks] >= min_coherence]
    return peaks


def clear_peaks(freq_hz: np.ndarray, H: np.ndarray, *, prominence_db: float = 10.0,
                above_noise: float = 30.0, span: int = 50) -> np.ndarray:
    """Line indices of the peaks of the first CMIF of ``H`` [n_out, n_in, n_freq] that stand clearly
    above the noise: ``prominence_db`` [dB] above the higher of the lowest points on either side before
    a higher peak, and ``above_noise`` times the noise of the curve around them (the median absolute
    second difference of the CMIF in dB over ``span`` lines either side: a few tenths of a dB where
    the FRFs are clean, several dB where noise dominates, e.g. at a zero of an impact's force
    spectrum).  A mode the data show; their count is a floor for what an identification must find.

    Examples
    --------
    >>> f = np.arange(1.0, 200.0)
    >>> H = (1 / (50.0 ** 2 - f ** 2 + 1j * f) + 1 / (120.0 ** 2 - f ** 2 + 2j * f))[None, None, :]
    >>> f[clear_peaks(f, H)].tolist()
    [50.0, 120.0]
    """
    ind = 20 * np.log10(cmif(np.asarray(H))[0] + 1e-300)
    peaks, props = scipy.signal.find_peaks(ind, prominence=prominence_db)
    if peaks.size == 0:
        return peaks
    rough = np.abs(np.diff(ind, 2))
    noise = np.array([np.median(rough[max(0, k - span):k + span]) for k in peaks])   # a loop over peaks
    return peaks[props["prominences"] >= above_noise * noise]


def visible_peaks(freq_hz: np.ndarray, H: np.ndarray, *, prominence_db: float = 3.0) -> np.ndarray:
    """Frequencies [Hz], ascending, of the peaks standing ``prominence_db`` above their surroundings in
    any FRF magnitude or any CMIF curve of ``H`` [n_out, n_in, n_freq]: where the data show a resonance
    (a mode with none of these near it and no close neighbour is not one the FRFs show).

    Examples
    --------
    >>> f = np.arange(1.0, 200.0)
    >>> H = (1 / (50.0 ** 2 - f ** 2 + 1j * f))[None, None, :] * np.array([1.0, -2.0])[:, None, None]
    >>> visible_peaks(f, H).tolist()
    [50.0]
    """
    f = np.asarray(freq_hz, float)
    curves = np.concatenate([np.abs(np.asarray(H)).reshape(-1, f.size), cmif(np.asarray(H))])
    db = 20 * np.log10(curves + 1e-300)
    lines = [scipy.signal.find_peaks(c, prominence=prominence_db)[0] for c in db]   # a loop over curves
    return f[np.unique(np.concatenate(lines))]


def quadrature_shapes(H_receptance: np.ndarray, lines: np.ndarray, reference: int = 0) -> np.ndarray:
    """Mode shapes [n_out, n_modes] as the imaginary part of the receptance at each resonance line
    (proportional damping, well separated modes)."""
    return np.asarray(H_receptance)[:, reference, np.asarray(lines, int)].imag
