"""Frequency-domain decomposition (FDD): the quick look of output-only modal analysis (Brincker, Zhang &
Andersen 2001, Smart Mater. Struct. 10(3)).

The output cross-spectral matrix ``G(f)`` [n_channels x n_refs] is Welch-averaged (Hann, 50 % overlap,
one-sided densities scaled as ``scipy.signal.csd``); its singular values at every line, largest first,
are the FDD spectrum.  Near a mode the first singular value peaks and its left singular vector is the
(unscaled) mode shape.  Peaks are picked on the first singular value (6 dB prominence).  Frequency and
damping by enhanced FDD (EFDD, Brincker, Ventura & Andersen 2001, IMAC XIX): the lines around the peak
whose first singular vector has MAC >= 0.8 with the peak's form the mode's single-degree-of-freedom
bell, whose inverse FFT is the mode's correlation function, a free decay; its logarithmic decrement
(:func:`flexmodal.modal.damping.log_decrement`) gives the damping ratio and its zero-crossing rate the
damped frequency.  A peak whose bell spans fewer than 12 lines, or whose correlation function does
not decay along a straight line in log amplitude (R² < 0.9), is noise and is dropped.  The Hann
window's leakage widens the bell, so damping is biased high when the bell holds few lines: SSI
(:mod:`flexmodal.modal.ssi`) gives the damping to rely on.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.fft
import scipy.signal
from threadpoolctl import threadpool_limits

from flexmodal.contract.mac import mac_pairs, to_real, unit_max
from flexmodal.modal.damping import log_decrement
from flexmodal.modal.errors import ModalError
from flexmodal.modal.identify import Modes
from flexmodal.modal.indicators import mpc, mpd
from flexmodal.modal.oma_uncertainty import MAX_DECAY_FRACTION, jackknife_std
from flexmodal.modal.spectra import default_nfft, welch_spectra

# A mode's correlation function decays exponentially: R² of the log-decrement line >= 0.97 for the
# shear frame's modes, 0.66-0.83 for peaks of noise
MIN_DECAY_R2 = 0.9
# A mode dominates the cross-spectral matrix over many lines (the shear frame's: 93-411 lines at
# nfft 2048-8192); a noise peak's singular vector changes within a few (2-11 seen)
MIN_BELL_LINES = 12


@dataclass(frozen=True)
class FddResult:
    """``freq_hz`` [n_freq], ``singular_values`` [n_sv, n_freq] (units² / Hz, largest first), first
    singular vectors ``vectors`` [n_channels, n_freq], the picked ``modes`` and the cross-spectral
    matrix ``spectrum`` [n_freq, n_channels, n_refs] (units² / Hz) they come from."""

    freq_hz: np.ndarray
    singular_values: np.ndarray
    vectors: np.ndarray
    modes: Modes
    spectrum: np.ndarray | None = None


def cross_spectra(y: np.ndarray, sample_rate_hz: float, references: Sequence[int], nfft: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Welch cross-spectral densities G [n_freq, n_channels, n_refs] of ``y`` [n_samples, n_channels]
    (Hann window, 50 % overlap, segment means removed), ``G_jk = 2 E[Y_j Y_k*] / (fs sum w^2)``, and
    the frequency lines [Hz]: flexmodal's one Welch engine (:func:`flexmodal.modal.spectra.welch_spectra`,
    the references as its inputs, every channel as an output), with its gap rule: segments that touch
    a gap (a NaN row) are left out."""
    s = welch_spectra(y, sample_rate_hz, list(references), range(y.shape[1]), nfft, min_segments=0)
    if s.n_averages == 0:
        raise ModalError(f"FDD: no segment of {nfft} samples free of gaps")
    return s.freq_hz, np.moveaxis(s.g_xf, -1, 0)


