"""Impact (hammer) test processing: hit segmentation, per-hit acceptance, force/exponential windows and
linear or exponential averaging of the hit spectra (Brandt 2011 §13.6; Ewins 2000 §3.6).

Each hit is one record of ``record_len`` samples starting ``pretrigger`` samples before its trigger.
Channel offsets are taken from the pretrigger samples.  The force gets the force window times the
exponential window, the responses the exponential window (by default none: ``exponential:1``, see
:func:`modal.windows.impact_windows`), both starting at the record start, so the FRF is that of the
structure with every pole's real part shifted by the window's decay rate (undone by
:func:`modal.windows.remove_added_damping`).  A hit is rejected, with the reason kept,
for lost data (its record overlaps a gap or corrupt event or holds NaN rows), a truncated record (the
data end before the record does), an overload (a flagged overload event or a clipped channel), a
double hit (the force rises again after the pulse), or low coherence (its FRF disagrees with the
others' average: FRAC below a limit).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from flexmodal.modal.errors import ModalError
from flexmodal.modal.indicators import frac
from flexmodal.modal.spectra import Spectra, spectra_of_segments
from flexmodal.modal.windows import window

MIN_LAST_RECORD = 0.9   # a last hit cut short by the end of the data still sets the record length


@dataclass(frozen=True)
class Hit:
    """One hammer hit: record start sample, trigger sample, and why it was rejected ("" = accepted)."""

    start: int
    trigger: int
    reason: str = ""

    @property
    def accepted(self) -> bool:
        return not self.reason


def find_triggers(force: np.ndarray, *, level: float | None = None, min_gap: int = 1) -> np.ndarray:
    """Sample indices where |force - median| first rises above ``level`` (default 20 % of its peak),
    at least ``min_gap`` samples apart (NaN samples ignored)."""
    f = np.abs(force - np.nanmedian(force))
    lev = 0.2 * np.nanmax(f) if level is None else level
    above = f >= lev   # NaN samples (lost data) are never above
    rises = np.flatnonzero(above & ~np.concatenate([[False], above[:-1]]))
    keep: list[int] = []
    for r in rises:  # a loop over rising edges (a handful), not samples
        if not keep or r - keep[-1] >= min_gap:
            keep.append(int(r))
    return np.array(keep, dtype=int)


def _clipped(x: np.ndarray, run_len: int = 3) -> bool:
    """True when the channel sits at its extreme value for ``run_len`` or more consecutive samples."""
    peak = np.abs(x).max()
    if peak == 0:
        return False
    at = np.abs(x) >= peak * (1 - 1e-9)
    runs = np.convolve(at.astype(int), np.ones(run_len, int), mode="valid")
    return bool(np.any(runs >= run_len))


def _double_hit(force: np.ndarray, fraction: float) -> bool:
    """True when, after the main pulse has decayed below 5 % of its peak, the force exceeds
    ``fraction`` of the peak again."""
    f = np.abs(force)
    k = int(np.argmax(f))
    ended = np.flatnonzero(f[k:] < 0.05 * f[k])
    return bool(ended.size and np.any(f[k + ended[0]:] > fraction * f[k]))


def average_weights(n: int, averaging: str = "linear", n_exp: int = 4) -> np.ndarray:
    """Weights [n] of successive hits: equal (linear) or exponential with time constant ``n_exp`` hits
    (each new hit enters with weight 1/n_exp, as an analyser's exponential averaging)."""
    if averaging == "linear":
        return np.full(n, 1.0 / n)
    if averaging != "exponential":
        raise ModalError(f"averaging {averaging!r}: use linear or exponential")
    alpha = 1.0 / max(1, n_exp)
    w = alpha * (1 - alpha) ** np.arange(n - 1, -1, -1)
    w[0] = (1 - alpha) ** (n - 1)   # the first hit starts the average with full weight
    return w


def _gap_reasons(samples: np.ndarray, starts: np.ndarray, record_len: int, chans: list[int],
                 gaps: Sequence[tuple[int, int]], sample_rate_hz: float) -> list[str]:
    """Per hit: why its record cannot be used because data are missing ("" if complete): it overlaps
    a gap/corrupt event (first sample, count) or holds non-finite samples (NaN rows of lost frames)."""
    ev = np.asarray(gaps, int).reshape(-1, 2)
    lo, hi = ev[:, 0], ev[:, 0] + np.maximum(ev[:, 1], 1)
    reasons = []
    for s in starts:   # a loop over hits (a few), not samples
        e = s + record_len
        hit = np.flatnonzero((lo < e) & (hi > s))
        bad = np.flatnonzero(~np.isfinite(samples[s:e][:, chans]).all(axis=1))
        if hit.size:
            k = hit[0]
            reasons.append(f"gap: lost data at samples {lo[k]}-{hi[k] - 1} "
                           f"({(lo[k] - s) / sample_rate_hz:.3g} s into the record)")
        elif bad.size:
            reasons.append(f"gap: {bad.size} non-finite samples from sample {s + bad[0]} "
                           f"({bad[0] / sample_rate_hz:.3g} s into the record)")
        else:
            reasons.append("")
    return reasons


def impact_spectra(samples: np.ndarray, sample_rate_hz: float, force_col: int, outputs: Sequence[int], *,
                   triggers: Sequence[int] | None = None, pretrigger_s: float = 0.02,
                   record_len: int | None = None, force_window: str = "force",
                   exp_window: str = "exponential:1", averaging: str = "linear", n_exp: int = 4,
                   double_hit_fraction: float = 0.1, min_frac: float = 0.9, min_gap_s: float = 1.0,
                   overloads: Sequence[tuple[int, int]] = (), gaps: Sequence[tuple[int, int]] = ()
                   ) -> tuple[Spectra, list[Hit]]:
    """Averaged spectra of the accepted hits and the list of hits with their verdicts.

    ``triggers`` default to :func:`find_triggers` on the force (hits at least ``min_gap_s`` apart, so a
    double hit stays in its record); ``record_len`` defaults to the shortest distance between
    consecutive record starts, shortened to the last hit's when that one holds at least
    ``MIN_LAST_RECORD`` of it (else the last hit alone is rejected as truncated).  ``overloads`` are
    (first sample, count) intervals flagged as overloaded by the acquisition (a count of 0 is one
    sample; an interval may run past the data's end), ``gaps`` (first sample, count) intervals of lost
    or corrupt data.  A hit whose record overlaps a gap or holds NaN samples, and a last hit
    whose record the data end cuts short, are rejected one by one with the reason; the others are used.
    """
    n = samples.shape[0]
    pre = int(round(pretrigger_s * sample_rate_hz))
    force = samples[:, force_col]
    trig = (np.asarray(triggers, int) if triggers is not None
            else find_triggers(force, min_gap=max(1, int(min_gap_s * sample_rate_hz))))
    trig = trig[trig >= pre]
    if trig.size == 0:
        raise ModalError("impact test: no hammer hit found in the force channel")
    starts = trig - pre
    if record_len is None:
        record_len = int(min(np.min(np.diff(starts), initial=n), n - starts[0]))
        if n - starts[-1] >= MIN_LAST_RECORD * record_len:   # all records a little shorter
            record_len = min(record_len, int(n - starts[-1]))
    if record_len < 16:
        raise ModalError(f"impact test: records of {record_len} samples are too short")
    chans = [force_col, *outputs]
    full = starts + record_len <= n
    reasons = ["" if ok else f"truncated: the data end {(n - s - pre) / sample_rate_hz:.3g} s after the "
               f"trigger, the record needs {(record_len - pre) / sample_rate_hz:.3g} s"
               for s, ok in zip(starts, full, strict=True)]
    lost = _gap_reasons(samples, starts[full], record_len, chans, gaps, sample_rate_hz)
    for k, why in zip(np.flatnonzero(full), lost, strict=True):
        reasons[k] = why
    usable = np.flatnonzero(np.array([not r for r in reasons], bool))
    recs = np.zeros((starts.size, len(chans), record_len))                      # [hit, ch, t]
    if usable.size:
        idx = starts[usable, None] + np.arange(record_len)[None, :]
        recs[usable] = np.moveaxis(samples[idx][:, :, chans], 1, 2).astype(float)
    if pre >= 8:
        recs -= recs[:, :, :pre].mean(axis=-1, keepdims=True)
    w_exp = window(exp_window, record_len)
    w = np.vstack([window(force_window, record_len) * w_exp, np.repeat(w_exp[None], len(outputs), 0)])
    spans = np.asarray(overloads, np.int64).reshape(-1, 2)
    first, end = spans[:, 0], spans[:, 0] + np.maximum(spans[:, 1], 1)
    for k in usable:  # a loop over hits (a few), not samples
        s = starts[k]
        if np.any((first < s + record_len) & (end > s)) or any(_clipped(c) for c in recs[k]):
            reasons[k] = "overload"
        elif _double_hit(recs[k, 0, pre:], double_hit_fraction):
            reasons[k] = "double hit"
    segs = recs * w[None]
    good = [k for k, r in enumerate(reasons) if not r]
    if len(good) >= 3:
        single = [spectra_of_segments(segs[[k]], 1, sample_rate_hz, w_exp) for k in good]
        gff = np.array([s.g_ff[0, 0].real for s in single])
        band = gff.min(axis=0) > 0.01 * gff.max()          # lines every hit excites within 20 dB
        per_hit = np.array([s.g_xf[:, 0, band] / s.g_ff[0, 0, band].real for s in single])   # [hit, out, f]
        for j, k in enumerate(good):
            rest = np.delete(per_hit, j, axis=0)
            others = np.median(rest.real, axis=0) + 1j * np.median(rest.imag, axis=0)
            value = float(frac(per_hit[j].ravel(), others.ravel()))
            if value < min_frac:
                reasons[k] = f"low coherence (FRAC {value:.2f} against the other hits)"
    hits = [Hit(int(s), int(t), r) for s, t, r in zip(starts, trig, reasons, strict=True)]
    good = [k for k, h in enumerate(hits) if h.accepted]
    if not good:
        raise ModalError("impact test: every hit was rejected (" + "; ".join(
            f"hit at sample {h.trigger}: {h.reason}" for h in hits) + ")")
    spectra = spectra_of_segments(segs[good], 1, sample_rate_hz, w_exp,
                                  weights=average_weights(len(good), averaging, n_exp))
    return spectra, hits
