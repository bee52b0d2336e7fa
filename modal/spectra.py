"""Averaged auto- and cross-spectra of all channels in one FFT pass (Welch 1967; Bendat & Piersol 2010 §11).

Conventions: ``g_xf[o, i] = E[X_o conj(F_i)]``, ``g_ff[i, j] = E[F_i conj(F_j)]``, ``g_xx[o] = E[|X_o|^2]``,
one-sided densities scaled like ``scipy.signal.csd(..., scaling="density")`` (units^2/Hz).  Segments are
processed in blocks small enough to stay in cache: per block one real FFT over every segment and
channel, then the products for all channel pairs at once; no loop over frequency lines or pairs.
float32 records are transformed in single precision and accumulated in double precision.
"""

from __future__ import annotations

import collections
import functools
import os
import queue
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from flexmodal.modal.errors import ModalError
from flexmodal.modal.windows import window

_BLOCK_BYTES = 8 << 20      # windowed segments per block (with its spectra, fits the shared L3 cache)
_READ_BYTES = 16 << 20      # samples read per block from a dataset on disk (rounded to whole chunks)
_TILE = 2048                # rows per tile of the block transpose (stays in L1/L2)


@functools.cache
def _pocketfft():
    """scipy's pocketfft extension, the engine of ``scipy.fft.rfft``, loaded by itself: importing
    ``scipy.fft`` costs 0.7-0.9 s (its array-API layers and scipy.special), the extension < 1 ms.
    It is registered under its own name, so a later ``import scipy.fft`` shares it."""
    import importlib.util
    import sys

    name = "scipy.fft._pocketfft.pypocketfft"
    if name in sys.modules:
        return sys.modules[name]
    try:
        spec = importlib.util.find_spec("scipy")
        folder = os.path.join(os.path.dirname(spec.origin), "fft", "_pocketfft")
        file = next(f for f in os.listdir(folder) if f.startswith("pypocketfft."))
        spec = importlib.util.spec_from_file_location(name, os.path.join(folder, file))
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        module.r2c                                         # noqa: B018 - the function used below
    except (ImportError, OSError, StopIteration, AttributeError, TypeError):
        import scipy.fft._pocketfft.pypocketfft as module  # the ordinary (slower) import
        return module
    sys.modules[name] = module
    return module


