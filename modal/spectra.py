"""Averaged auto- and cross-spectra of all channels in one FFT pass: the one Welch engine of flexmodal
(Welch 1967; Bendat & Piersol 2010 §11), behind FRFs (:mod:`flexmodal.modal.compute`), impact hits
(:mod:`flexmodal.modal.impact`) and the output cross-spectral matrix of FDD and of the SSI display
(:mod:`flexmodal.modal.fdd`).

Conventions: ``g_xf[o, i] = E[X_o conj(F_i)]``, ``g_ff[i, j] = E[F_i conj(F_j)]``, ``g_xx[o] = E[|X_o|^2]``,
one-sided densities scaled like ``scipy.signal.csd(..., scaling="density")`` (units^2/Hz).  One gap rule:
a segment holding a NaN/inf sample in a used channel, or touching a skipped interval, is left out.

One pass per block of segments, on a block in cache: the samples, row-major as stored, less the
block's first sample (so a large offset never reaches a single-precision FFT) from a strided view
(segments overlap in memory; no transpose, no float64 copy of float32 data), their sums (each
segment's mean, and the only check for NaN/inf samples), the window, one real FFT along the sample
axis with ``scipy.fft.rfft`` (float32 records in single precision), each segment's mean times the
window's spectrum taken out of the first lines of its transform (windows with a long spectrum: the
mean taken out before windowing), then the cross-spectra against the references as one batched
matrix product over the segment axis (``[f, channel, segment] @ [f, segment, reference]``) and the
auto-spectra as one reduction; block sums are accumulated in double precision, in segment order.
"""

from __future__ import annotations

import collections
import contextlib
import os
import queue
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.fft

from flexmodal.modal.errors import ModalError
from flexmodal.modal.windows import window

_BLOCK_BYTES = 4 << 20      # windowed segments per block (with its spectra, stays in the L3 cache)
_READ_BYTES = 16 << 20      # samples read per block from a dataset on disk (rounded to whole chunks)
DEFAULT_NFFT_MAX = 8192
MAX_SEGMENT_ENERGY = 1e280  # a segment's sum of |X|^2 above this: its spectral products overflow
MIN_STEP_FRACTION = 1 / 64  # Welch segments closer than nfft/64 (overlap > 98.4 %) add no new data, only work


def default_nfft(n_samples: int) -> int:
    """The one nfft policy of every Welch spectrum (FRFs, FDD, the SSI display): the largest power of
    two giving at least 8 half-overlapping segments of ``n_samples``, at most 8192, at least 64.

    Examples
    --------
    >>> default_nfft(30720), default_nfft(10 ** 7), default_nfft(100)
    (4096, 8192, 64)
    """
    n = 64
    while n * 2 <= min(DEFAULT_NFFT_MAX, n_samples // 4):
        n *= 2
    return n


def rfftfreq(nfft: int, sample_rate_hz: float) -> np.ndarray:
    """Frequencies (Hz) of the ``nfft // 2 + 1`` lines of a real FFT, as ``numpy.fft.rfftfreq(nfft,
    1 / sample_rate_hz)`` computes them (the same values)."""
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


def _products(spec: np.ndarray, refs: Sequence[int], weights: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
    """(Weighted) sums over segments of the spectral products of one block ``spec`` [seg, f, ch]:
    ``g`` [f, ch, ref] = sum X_ch conj(X_ref), one batched matrix product over the segment axis, and
    ``auto`` [f, ch] = sum |X_ch|^2, one reduction over the real view (no complex temporaries)."""
    refs = list(refs)
    ref = (spec[:, :, refs[0]:refs[-1] + 1] if refs == list(range(refs[0], refs[-1] + 1))
           else spec[:, :, refs]).conj()
    if weights is not None:
        ref *= weights[:, None, None]
    g = np.matmul(spec.transpose(1, 2, 0), ref.transpose(1, 0, 2))
    v = spec.view(spec.real.dtype).reshape(spec.shape[0], -1)      # re, im interleaved
    sq = np.einsum("sk,sk->k", v, v) if weights is None else np.einsum("s,sk,sk->k", weights, v, v)
    return g, (sq[0::2] + sq[1::2]).reshape(spec.shape[1:])


def _spectra(g: np.ndarray, auto: np.ndarray, n_in: int, scale: np.ndarray, freq_hz: np.ndarray,
             n_averages: int, n_skipped: int = 0, mean: np.ndarray | None = None) -> Spectra:
    """Spectra of the sums ``g`` [f, ch, n_in] and ``auto`` [f, ch] whose channels are the inputs
    then the outputs, scaled by ``scale`` [f]."""
    g_xf = np.moveaxis(g[:, n_in:], 0, -1) * scale
    g_ff = np.moveaxis(g[:, :n_in], 0, -1) * scale
    return Spectra(freq_hz, g_xf, g_ff, auto[:, n_in:].T * scale, n_averages, n_skipped, mean)


def spectra_of_segments(segments: np.ndarray, n_in: int, sample_rate_hz: float,
                        scale_window: np.ndarray, weights: np.ndarray | None = None) -> Spectra:
    """Spectra from already windowed segments [n_seg, n_ch, nfft] (inputs first), e.g. impact hits.

    ``weights`` [n_seg] (summing to 1) gives a weighted average (linear: equal; exponential: decaying).
    """
    nfft = segments.shape[-1]
    spec = scipy.fft.rfft(np.swapaxes(segments, 1, 2), axis=1)                 # [seg, f, ch]
    w = None if weights is None else np.asarray(weights, float)
    g, auto = _products(spec, range(n_in), w)
    norm = 1.0 if w is not None else 1.0 / segments.shape[0]
    scale = density_scale(spec.shape[1], nfft, sample_rate_hz, scale_window) * norm
    return _spectra(g, auto, n_in, scale, rfftfreq(nfft, sample_rate_hz), segments.shape[0])


def _window_array(spec: str | np.ndarray, nfft: int) -> np.ndarray:
    if isinstance(spec, str):
        return window(spec, nfft)
    w = np.asarray(spec, float)
    if w.shape != (nfft,):
        raise ModalError(f"window array of shape {w.shape}: expected ({nfft},)")
    return w


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask, e.g. ``taskset -c 0``; else every CPU)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):   # not Linux
        return os.cpu_count() or 1


