"""Sine-sweep (chirp) records: where each sweep starts, and the record cut into one segment per sweep.

A swept-sine FRF is leakage-free when each sweep is transformed whole with a rectangular window, the
response having died out by the end of its segment (Brandt 2011 §13.6: chirp excitation is analysed one
sweep per block, with no window; Ewins 2000 §3.9).  A record of several sweeps (repetitions, or one
sweep per drive pattern of a multi-input test) is cut at each sweep's start and the segments averaged
as in H1: one segment per sweep, not Welch blocks much shorter than a sweep, whose Hann window widens
the half-power band of a lightly damped mode and so biases its damping high.
"""

from __future__ import annotations

import numpy as np

BLOCKS = 64          # blocks the force record is cut into to follow the swept frequency
MIN_BLOCK = 128      # samples a block needs for its spectral peak to follow a sweep (64 lines)
ACTIVE = 0.05        # a block is driven when its energy is at least this share of the largest's


def _runs(track: np.ndarray) -> list[tuple[int, int]] | None:
    """(first, last) positions in ``track`` (the peak line of each driven block) of the sweeps: runs
    that rise monotonically (within one line) by at least four lines over at least four blocks, each
    ended by a drop of more than half the track's range (the next sweep restarting); None when the
    track is not made of such runs (random or impact forces)."""
    if track.size < 4:
        return None
    step = np.diff(track)
    reset = step < -max(1, (track.max() - track.min()) // 2)
    if np.any(step[~reset] < -1):
        return None
    edges = np.concatenate([[0], np.flatnonzero(reset) + 1, [track.size]])
    runs = [(int(a), int(b) - 1) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    if any(b - a < 3 or track[b] - track[a] < 4 for a, b in runs):
        return None
    return runs


def sweep_starts(forces: np.ndarray) -> np.ndarray | None:
    """Sample indices where the sweeps of a force record [n_samples, n_forces] start (the first is 0:
    a lead before the first sweep stays with it), or None when the record is not a sweep.

    The record is cut into up to 64 blocks of at least 128 samples; the peak of the Hann spectrum
    summed over the forces (so that drives in anti-phase do not cancel) follows the swept frequency
    through the driven blocks.  A sweep rises monotonically over at least four blocks and four
    lines; a fall by more than half the range starts the next one (down-sweeps are read reversed).
    The next sweep starts at its first driven block, or at the block before it when that one is
    quiet (a gap between sweeps: the cut then falls before the sweep's first sample, which may lie
    inside its first driven block).

    Examples
    --------
    Two 18 s sweeps 1-40 Hz, each followed by 2 s of silence (100 Hz sampling): the second starts at
    sample 2000, and the cut falls in the quiet gap before it.

    >>> from scipy.signal import chirp
    >>> one = np.concatenate([chirp(np.arange(1800) / 100.0, 1.0, 18.0, 40.0), np.zeros(200)])
    >>> starts = sweep_starts(np.concatenate([one, one])[:, None])
    >>> starts.tolist()[0], 1800 <= starts.tolist()[1] <= 2000
    (0, True)
    >>> sweep_starts(np.random.default_rng(0).standard_normal((4000, 1))) is None
    True
    """
    x = np.asarray(forces, float)
    x = x.reshape(x.shape[0], -1)
    blocks = min(BLOCKS, x.shape[0] // MIN_BLOCK)
    if blocks < 4:
        return None
    n = x.shape[0] // blocks
    seg = x[:n * blocks].reshape(blocks, n, x.shape[1])
    seg = seg - seg.mean(axis=1, keepdims=True)   # each block's own offset (a half-quiet block's is large)
    seg = seg * np.hanning(n)[None, :, None]
    # energy under the window: a block the sweep only enters or leaves at its edge (where the window
    # is ~0) has a peak that says nothing and is not driven
    energy = np.sum(seg ** 2, axis=(1, 2))
    driven = np.flatnonzero(energy >= ACTIVE * energy.max())
    spec = np.abs(np.fft.rfft(seg[driven], axis=1)).sum(axis=2)
    track = np.argmax(spec[:, 1:], axis=1) + 1
    runs = _runs(track)
    if runs is None:
        reverse = _runs(track[::-1])
        if reverse is None:
            return None
        runs = [(track.size - 1 - b, track.size - 1 - a) for a, b in reversed(reverse)]
    first = np.array([driven[a] for a, _ in runs[1:]], dtype=np.int64)
    quiet_before = ~np.isin(first - 1, driven)
    return np.concatenate([[0], (first - quiet_before) * n]).astype(np.int64)


def sweep_plan(forces: np.ndarray) -> np.ndarray | None:
    """The sweep starts of a force record [n_samples, n_forces] when its FRFs are to be formed one
    segment per sweep: :func:`sweep_starts`, or None when the record is not a sweep or holds fewer
    sweeps than forces (H1 of n inputs needs at least n independent segments; Welch then)."""
    x = np.asarray(forces, float).reshape(np.shape(forces)[0], -1)
    starts = sweep_starts(x)
    return starts if starts is not None and starts.size >= x.shape[1] else None


def sweep_segments(samples: np.ndarray, starts: np.ndarray, channels: list[int]) -> np.ndarray:
    """One segment per sweep [n_sweeps, n_channels, n_longest] of ``channels`` of ``samples``
    [n_samples, n_channels_all]: from each start to the next (the last to the record's end, an even
    length), each without its mean, zero-padded to the longest (a sweep's response has died out by
    the end of its segment, so the padding adds no leakage)."""
    x = np.asarray(samples[()], float)[:, channels]
    ends = np.append(np.asarray(starts[1:], np.int64), x.shape[0])
    length = int(np.max(ends - starts))
    length -= length % 2
    out = np.zeros((len(starts), len(channels), length))
    for k, (a, b) in enumerate(zip(starts, ends, strict=True)):   # a loop over sweeps, not samples
        piece = x[a:min(b, a + length)]
        out[k, :, :piece.shape[0]] = (piece - piece.mean(axis=0)).T
    return out