def fdd(y: np.ndarray, sample_rate_hz: float, *, references: Sequence[int] | None = None,
        nfft: int | None = None, fmin: float | None = None, fmax: float | None = None,
        prominence_db: float = 6.0, mac_min: float = 0.8, uncertainty_blocks: int = 0) -> FddResult:
    """FDD of an output-only record ``y`` [n_samples, n_channels]: singular values of the cross-spectral
    matrix with ``references`` (default all channels) and the peaks of the first between ``fmin`` and
    ``fmax`` Hz (see module docstring).  ``nfft`` defaults to the power of two giving >= 8 segments.
    ``uncertainty_blocks``: each mode's ``freq_std_hz``/``damping_std`` by the delete-one-block
    jackknife over that many contiguous blocks of the record (modal/oma_uncertainty.py; 0: none, as
    ``identify`` runs it: about four times FDD's cost)."""
    y = np.asarray(y, float)
    if y.ndim != 2 or np.isinf(y).any():
        raise ModalError(f"FDD: record of shape {y.shape} is not a finite [n_samples, n_channels] array "
                         "(NaN rows are gaps)")
    n_ch = y.shape[1]
    refs = list(range(n_ch)) if references is None else [int(r) for r in references]
    if not refs or any(r < 0 or r >= n_ch for r in refs):
        raise ModalError(f"FDD: reference channels {refs} must be indices below {n_ch}")
    nfft = default_nfft(y.shape[0]) if nfft is None else int(nfft)
    if nfft < 16 or nfft > y.shape[0]:
        raise ModalError(f"FDD: segment of {nfft} samples does not fit a record of {y.shape[0]}")
    f, G = cross_spectra(y, sample_rate_hz, refs, nfft)
    U, sv, _ = np.linalg.svd(G, full_matrices=False)                                   # batched over lines
    band = (f >= (fmin if fmin is not None else f[1])) & (f <= (fmax if fmax is not None else f[-1]))
    level = 10 * np.log10(sv[:, 0] + 1e-300)
    level = np.where(band, level, level[band].min() if band.any() else 0.0)
    peaks, _ = scipy.signal.find_peaks(level, prominence=prominence_db)
    peaks = peaks[band[peaks]]
    if peaks.size == 0:
        raise ModalError(f"FDD: no peak of the first singular value between {f[band].min():g} and "
                         f"{f[band].max():g} Hz")
    fn, zeta, lines, warnings = [], [], [], []
    for k in peaks:   # a loop over peaks (modes)
        try:
            z, f_n = _efdd(f, sv[:, 0], U[:, :, 0], int(k), sample_rate_hz, mac_min)
        except ModalError as exc:
            warnings.append(f"FDD peak at {f[k]:.4g} Hz: {exc}")
            continue
        fn.append(f_n)
        zeta.append(z)
        lines.append(int(k))
    if not fn:
        raise ModalError("FDD: no peak gave a decaying correlation function (" + "; ".join(warnings) + ")")
    complex_shapes = unit_max(U[lines, :, 0].T)
    modes = Modes(np.array(fn), np.array(zeta), to_real(complex_shapes), complex_shapes, "fdd", False,
                  tuple(warnings), mpc=mpc(complex_shapes), mpd=mpd(complex_shapes))
    if uncertainty_blocks:   # freq_std_hz / damping_std (issue 26)
        with threadpool_limits(1, "blas"):        # small batched SVDs: threads only spin on them
            std = _jackknife(y, sample_rate_hz, refs, nfft, lines, mac_min, uncertainty_blocks)
        # a mode decaying over more than MAX_DECAY_FRACTION of a block: the blocks are not independent
        block_s = y.shape[0] / _n_blocks(y.shape[0], nfft, uncertainty_blocks) / sample_rate_hz
        std[1.0 / (modes.damping_ratio * 2 * np.pi * modes.freq_hz) > MAX_DECAY_FRACTION * block_s] = np.nan
        modes = replace(modes, freq_std_hz=std[:, 0], damping_std=std[:, 1])
    return FddResult(f, sv.T, U[:, :, 0].T, modes, G)