def _thread_count(workers: int | None) -> int:
    """Threads for ``workers`` as in scipy.fft: None -> 1, -1 -> every usable CPU, n -> n."""
    if workers is None:
        return 1
    if workers < 0:
        return max(1, usable_cpus() + 1 + workers)
    return max(1, workers)


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
    """The first k lines [k, n_ch] of the real FFT of every channel's window as used (``windows``
    [n_ch, nfft], possibly rounded to single precision), all a segment's mean times the window puts
    into its transform, when the exact windows' spectra (``exact``, double) are zero to rounding
    beyond them (|W| <= 64 eps sum|w|) and k <= _MAX_WINDOW_LINES: the periodic cosine windows
    (rect 1 line, hann 2, flattop 5); None for any other window.  The lines left out of a
    single-precision window are its rounding, ~1e-9 of sum|w|, below the FFT's own."""
    big = np.abs(np.fft.rfft(exact)) > 64 * np.finfo(float).eps * np.abs(exact).sum(axis=1, keepdims=True)
    k = int(np.flatnonzero(big.any(axis=0))[-1]) + 1 if big.any() else 1
    if k > _MAX_WINDOW_LINES:
        return None
    return np.fft.rfft(windows.astype(float)).T[:k].astype(np.result_type(windows.dtype, np.complex64))


_SUM_LANES = 256     # samples of a segment summed apart, in the segment's precision, before double


