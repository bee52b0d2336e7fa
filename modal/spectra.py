"""Averaged auto- and cross-spectra of all channels in one FFT pass (Welch 1967; Bendat & Piersol 2010 §11).

Conventions: ``g_xf[o, i] = E[X_o conj(F_i)]``, ``g_ff[i, j] = E[F_i conj(F_j)]``, ``g_xx[o] = E[|X_o|^2]``,
one-sided densities scaled like ``scipy.signal.csd(..., scaling="density")`` (units^2/Hz).  Segments are
processed in blocks small enough to stay in cache: per block one real FFT over every segment and
channel, then the products for all channel pairs at once; no loop over frequency lines or pairs.
float32 records are transformed in single precision and accumulated in double precision.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.fft

from modal.errors import ModalError
from modal.windows import window

_BLOCK_BYTES = 2 << 20


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


def _products(x: np.ndarray, n_in: int, weights: np.ndarray | None):
    """(Weighted) sums over segments of the spectral products of one block ``x`` [ch, s, f] whose
    first ``n_in`` channels are the inputs: g_xf [o, i, f], g_ff [i, i, f], g_xx [o, f]."""
    f, y = x[:n_in], x[n_in:]
    wy = y if weights is None else y * weights[None, :, None].astype(y.real.dtype)
    if n_in == 1:
        g_xf = (wy * f[0].conj()).sum(axis=1)[:, None, :]
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


def welch_spectra(samples: np.ndarray, sample_rate_hz: float, inputs: Sequence[int],
                  outputs: Sequence[int], nfft: int, *, overlap: float = 0.5,
                  window_spec: str | np.ndarray = "hann", input_window_spec: str | np.ndarray | None = None,
                  detrend: bool = True,
                  workers: int | None = None) -> Spectra:
    """Welch-averaged spectra of ``samples`` [n_samples, n_channels] (columns ``inputs`` are references).

    Segments of ``nfft`` samples advance by ``nfft - round(overlap * nfft)``; each segment loses its
    mean (``detrend``) and is multiplied by its window (``input_window_spec`` on the inputs if given);
    a window is a spec string (:mod:`modal.windows`) or an array of ``nfft`` samples.
    """
    n_samples = samples.shape[0]
    if nfft < 8:
        raise ModalError(f"nfft {nfft}: must be at least 8")
    if n_samples < nfft:
        raise ModalError(f"record of {n_samples} samples is shorter than one segment (nfft {nfft})")
    if not 0.0 <= overlap < 1.0:
        raise ModalError(f"overlap {overlap}: must be in [0, 1)")
    step = nfft - int(round(overlap * nfft))
    chans = list(inputs) + list(outputs)
    n_in = len(inputs)
    dtype = np.float32 if samples.dtype == np.float32 else np.float64
    w_out = _window_array(window_spec, nfft)
    w_in = w_out if input_window_spec is None else _window_array(input_window_spec, nfft)
    w = np.vstack([np.repeat(w_in[None], n_in, 0), np.repeat(w_out[None], len(outputs), 0)]).astype(dtype)
    xt = np.empty((len(chans), n_samples), dtype)                  # channel-major copy, blocked transpose
    for t0 in range(0, n_samples, 1 << 16):
        xt[:, t0:t0 + (1 << 16)] = samples[t0:t0 + (1 << 16), chans].T
    view = np.lib.stride_tricks.sliding_window_view(xt, nfft, axis=1)[:, ::step]   # [ch, seg, nfft]
    n_seg = view.shape[1]
    block = max(1, _BLOCK_BYTES // (len(chans) * nfft * np.dtype(dtype).itemsize))
    buf = np.empty((len(chans), block, nfft), dtype)
    n_freq = nfft // 2 + 1
    g_xf = np.zeros((len(outputs), n_in, n_freq), complex)
    g_ff = np.zeros((n_in, n_in, n_freq), complex)
    g_xx = np.zeros((len(outputs), n_freq))
    for s0 in range(0, n_seg, block):
        blk = view[:, s0:s0 + block]
        seg = buf[:, :blk.shape[1]]
        if detrend:
            np.subtract(blk, blk.mean(axis=-1, keepdims=True), out=seg)
            seg *= w[:, None, :]
        else:
            np.multiply(blk, w[:, None, :], out=seg)
        x = scipy.fft.rfft(seg, axis=-1, workers=workers)
        a, b, c = _products(x, n_in, None)
        g_xf += a
        g_ff += b
        g_xx += c
    scale = density_scale(n_freq, nfft, sample_rate_hz, w_out) / n_seg
    return Spectra(np.fft.rfftfreq(nfft, 1.0 / sample_rate_hz), g_xf * scale, g_ff * scale,
                   g_xx * scale, n_seg)