def _n_blocks(n_samples: int, nfft: int, n_blocks: int) -> int:
    """Blocks of at least two half-overlapping segments, at most ``n_blocks`` (and at least 1)."""
    return max(1, min(n_blocks, int(n_samples // (1.5 * nfft))))


def _jackknife(y: np.ndarray, sample_rate_hz: float, refs: list[int], nfft: int, lines: list[int],
               mac_min: float, n_blocks: int) -> np.ndarray:
    """Standard deviations [n_modes, 2] of (f_n [Hz], zeta) of the EFDD modes at ``lines``: the
    delete-one-block jackknife over ``n_blocks`` contiguous blocks (fewer when a block would hold
    fewer than two segments; NaN below 4 blocks or where a block's removal loses the mode), each
    mode's bell kept at its lines in the whole record's spectrum (the jackknife needs a smooth
    statistic; the bell's edges are a threshold decision)."""
    n_b = _n_blocks(y.shape[0], nfft, n_blocks)
    nan = np.full((len(lines), 2), np.nan)
    if n_b < 4:
        return nan
    length = y.shape[0] // n_b
    try:
        G = np.stack([cross_spectra(y[j * length:(j + 1) * length], sample_rate_hz, refs, nfft)[1]
                      for j in range(n_b)])                   # a loop over blocks
    except ModalError:                                        # a block that is all gaps
        return nan
    f = np.fft.rfftfreq(nfft, 1.0 / sample_rate_hz)
    total = G.sum(axis=0)
    U, sv, _ = np.linalg.svd(total / n_b, full_matrices=False)
    bells = [_bell(sv[:, 0], U[:, :, 0], k, mac_min) for k in lines]
    est = np.full((n_b, len(lines), 2), np.nan)
    used = np.unique(np.concatenate([np.arange(lo, hi) for lo, hi in bells]))
    s1 = np.zeros(f.size)
    for j in range(n_b):                                      # a loop over blocks left out
        s1[used] = np.linalg.svd((total[used] - G[j, used]) / (n_b - 1), compute_uv=False)[:, 0]
        for m, k in enumerate(lines):                         # and over modes
            try:
                z, f_n = _efdd(f, s1, U[:, :, 0], k, sample_rate_hz, mac_min, bells[m])
            except ModalError:
                continue
            est[j, m] = f_n, z
    return jackknife_std(est)


def _bell(s1: np.ndarray, u1: np.ndarray, peak: int, mac_min: float) -> tuple[int, int]:
    """Lines [lo, hi) around ``peak`` whose first singular vector has MAC >= ``mac_min`` with the peak's."""
    similar = mac_pairs(u1.T, np.broadcast_to(u1[peak], u1.shape).T) >= mac_min
    edges = np.flatnonzero(~similar)
    return int(edges[edges < peak].max(initial=-1) + 1), int(edges[edges > peak].min(initial=s1.size))


def _efdd(freq_hz: np.ndarray, s1: np.ndarray, u1: np.ndarray, peak: int, sample_rate_hz: float,
          mac_min: float, bell: tuple[int, int] | None = None) -> tuple[float, float]:
    """EFDD damping ratio and undamped natural frequency [Hz] of the peak at line ``peak`` of the first
    singular value ``s1`` [n_freq] with first singular vectors ``u1`` [n_freq, n_channels] (over the
    lines ``bell`` when given, else :func:`_bell`)."""
    lo, hi = bell or _bell(s1, u1, peak, mac_min)
    if hi - lo < MIN_BELL_LINES:
        raise ModalError(f"its singular vector stays similar over {hi - lo} lines only (< {MIN_BELL_LINES}): "
                         "a noise peak, not a mode")
    bell = np.zeros_like(s1)
    bell[lo:hi] = s1[lo:hi]
    nfft = 2 * (s1.size - 1)
    corr = scipy.fft.irfft(bell, nfft)[: nfft // 2]
    dec = log_decrement(corr, sample_rate_hz, float(freq_hz[peak]), floor=0.1)
    if dec.r2 < MIN_DECAY_R2:
        raise ModalError(f"its correlation function does not decay exponentially (R² {dec.r2:.2f} < "
                         f"{MIN_DECAY_R2}): a noise peak, not a mode")
    return dec.damping_ratio, dec.fn_hz / np.sqrt(1 - dec.damping_ratio ** 2)
