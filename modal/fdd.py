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

from flexmodal.checked_io.blas import one_blas_thread
from flexmodal.contract.mac import mac_pairs, to_real, unit_max
from flexmodal.modal.damping import log_decrement
from flexmodal.modal.errors import ModalError
from flexmodal.modal.identify import Modes
from flexmodal.modal.indicators import mpc, mpd
from flexmodal.modal.oma_uncertainty import (
    MAX_DECAY_FRACTION,
    N_BOOTSTRAP,
    bootstrap_weights,
    interval_factor,
)
from flexmodal.modal.spectra import default_nfft, welch_spectra
from flexmodal.modal.uncertainty import welch_noise

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
    ``uncertainty_blocks``: each mode's ``freq_std_hz``/``damping_std`` by the bootstrap over at most
    that many contiguous runs of the Welch segments (:func:`_bootstrap`, modal/oma_uncertainty.py; 0:
    none, as ``identify`` runs it)."""
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
    if not band.any():   # an fmin above Nyquist: the empty band's minimum was a numpy ValueError
        raise ModalError(f"FDD: no frequency line between {fmin if fmin is not None else f[1]:g} and "
                         f"{fmax if fmax is not None else f[-1]:g} Hz (lines 0..{f[-1]:g} Hz)")
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
        with one_blas_thread():        # small batched SVDs: threads only spin on them
            std, unit_s = _bootstrap(y, sample_rate_hz, refs, nfft, lines, mac_min, uncertainty_blocks,
                                     [_bell(sv[:, 0], U[:, :, 0], k, mac_min) for k in lines])
        # a mode decaying over more than MAX_DECAY_FRACTION of a unit: the units are not independent
        std[1.0 / (modes.damping_ratio * 2 * np.pi * modes.freq_hz) > MAX_DECAY_FRACTION * unit_s] = np.nan
        modes = replace(modes, freq_std_hz=std[:, 0], damping_std=std[:, 1])
    return FddResult(f, sv.T, U[:, :, 0].T, modes, G)


def _bootstrap(y: np.ndarray, sample_rate_hz: float, refs: list[int], nfft: int, lines: list[int],
               mac_min: float, n_units: int, bells: list[tuple[int, int]]) -> tuple[np.ndarray, float]:
    """Standard deviations [n_modes, 2] of (f_n [Hz], zeta) of the EFDD modes at ``lines`` and the
    length [s] of the shortest unit's own share of the record (a segment step per segment).

    The Welch segments (Hann, half-overlapping, as :func:`cross_spectra`) are split into at most
    ``n_units`` contiguous runs whose spectra, weighted by their segment counts (segments touching a
    gap left out), average to the record's; each of ``N_BOOTSTRAP`` replicates re-weights the runs by
    multinomial counts (modal/oma_uncertainty.py) and repeats EFDD at each mode's peak line over the
    record's bell ``bells`` (its lines [lo, hi), :func:`_bell`), without EFDD's detection checks (bell
    width, R²): whether the peak is a mode was decided once, on the record; the sigma is the scatter of
    its estimate.  (With each replicate's own bell and the checks, a quarter of the modes at 0.4-1 %
    damping got no sigma -- more than a quarter of their replicates failed -- and the rest covered
    less, the failures being the replicates that strayed furthest; with its own bell but no checks, a
    replicate's bell can shrink to a few lines and its sigma explode, 10x in Monte-Carlo.)
    The sigma is the replicates' standard deviation times ``sqrt(n / (n - 1))`` (the bootstrap's
    plug-in variance of a mean of n units), times the overlap of neighbouring units (the bootstrap
    takes the units as independent; the boundary segments of two neighbouring units overlap by half,
    their spectra correlated by ``rho = c(D)^2``, 1/36 for Hann at 50 % (Welch 1967; Harris 1978), so
    the mean's variance is ``1 + 2 rho (n - 1) / sum_i (c_i + 2 rho (c_i - 1))`` times the sum of the
    units' own, c_i the units' segment counts), times the Student factor of its degrees of freedom
    (:func:`flexmodal.modal.oma_uncertainty.interval_factor`: 14 single-segment units and 20
    replicates leave about 8, so that +-1.96 sigma is the 95 % interval; without it the intervals
    covered 91-93 % at best in Monte-Carlo).  A replicate whose log decrement fails (fewer than four
    peaks) is left out; NaN below 4 units, and for a mode whose EFDD fails in more than a quarter of
    the replicates."""
    step = nfft - int(round(0.5 * nfft))
    n_seg = (y.shape[0] - nfft) // step + 1
    runs = np.array_split(np.arange(n_seg), min(n_units, n_seg))
    nan = np.full((len(lines), 2), np.nan)
    spectra, counts = [], []
    for run in runs:                                          # a loop over units (runs of segments)
        unit = welch_spectra(y[run[0] * step:run[-1] * step + nfft], sample_rate_hz, refs, range(y.shape[1]),
                             nfft, min_segments=0)          # as cross_spectra, with its segment count
        if unit.n_averages:                                   # (segments touching a gap are left out)
            spectra.append(np.moveaxis(unit.g_xf, -1, 0))
            counts.append(unit.n_averages)
    unit_s = min(r.size for r in runs) * step / sample_rate_hz
    if len(counts) < 4:
        return nan, unit_s
    G, c = np.stack(spectra), np.asarray(counts, float)
    f = np.fft.rfftfreq(nfft, 1.0 / sample_rate_hz)
    est = np.full((N_BOOTSTRAP, len(lines), 2), np.nan)
    for b, w in enumerate(bootstrap_weights(len(c), N_BOOTSTRAP)):   # a loop over replicates
        wc = w * c
        U, sv, _ = np.linalg.svd(np.tensordot(wc, G, 1) / wc.sum(), full_matrices=False)
        for m, k in enumerate(lines):                         # and over modes
            try:
                z, f_n = _efdd(f, sv[:, 0], U[:, :, 0], k, sample_rate_hz, mac_min,
                               bells[m], checks=False)
            except ModalError:
                continue
            est[b, m] = f_n, z
    ok = np.isfinite(est[..., 0])
    n = len(c)
    std = np.array([np.std(est[ok[:, m], m], axis=0, ddof=1) * interval_factor(n, int(ok[:, m].sum()))
                    if ok[:, m].mean() >= 0.75 else [np.nan] * 2 for m in range(len(lines))])
    rho = welch_noise("hann", nfft).lag[step] ** 2
    overlap = 1.0 + 2.0 * rho * (n - 1) / float(np.sum(c + 2.0 * rho * (c - 1)))
    return std * np.sqrt(n / (n - 1.0) * overlap), unit_s


def _bell(s1: np.ndarray, u1: np.ndarray, peak: int, mac_min: float) -> tuple[int, int]:
    """Lines [lo, hi) around ``peak`` whose first singular vector has MAC >= ``mac_min`` with the peak's."""
    similar = mac_pairs(u1.T, np.broadcast_to(u1[peak], u1.shape).T) >= mac_min
    edges = np.flatnonzero(~similar)
    return int(edges[edges < peak].max(initial=-1) + 1), int(edges[edges > peak].min(initial=s1.size))


