"""Averaged auto- and cross-spectra of all channels in one FFT pass (Welch 1967; Bendat & Piersol 2010 §11).

Conventions: ``g_xf[o, i] = E[X_o conj(F_i)]``, ``g_ff[i, j] = E[F_i conj(F_j)]``, ``g_xx[o] = E[|X_o|^2]``,
one-sided densities scaled like ``scipy.signal.csd(..., scaling="density")`` (units^2/Hz).  Segments are
processed in blocks small enough to stay in cache: per block one real FFT over every segment and
channel, then the products for all channel pairs at once; no loop over frequency lines or pairs.
float32 records are transformed in single precision and accumulated in double precision.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.fft

from flexmodal.modal.errors import ModalError
from flexmodal.modal.windows import window

_BLOCK_BYTES = 8 << 20      # windowed segments per block (with its spectra, fits the shared L3 cache)
_TILE = 2048                # rows per tile of the block transpose (stays in L1/L2)


@dataclass(frozen=True)
class Spectra:
    """Averaged one-sided spectra: ``freq_hz`` [n_freq], ``g_xf`` [n_out, n_in, n_freq],
    ``g_ff`` [n_in, n_in, n_freq], ``g_xx`` [n_out, n_freq] (real), ``n_averages`` segments or hits."""

    freq_hz: np.ndarray
    g_xf: np.ndarray
    g_ff: np.ndarray
    g_xx: np.ndarray
    n_averages: int


def density_scale(n_freq: int, nfft: int, sample_rate_hz: float, w: np.ndarray) -> np.ndarray:
    """One-sided density scaling per line: 2/(fs sum w^2), not doubled at DC and Nyquist."""
    scale = np.full(n_freq, 2.0 / (sample_rate_hz * float(np.sum(np.asarray(w, float) ** 2))))
    scale[0] /= 2
    if nfft % 2 == 0:
        scale[-1] /= 2
    return scale


def _auto(z: np.ndarray, weights: np.ndarray | None) -> np.ndarray:
    """Sum over segments (axis 1) of |z|^2 [c, f], computed on the real view (no complex temporaries)."""
    v = z.view(z.real.dtype)                                        # [c, s, 2f]: re, im interleaved
    sq = np.einsum("csf,csf->cf", v, v) if weights is None else np.einsum("csf,csf,s->cf", v, v, weights)
    return sq[:, 0::2] + sq[:, 1::2]


def _products(x: np.ndarray, n_in: int, weights: np.ndarray | None, work: np.ndarray | None = None):
    """(Weighted) sums over segments of the spectral products of one block ``x`` [ch, s, f] whose
    first ``n_in`` channels are the inputs: g_xf [o, i, f], g_ff [i, i, f], g_xx [o, f].  ``work``
    (at least [o, s, f], dtype of ``x``) takes the single-input products instead of a new array."""
    f, y = x[:n_in], x[n_in:]
    wy = y if weights is None else y * weights[None, :, None].astype(y.real.dtype)
    if n_in == 1:
        prod = np.multiply(wy, f[0].conj(), out=None if work is None else work[:, :y.shape[1]])
        g_xf = prod.sum(axis=1)[:, None, :]
        g_ff = _auto(f, weights)[:, None, :]
    else:
        wf = f if weights is None else f * weights[None, :, None].astype(f.real.dtype)
        g_xf = np.einsum("osf,isf->oif", wy, f.conj())
        g_ff = np.einsum("isf,jsf->ijf", wf, f.conj())
    return g_xf, g_ff, _auto(y, weights)


def spectra_of_segments(segments: np.ndarray, n_in: int, sample_rate_hz: float,
                        scale_window: np.ndarray, weights: np.ndarray | None = None) -> Spectra:
    """Spectra from already windowed segments [n_seg, n_ch, nfft] (inputs first), e.g. impact hits.

    ``weights`` [n_seg] (summing to 1) gives a weighted average (linear: equal; exponential: decaying).
    """
    nfft = segments.shape[-1]
    x = scipy.fft.rfft(np.moveaxis(segments, 1, 0), axis=-1)
    w = None if weights is None else np.asarray(weights, float)
    g_xf, g_ff, g_xx = _products(x, n_in, w)
    norm = 1.0 if w is not None else 1.0 / segments.shape[0]
    scale = density_scale(x.shape[-1], nfft, sample_rate_hz, scale_window) * norm
    return Spectra(np.fft.rfftfreq(nfft, 1.0 / sample_rate_hz), g_xf * scale, g_ff * scale,
                   g_xx * scale, segments.shape[0])


def _window_array(spec: str | np.ndarray, nfft: int) -> np.ndarray:
    if isinstance(spec, str):
        return window(spec, nfft)
    w = np.asarray(spec, float)
    if w.shape != (nfft,):
        raise ModalError(f"window array of shape {w.shape}: expected ({nfft},)")
    return w


def _thread_count(workers: int | None) -> int:
    """Threads for ``workers`` as in scipy.fft: None -> 1, -1 -> every CPU, n -> n."""
    if workers is None:
        return 1
    if workers < 0:
        return max(1, (os.cpu_count() or 1) + 1 + workers)
    return max(1, workers)


def _segment_means(rows: np.ndarray, view: np.ndarray, step: int) -> np.ndarray:
    """Mean of every segment [ch, seg, 1]: from (pairwise) sums of ``step``-sample pieces, each sample
    read once, when a segment is a whole number of pieces, else directly."""
    nfft = view.shape[-1]
    if nfft % step:
        return view.mean(axis=-1, keepdims=True)
    pieces = rows.reshape(rows.shape[0], -1, step).sum(axis=-1)   # not BLAS: its threads would spin
    cum = np.zeros((rows.shape[0], pieces.shape[1] + 1))
    np.cumsum(pieces, axis=1, out=cum[:, 1:])
    k = nfft // step
    return ((cum[:, k:] - cum[:, :-k]) / nfft)[..., None].astype(rows.dtype)


def _welch_sums(samples: np.ndarray, cols, windows: np.ndarray, n_in: int, step: int, n_seg: int,
                starts: Sequence[int], block: int, detrend: bool):
    """Sums over the segments of the blocks starting at segment indices ``starts`` (``block`` segments
    each): per block, a channel-major copy of the block's samples (transposed in cache-sized tiles),
    the mean-removed windowed segments from a strided view of it, one real FFT over every segment and
    channel, and the products."""
    n_ch, nfft = windows.shape
    n_freq = nfft // 2 + 1
    g_xf = np.zeros((n_ch - n_in, n_in, n_freq), complex)
    g_ff = np.zeros((n_in, n_in, n_freq), complex)
    g_xx = np.zeros((n_ch - n_in, n_freq))
    rows = np.empty((n_ch, (block - 1) * step + nfft), windows.dtype)
    buf = np.empty((n_ch, block, nfft), windows.dtype)
    work = np.empty((n_ch - n_in, block, n_freq), np.result_type(windows.dtype, np.complex64))
    for s0 in starts:
        b = min(block, n_seg - s0)
        length = (b - 1) * step + nfft
        for t0 in range(0, length, _TILE):
            t1 = min(length, t0 + _TILE)
            rows[:, t0:t1] = samples[s0 * step + t0:s0 * step + t1, cols].T
        view = np.lib.stride_tricks.sliding_window_view(rows[:, :length], nfft, axis=1)[:, ::step]
        seg = buf[:, :b]
        if detrend:
            np.subtract(view, _segment_means(rows[:, :length], view, step), out=seg)
            seg *= windows[:, None, :]
        else:
            np.multiply(view, windows[:, None, :], out=seg)
        a, c, d = _products(scipy.fft.rfft(seg, axis=-1), n_in, None, work)
        g_xf += a
        g_ff += c
        g_xx += d
    return g_xf, g_ff, g_xx


def welch_spectra(samples: np.ndarray, sample_rate_hz: float, inputs: Sequence[int],
                  outputs: Sequence[int], nfft: int, *, overlap: float = 0.5,
                  window_spec: str | np.ndarray = "hann", input_window_spec: str | np.ndarray | None = None,
                  detrend: bool = True,
                  workers: int | None = None) -> Spectra:
    """Welch-averaged spectra of ``samples`` [n_samples, n_channels] (columns ``inputs`` are references).

    Segments of ``nfft`` samples advance by ``nfft - round(overlap * nfft)``; each segment loses its
    mean (``detrend``) and is multiplied by its window (``input_window_spec`` on the inputs if given);
    a window is a spec string (:mod:`modal.windows`) or an array of ``nfft`` samples.  Blocks of
    segments are shared out to ``workers`` threads (as in scipy.fft: None one, -1 every CPU), each
    with its own sums; the sums are added in a fixed order, so the result does not depend on timing.
    """
    n_samples = samples.shape[0]
    if nfft < 8:
        raise ModalError(f"nfft {nfft}: must be at least 8")
    if n_samples < nfft:
        raise ModalError(f"record of {n_samples} samples is shorter than one segment (nfft {nfft})")
    if not 0.0 <= overlap < 1.0:
        raise ModalError(f"overlap {overlap}: must be in [0, 1)")
    step = nfft - int(round(overlap * nfft))
    chans = [int(c) for c in inputs] + [int(c) for c in outputs]
    n_in = len(inputs)
    contiguous = chans == list(range(chans[0], chans[0] + len(chans)))
    cols = slice(chans[0], chans[0] + len(chans)) if contiguous else chans
    dtype = np.float32 if samples.dtype == np.float32 else np.float64
    w_out = _window_array(window_spec, nfft)
    w_in = w_out if input_window_spec is None else _window_array(input_window_spec, nfft)
    windows = np.vstack([np.repeat(w_in[None], n_in, 0),
                         np.repeat(w_out[None], len(outputs), 0)]).astype(dtype)
    n_seg = (n_samples - nfft) // step + 1
    block = max(1, min(n_seg, _BLOCK_BYTES // (len(chans) * nfft * np.dtype(dtype).itemsize)))
    starts = range(0, n_seg, block)
    n_threads = min(_thread_count(workers), len(starts))
    parts = [starts[k::n_threads] for k in range(n_threads)]

    def run(part):
        return _welch_sums(samples, cols, windows, n_in, step, n_seg, part, block, detrend)

    if n_threads == 1:
        sums = [run(parts[0])]
    else:
        with ThreadPoolExecutor(n_threads) as pool:
            sums = list(pool.map(run, parts))
    g_xf, g_ff, g_xx = (sum(s[k] for s in sums) for k in range(3))
    scale = density_scale(g_xx.shape[-1], nfft, sample_rate_hz, w_out) / n_seg
    return Spectra(np.fft.rfftfreq(nfft, 1.0 / sample_rate_hz), g_xf * scale, g_ff * scale,
                   g_xx * scale, n_seg)