def _segment_sums(seg: np.ndarray) -> np.ndarray:
    """Sums [n_seg, n_ch] over the samples of segments ``seg`` [n_seg, nfft, n_ch]: each of q lanes
    (q the largest divisor of nfft up to _SUM_LANES) adds every q-th sample in the segment's own
    precision, a vectorised pass over whole rows of the contiguous segments (nfft / q terms each:
    16 for nfft 4096), the lanes are then added in double precision; NaN/inf where a segment holds a
    non-finite sample (this is also the pass that finds them)."""
    n_seg, nfft, n_ch = seg.shape
    q = next(d for d in range(min(nfft, _SUM_LANES), 0, -1) if nfft % d == 0)
    lanes = np.add.reduce(seg.reshape(n_seg, nfft // q, q * n_ch), axis=1)        # [n_seg, q * n_ch]
    return np.matmul(np.ones(q), lanes.reshape(n_seg, q, n_ch).astype(float))


class _Work:
    """One thread's windowed-segment buffer, sized for ``block`` segments of every column."""

    def __init__(self, block: int, nfft: int, n_cols: int, dtype) -> None:
        self.seg = np.empty((block, nfft * n_cols), dtype)


@dataclass(frozen=True)
class _Plan:
    """What every block needs: segment length and step, the flat window [nfft * n_cols] of every
    column (row-major, as the samples), the columns ``cols`` transformed (a slice of the record's),
    the positions ``refs`` of the inputs and ``used`` of every used channel among them, whether
    segment means are removed (``detrend``) and the window lines a unit mean puts into each transform
    [k, n transformed] (None: the means are removed before windowing), the skipped segments, FFT
    threads per block."""

    nfft: int
    step: int
    flat_window: np.ndarray
    cols: slice
    refs: list[int]
    used: list[int]
    detrend: bool
    lines: np.ndarray | None
    skipped: np.ndarray
    fft_workers: int

    def sums(self, work: _Work, rows: np.ndarray, first: int, b: int) -> tuple:
        """(g, auto, sum of segment means, segments used) of segments ``first`` .. ``first + b - 1``
        over the transformed columns, whose samples are ``rows`` [(b - 1) * step + nfft, n_cols],
        row-major: the segments less the block's first sample from a strided view of them (no
        transpose; the offset kept out of single-precision transforms), their sums (the means, and
        the check for non-finite samples), the window, one real FFT along the sample axis, each
        segment's mean times the window's spectrum taken out of the transform (the FFT is linear:
        the same as removing it before windowing), segments holding a non-finite sample, whose
        spectral energy in a used channel exceeds :data:`MAX_SEGMENT_ENERGY` (their products would
        overflow: values near 1e300) or marked skipped zeroed and not counted."""
        n_cols = rows.shape[1]
        isz = rows.itemsize
        seg = work.seg[:b]
        view = np.ndarray((b, self.nfft * n_cols), rows.dtype, rows, strides=(self.step * n_cols * isz, isz))
        offset = np.where(np.isfinite(rows[0]), rows[0], 0)   # the block's first sample: exact to subtract
        with np.errstate(invalid="ignore", over="ignore"):
            np.subtract(view, np.tile(offset, self.nfft), out=seg)
            means = _segment_sums(seg.reshape(b, self.nfft, n_cols)) / self.nfft          # [b, n_cols]
            if self.detrend and self.lines is None:     # a long window spectrum: remove before windowing
                for k in range(b):    # a loop over the block's segments, each a flat pass
                    seg[k] -= np.tile(means[k].astype(seg.dtype), self.nfft)
            np.multiply(seg, self.flat_window, out=seg)
            spec = scipy.fft.rfft(seg.reshape(b, self.nfft, n_cols)[:, :, self.cols], axis=1,
                                  workers=self.fft_workers)                         # [b, f, cols]
        means = means[:, self.cols]
        parts = spec.view(spec.real.dtype)                          # [b, f, re/im of each column]
        squares = np.einsum("sfk,sfk->sk", parts, parts, dtype=float)   # inf, not a warning, on overflow
        energy = (squares[:, 0::2] + squares[:, 1::2])[:, self.used].max(axis=1)
        bad = self.skipped[first:first + b] | ~np.isfinite(means[:, self.used]).all(axis=1) \
            | ~(energy <= MAX_SEGMENT_ENERGY)   # NaN/inf, or values whose products overflow
        if bad.any():
            means[bad] = 0
            spec[bad] = 0
        if self.detrend and self.lines is not None:
            k = self.lines.shape[0]
            spec[:, :k] -= means[:, None, :].astype(spec.real.dtype) * self.lines
        used = b - int(bad.sum())
        g, auto = _products(spec, self.refs)    # in double here, so the ordered sums are plain adds
        mean_sum = means.sum(axis=0) + offset[self.cols].astype(float) * used
        return g.astype(complex), auto.astype(float), mean_sum, used


def _read_rows(samples, first: int, dest: np.ndarray) -> None:
    """Rows ``first`` .. ``first + len(dest) - 1`` of ``samples`` into ``dest`` (a row-major view of a
    reused buffer): an HDF5 dataset (h5py) reads straight into it, converting to its dtype; any
    other array-like is sliced and copied."""
    if hasattr(samples, "read_direct"):
        samples.read_direct(dest, np.s_[first:first + dest.shape[0]])
    else:
        dest[...] = samples[first:first + dest.shape[0]]


_BUFFERS = 3      # reused read buffers: one being filled, one being transformed, one still in use


def _row_blocks(samples, rows_per_read: int, keep: int, dtype) -> Iterator[tuple[int, np.ndarray]]:
    """(first row, rows [n, n_columns] as a row-major ``dtype`` array) blocks of ``samples``: an
    in-memory array that is one already as one block (no copy, no thread); else ``rows_per_read``
    rows at a time read (an on-disk dataset, h5py) or converted one block ahead in a background
    thread, so reading overlaps the FFTs, into _BUFFERS buffers allocated once (no fresh memory,
    hence no page faults, per read).  Each block also holds the ``keep`` rows before its read
    (copied from the previous block), so any ``keep + 1`` consecutive rows lie whole in the first
    block that reaches their end.  A block's rows stay valid until the block after the next one is
    asked for."""
    if isinstance(samples, np.ndarray) and samples.dtype == dtype and samples.flags.c_contiguous:
        yield 0, samples
        return
    n, n_cols = samples.shape
    buffers = [np.empty((min(n, keep + rows_per_read), n_cols), dtype) for _ in range(_BUFFERS)]
    free: queue.SimpleQueue = queue.SimpleQueue()
    for k in range(_BUFFERS):
        free.put(k)
    ready: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()

    def read() -> None:
        try:
            prev, prev_start = 0, 0
            for r in range(0, n, rows_per_read):
                k = free.get()
                if stop.is_set():
                    return
                start = max(0, r - keep)
                buf = buffers[k]
                buf[:r - start] = buffers[prev][start - prev_start:r - prev_start]
                count = min(rows_per_read, n - r)
                _read_rows(samples, r, buf[r - start:r - start + count])
                ready.put((start, buf[:r - start + count], k))
                prev, prev_start = k, start
            ready.put(None)
        except BaseException as exc:  # handed to the consumer, raised there
            ready.put(exc)

    reader = threading.Thread(target=read, name="flexmodal-read", daemon=True)
    reader.start()
    held: collections.deque = collections.deque()
    try:
        while (item := ready.get()) is not None:
            if isinstance(item, BaseException):
                raise item
            start, rows, k = item
            held.append(k)
            if len(held) > 2:               # the block before the previous one: free for the reader
                free.put(held.popleft())
            yield start, rows
    finally:
        stop.set()
        free.put(0)                         # wakes a reader waiting for a buffer: it sees stop
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
    a window is a spec string (:mod:`modal.windows`) or an array of ``nfft`` samples.  A column may be
    both an input and an output (FDD's references).  Segments holding a NaN/inf sample in any used
    channel (or values whose spectral products overflow, :data:`MAX_SEGMENT_ENERGY`), or touching one
    of the ``skip`` sample intervals (first sample, count), are left out of
    the average (``n_skipped``); fewer than ``min_segments`` left is an error.  Segments are processed
    in blocks at fixed segment indices, shared out to ``workers`` threads (as in scipy.fft: None one,
    -1 every CPU); the block sums are added in segment order, so the result is the same for any thread
    count, timing or read block size.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).standard_normal((4096, 2))
    >>> s = welch_spectra(x, 100.0, [0], [1], 256)
    >>> s.g_xf.shape, s.g_ff.shape, s.g_xx.shape, s.n_averages
    ((1, 1, 129), (1, 1, 129), (1, 129), 31)
    """
    n_samples = samples.shape[0]
    if nfft < 8:
        raise ModalError(f"nfft {nfft}: must be at least 8")
    if n_samples < nfft:
        raise ModalError(f"record of {n_samples} samples is shorter than one segment (nfft {nfft})")
    if not 0.0 <= overlap < 1.0:
        raise ModalError(f"overlap {overlap}: must be in [0, 1)")
    step = nfft - int(round(overlap * nfft))
    if step < max(1.0, nfft * MIN_STEP_FRACTION):
        raise ModalError(f"overlap {overlap:g} leaves segments of nfft {nfft} only {step} samples apart: at "
                         f"most {1 - MIN_STEP_FRACTION:g} (a step of nfft/{round(1 / MIN_STEP_FRACTION)} or "
                         "more; closer segments add no new data, only work)")
    n_in = len(inputs)
    chans = [int(c) for c in inputs] + [int(c) for c in outputs]
    lo, hi = min(chans), max(chans) + 1
    n_cols = samples.shape[1]
    dtype = np.dtype(np.float32 if samples.dtype == np.float32 else np.float64)
    w_out = _window_array(window_spec, nfft)
    w_in = w_out if input_window_spec is None else _window_array(input_window_spec, nfft)
    exact = np.repeat(w_out[None], n_cols, 0)
    exact[chans[:n_in]] = w_in
    windows = exact.astype(dtype)
    n_seg = (n_samples - nfft) // step + 1
    block = max(1, min(n_seg, _BLOCK_BYTES // (n_cols * nfft * dtype.itemsize)))
    n_blocks = -(-n_seg // block)
    n_threads = min(_thread_count(workers), n_blocks)
    plan = _Plan(nfft, step, np.ascontiguousarray(windows.T).ravel(), slice(lo, hi), [c - lo for c in inputs],
                 sorted({c - lo for c in chans}), detrend, _window_lines(exact[lo:hi], windows[lo:hi]),
                 skipped_segments(skip, n_seg, nfft, step), max(1, _thread_count(workers) // n_threads))
    chunk = (getattr(samples, "chunks", None) or (1,))[0]
    row_bytes = n_cols * dtype.itemsize
    read_rows = max((block - 1) * step + nfft, _READ_BYTES // row_bytes)
    read_rows = -(-read_rows // chunk) * chunk                       # whole storage chunks
    free: queue.SimpleQueue = queue.SimpleQueue()      # one set of work buffers per thread
    for _ in range(n_threads):
        free.put(_Work(block, nfft, n_cols, dtype))
    n_freq = nfft // 2 + 1
    total = [np.zeros((n_freq, hi - lo, n_in), complex), np.zeros((n_freq, hi - lo)), np.zeros(hi - lo), 0]
    pool = ThreadPoolExecutor(n_threads) if n_threads > 1 else None
    pending: collections.deque = collections.deque()

    def run(j: int, rows: np.ndarray) -> tuple:
        work = free.get()                   # whichever thread is free takes the next block
        try:
            return plan.sums(work, rows, j * block, min(block, n_seg - j * block))
        finally:
            free.put(work)

    def submit(j: int, rows: np.ndarray) -> None:
        if pool is None:
            add(run(j, rows))
            return
        pending.append(pool.submit(run, j, rows))  # blocks of the next read start while these finish
        while len(pending) > 2 * n_threads:
            add(pending.popleft().result())

    def add(part: tuple) -> None:           # block sums added in segment order, whatever the threads
        for k, value in enumerate(part):
            total[k] += value

    def span(j: int) -> tuple[int, int]:    # rows of segment block j
        return j * block * step, (j * block + min(block, n_seg - j * block) - 1) * step + nfft

    j = 0              # segment blocks submitted (those not in ``pending`` are added)
    reads = contextlib.closing(_row_blocks(samples, read_rows, span(0)[1] - 1, dtype))
    try:   # each read holds the rows of one block before it: every segment block lies whole in one
        with reads as blocks:       # closed on any way out: the reader thread has ended
            for r0, rows in blocks:
                earlier = j
                end = r0 + rows.shape[0]
                while j < n_blocks and span(j)[1] <= end:
                    first, last = span(j)
                    submit(j, rows[first - r0:last - r0])
                    j += 1
                while j - len(pending) < earlier:   # the earlier reads' blocks added: asking for the
                    add(pending.popleft().result())  # next read lets the reader reuse the one before
        while pending:
            add(pending.popleft().result())
    finally:
        if pool is not None:
            for fut in pending:
                fut.cancel()
            pool.shutdown()
    g, auto, mean_sum, n_used = total
    if n_used < min_segments:
        raise ModalError(f"only {n_used} of {n_seg} segments usable (NaN/inf samples or skipped "
                         f"intervals in the others); at least {min_segments} needed")
    scale = density_scale(n_freq, nfft, sample_rate_hz, w_out) / max(n_used, 1)
    pos = [c - lo for c in chans]                       # inputs then outputs among the transformed
    mean = mean_sum[pos] / max(n_used, 1)
    return _spectra(g[:, pos], auto[:, pos], n_in, scale, rfftfreq(nfft, sample_rate_hz), n_used,
                    n_seg - n_used, mean)
