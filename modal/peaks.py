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


def quadrature_shapes(H_receptance: np.ndarray, lines: np.ndarray, reference: int = 0) -> np.ndarray:
    """Mode shapes [n_out, n_modes] as the imaginary part of the receptance at each resonance line
    (proportional damping, well separated modes)."""
    return np.asarray(H_receptance)[:, reference, np.asarray(lines, int)].imag