def rfft(x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Real FFT along the last axis (unnormalised, as ``scipy.fft.rfft``), single precision for
    float32 input; into ``out`` when given (complex, last axis ``n // 2 + 1``)."""
    return _pocketfft().r2c(x, axes=[x.ndim - 1], forward=True, inorm=0, out=out, nthreads=1)


def rfftfreq(nfft: int, sample_rate_hz: float) -> np.ndarray:
    """Frequencies (Hz) of the ``nfft // 2 + 1`` lines of a real FFT, computed as
    ``numpy.fft.rfftfreq(nfft, 1 / sample_rate_hz)`` does (same values) without importing numpy.fft."""
    return np.arange(nfft // 2 + 1) * (1.0 / (nfft * (1.0 / sample_rate_hz)))


@dataclass(frozen=True)
class Spectra:
    """Averaged one-sided spectra: ``freq_hz`` [n_freq], ``g_xf`` [n_out, n_in, n_freq],
    ``g_ff`` [n_in, n_in, n_freq], ``g_xx`` [n_out, n_freq] (real), ``n_averages`` segments or hits
    used, ``n_skipped`` segments left out (NaN rows, gaps), ``mean`` [n_in + n_out] the mean of every
    channel over the used segments (Welch only; inputs first)."""

    freq_hz: np.ndarray
    g_xf: np.ndarray
    g_ff: np.ndarray
    g_xx: np.ndarray
    n_averages: int
    n_skipped: int = 0
    mean: np.ndarray | None = None


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
    x = rfft(np.moveaxis(segments, 1, 0))
    w = None if weights is None else np.asarray(weights, float)
    g_xf, g_ff, g_xx = _products(x, n_in, w)
    norm = 1.0 if w is not None else 1.0 / segments.shape[0]
    scale = density_scale(x.shape[-1], nfft, sample_rate_hz, scale_window) * norm
    return Spectra(rfftfreq(nfft, sample_rate_hz), g_xf * scale, g_ff * scale,
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
    """Mean of every segment [ch, seg, 1], NaN for a segment holding a non-finite sample: from
    (pairwise) sums of ``step``-sample pieces, each sample read once, when a segment is a whole number
    of pieces, else directly.  This is also the pass that finds NaN/inf samples."""
    nfft = view.shape[-1]
    if nfft % step:
        with np.errstate(invalid="ignore", over="ignore"):
            return view.mean(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", over="ignore"):
        pieces = rows.reshape(rows.shape[0], -1, step).sum(axis=-1)   # not BLAS: its threads would spin
    bad = ~np.isfinite(pieces)
    if bad.any():
        pieces[bad] = 0
    cum = np.zeros((rows.shape[0], pieces.shape[1] + 1))
    np.cumsum(pieces, axis=1, out=cum[:, 1:])
    k = nfft // step
    means = (cum[:, k:] - cum[:, :-k]) / nfft
    if bad.any():
        n_bad = np.concatenate([[0], np.cumsum(bad.any(axis=0))])
        means[:, n_bad[k:] > n_bad[:-k]] = np.nan
    return means[..., None].astype(rows.dtype)


def skipped_segments(intervals: Sequence[tuple[int, int]], n_seg: int, nfft: int, step: int) -> np.ndarray:
    """Segments [n_seg] (segment k covers samples k*step .. k*step+nfft-1) that touch any of the sample
    ``intervals`` (first sample, number of samples >= 1), e.g. gap or corrupt events of a run."""
    marks = np.zeros(n_seg + 1, np.int64)
    if len(intervals):
        first, count = np.asarray(intervals, np.int64).reshape(-1, 2).T
        last = first + np.maximum(count, 1) - 1
        lo = np.clip(-((nfft - 1 - first) // step), 0, n_seg)      # ceil((first - nfft + 1) / step)
        hi = np.clip(last // step + 1, 0, n_seg)
        np.add.at(marks, lo, 1)
        np.add.at(marks, hi, -1)
    return np.cumsum(marks[:-1]) > 0


_MAX_WINDOW_LINES = 8      # a window whose spectrum has more lines is detrended before windowing


def _window_lines(exact: np.ndarray, windows: np.ndarray) -> np.ndarray | None:
    """The first k lines [n_ch, k] of the real FFT of every channel's window as used (``windows``,
    possibly rounded to single precision) when the exact windows' spectra (``exact``, double) are
    zero to rounding beyond them (|W| <= 64 eps sum|w|) and k <= _MAX_WINDOW_LINES: the periodic
    cosine windows (rect 1 line, hann 2, flattop 5); None for any other window.  The lines left out
    of a single-precision window are its rounding, ~1e-9 of sum|w|, below the FFT's own."""
    big = np.abs(rfft(exact)) > 64 * np.finfo(float).eps * np.abs(exact).sum(axis=1, keepdims=True)
    k = int(np.flatnonzero(big.any(axis=0))[-1]) + 1 if big.any() else 1
    if k > _MAX_WINDOW_LINES:
        return None
    return rfft(windows.astype(float))[:, :k].astype(np.result_type(windows.dtype, np.complex64))


class _Work:
    """One thread's work buffers, sized for ``block`` segments."""

    def __init__(self, windows: np.ndarray, n_in: int, step: int, block: int) -> None:
        n_ch, nfft = windows.shape
        n_freq = nfft // 2 + 1
        real, cplx = np.dtype(windows.dtype), np.result_type(windows.dtype, np.complex64)
        self.rows = np.empty((n_ch, (block - 1) * step + nfft), real)
        self.spec = np.empty((n_ch, block, n_freq), cplx)
        # the windowed segments are dead once transformed: the products reuse their memory
        seg_bytes = n_ch * block * nfft * real.itemsize
        work_bytes = (n_ch - n_in) * block * n_freq * cplx.itemsize
        shared = np.empty(max(seg_bytes, work_bytes), np.uint8)
        self.buf = shared[:seg_bytes].view(real).reshape(n_ch, block, nfft)
        self.work = shared[:work_bytes].view(cplx).reshape(n_ch - n_in, block, n_freq)

    def sums(self, sources, cols, windows: np.ndarray, n_in: int, step: int, first: int, b: int,
             skip: np.ndarray, detrend: bool, lines: np.ndarray | None) -> tuple:
        """(g_xf, g_ff, g_xx, sum of segment means, segments used) over segments ``first`` ..
        ``first + b - 1``: a channel-major copy of their samples less the block's first sample (from
        the row-major ``sources`` pieces, transposed in cache-sized tiles), the windowed segments
        from a strided view of it, one real FFT over every segment and channel, the products.
        Each segment's mean is removed (``detrend``): where the windows' spectra ``lines`` are given
        (their first lines, the rest zero to rounding, as for the cosine windows), by subtracting
        mean x spectrum of the window from those lines of the transform (the FFT is linear: the same
        as removing it before windowing, without a pass over the segments), else before windowing.
        Removing the block's first sample first keeps a large offset out of the single-precision
        FFT.  Segments holding a non-finite sample or marked in ``skip`` are zeroed and not counted."""
        nfft = windows.shape[1]
        length = (b - 1) * step + nfft
        rows = self.rows[:, :length]
        g0 = first * step
        offset = np.zeros(rows.shape[0], rows.dtype)
        if detrend:
            start, arr = next((st, a) for st, a in sources if st <= g0 < st + a.shape[0])
            value = np.asarray(arr[g0 - start, cols], rows.dtype)
            offset[np.isfinite(value)] = value[np.isfinite(value)]
        for start, arr in sources:
            lo, hi = max(g0, start), min(g0 + length, start + arr.shape[0])
            for t0 in range(lo, hi, _TILE):
                t1 = min(hi, t0 + _TILE)
                np.subtract(arr[t0 - start:t1 - start, cols].T, offset[:, None], out=rows[:, t0 - g0:t1 - g0])
        view = np.lib.stride_tricks.sliding_window_view(rows, nfft, axis=1)[:, ::step]
        means = _segment_means(rows, view, step)
        bad = skip[first:first + b] | ~np.isfinite(means[:, :, 0]).all(axis=0)
        seg = self.buf[:, :b]
        with np.errstate(invalid="ignore"):
            if detrend and lines is None:
                np.subtract(view, means, out=seg)
                seg *= windows[:, None, :]
            else:
                np.multiply(view, windows[:, None, :], out=seg)
        if bad.any():
            seg[:, bad] = 0
        spec = rfft(seg, self.spec[:, :b])
        used = means[:, ~bad, 0].sum(axis=1, dtype=float) + offset.astype(float) * (b - int(bad.sum()))
        if detrend and lines is not None:
            means[:, bad] = 0
            spec[:, :, :lines.shape[1]] -= means * lines[:, None, :]
        a, c, d = _products(spec, n_in, None, self.work)
        return a, c, d, used, b - int(bad.sum())


def _row_blocks(samples, rows_per_block: int) -> Iterator[tuple[int, np.ndarray]]:
    """(first row, rows [n, n_channels]) blocks of ``samples``: views of an in-memory array, or for
    an on-disk dataset (h5py) reads done one block ahead in a background thread, so reading overlaps
    the FFTs; at most three blocks are held at a time."""
    n = samples.shape[0]
    if isinstance(samples, np.ndarray):
        for r in range(0, n, rows_per_block):
            yield r, samples[r:r + rows_per_block]
        return
    ready: queue.Queue = queue.Queue(maxsize=1)
    stop = threading.Event()

    def read() -> None:
        try:
            for r in range(0, n, rows_per_block):
                if stop.is_set():
                    return
                ready.put((r, samples[r:r + rows_per_block]))
            ready.put(None)
        except BaseException as exc:  # handed to the consumer, raised there
            ready.put(exc)

    reader = threading.Thread(target=read, name="flexmodal-read", daemon=True)
    reader.start()
    try:
        while (item := ready.get()) is not None:
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        while reader.is_alive():
            try:
                ready.get(timeout=0.05)
            except queue.Empty:
                pass
        reader.join()


def welch_spectra(samples, sample_rate_hz: float, inputs: Sequence[int],
                  outputs: Sequence[int], nfft: int, *, overlap: float = 0.5,
                  window_spec: str | np.ndarray = "hann", input_window_spec: str | np.ndarray | None = None,
                  detrend: bool = True, workers: int | None = None,
                  skip: Sequence[tuple[int, int]] = (), min_segments: int = 1) -> Spectra:
    """Welch-averaged spectra of ``samples`` [n_samples, n_channels] (columns ``inputs`` are references),
    an in-memory array or an on-disk dataset (h5py), streamed in blocks of whole storage chunks: memory
    stays a few blocks whatever the record length.

    Segments of ``nfft`` samples advance by ``nfft - round(overlap * nfft)``; each segment loses its
    mean (``detrend``) and is multiplied by its window (``input_window_spec`` on the inputs if given);
    a window is a spec string (:mod:`modal.windows`) or an array of ``nfft`` samples.  Segments holding
    a NaN/inf sample in any used channel, or touching one of the ``skip`` sample intervals (first
    sample, count), are left out of the average (``n_skipped``); fewer than ``min_segments`` left is an
    error.  Segments are processed in blocks at fixed segment indices, shared out to ``workers``
    threads (as in scipy.fft: None one, -1 every CPU); the block sums are added in segment order, so
    the result is the same for any thread count, timing or read block size.
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
    exact = np.vstack([np.repeat(w_in[None], n_in, 0), np.repeat(w_out[None], len(outputs), 0)])
    windows = exact.astype(dtype)
    n_seg = (n_samples - nfft) // step + 1
    skipped = skipped_segments(skip, n_seg, nfft, step)
    lines = _window_lines(exact, windows) if detrend else None
    block = max(1, min(n_seg, _BLOCK_BYTES // (len(chans) * nfft * np.dtype(dtype).itemsize)))
    chunk = (getattr(samples, "chunks", None) or (1,))[0]
    row_bytes = samples.shape[1] * np.dtype(samples.dtype).itemsize
    read_rows = max((block - 1) * step + nfft, _READ_BYTES // row_bytes)
    read_rows = -(-read_rows // chunk) * chunk                       # whole storage chunks
    n_threads = min(_thread_count(workers), -(-n_seg // block))
    free: queue.SimpleQueue = queue.SimpleQueue()      # one set of work buffers per thread
    for _ in range(n_threads):
        free.put(_Work(windows, n_in, step, block))
    n_ch, n_freq = len(chans), nfft // 2 + 1
    total = [np.zeros((n_ch - n_in, n_in, n_freq), complex), np.zeros((n_in, n_in, n_freq), complex),
             np.zeros((n_ch - n_in, n_freq)), np.zeros(n_ch), 0]
    pool = ThreadPoolExecutor(n_threads) if n_threads > 1 else None
    pending: collections.deque = collections.deque()

    def add(part: tuple) -> None:           # block sums added in segment order, whatever the threads
        for k, value in enumerate(part):
            total[k] += value

    done, tail_start, tail = 0, 0, None
    try:
        for r0, rows in _row_blocks(samples, read_rows):
            sources = [(tail_start, tail), (r0, rows)] if tail is not None else [(r0, rows)]
            ready = min(n_seg, (r0 + rows.shape[0] - nfft) // step + 1)   # segments complete by now
            jobs = [s0 for s0 in range(done, ready, block) if min(s0 + block, n_seg) <= ready]

            def run(s0: int, sources=sources) -> tuple:
                work = free.get()                   # whichever thread is free takes the next block
                try:
                    return work.sums(sources, cols, windows, n_in, step, s0, min(block, n_seg - s0),
                                     skipped, detrend, lines)
                finally:
                    free.put(work)

            if pool is None:
                for s0 in jobs:
                    add(run(s0))
            else:       # blocks of the next read start while these finish; at most 2 per thread queued
                pending.extend(pool.submit(run, s0) for s0 in jobs)
                while len(pending) > 2 * n_threads:
                    add(pending.popleft().result())
            if jobs:
                done = min(jobs[-1] + block, n_seg)
            start = done * step
            if start >= r0:
                tail_start, tail = start, rows[start - r0:]
            else:   # a read block shorter than the segment block still open: keep both
                tail = np.concatenate([tail[start - tail_start:], rows])
                tail_start = start
        while pending:
            add(pending.popleft().result())
    finally:
        if pool is not None:
            for fut in pending:
                fut.cancel()
            pool.shutdown()
    g_xf, g_ff, g_xx, mean_sum, n_used = total
    if n_used < min_segments:
        raise ModalError(f"only {n_used} of {n_seg} segments usable (NaN/inf samples or skipped "
                         f"intervals in the others); at least {min_segments} needed")
    scale = density_scale(g_xx.shape[-1], nfft, sample_rate_hz, w_out) / max(n_used, 1)
    return Spectra(rfftfreq(nfft, sample_rate_hz), g_xf * scale, g_ff * scale,
                   g_xx * scale, n_used, n_seg - n_used, mean_sum / max(n_used, 1))