def _efdd(freq_hz: np.ndarray, s1: np.ndarray, u1: np.ndarray, peak: int, sample_rate_hz: float,
          mac_min: float, bell: tuple[int, int] | None = None, checks: bool = True) -> tuple[float, float]:
    """EFDD damping ratio and undamped natural frequency [Hz] of the peak at line ``peak`` of the first
    singular value ``s1`` [n_freq] with first singular vectors ``u1`` [n_freq, n_channels] (over the
    lines ``bell`` when given, else :func:`_bell`)."""
    lo, hi = bell or _bell(s1, u1, peak, mac_min)
    if checks and hi - lo < MIN_BELL_LINES:
        raise ModalError(f"its singular vector stays similar over {hi - lo} lines only (< {MIN_BELL_LINES}): "
                         "a noise peak, not a mode")
    bell = np.zeros_like(s1)
    bell[lo:hi] = s1[lo:hi]
    nfft = 2 * (s1.size - 1)
    corr = scipy.fft.irfft(bell, nfft)[: nfft // 2]
    dec = log_decrement(corr, sample_rate_hz, float(freq_hz[peak]), floor=0.1)
    if checks and dec.r2 < MIN_DECAY_R2:
        raise ModalError(f"its correlation function does not decay exponentially (R² {dec.r2:.2f} < "
                         f"{MIN_DECAY_R2}): a noise peak, not a mode")
    return dec.damping_ratio, dec.fn_hz / np.sqrt(1 - dec.damping_ratio ** 2)
