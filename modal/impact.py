"""Impact (hammer) test processing: hit segmentation, per-hit acceptance, force/exponential windows and
linear or exponential averaging of the hit spectra (Brandt 2011 §13.6; Ewins 2000 §3.6).

Each hit is one record of ``record_len`` samples starting ``pretrigger`` samples before its trigger.
Channel offsets are taken from the pretrigger samples.  The force gets the force window times the
exponential window, the responses the exponential window, both starting at the record start, so the
FRF is that of the structure with every pole's real part shifted by the window's decay rate
(undone by :func:`modal.windows.remove_added_damping`).  A hit is rejected, with the reason kept,
for an overload (a flagged overload event or a clipped channel), a double hit (the force rises again
after the pulse), or low coherence (its FRF disagrees with the others' average: FRAC below a limit).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from flexmodal.modal.errors import ModalError
from flexmodal.modal.spectra import Spectra, spectra_of_segments
from flexmodal.modal.windows import window


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
    at least ``min_gap`` samples apart."""
    f = np.abs(force - np.median(force))
    lev = 0.2 * f.max() if level is None else level
    above = f >= lev
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


def _frac(a: np.ndarray, b: np.ndarray) -> float:
    """Frequency response assurance criterion of two FRFs (1 = identical shape over frequency)."""
    return float(np.abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real))


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


def impact_spectra(samples: np.ndarray, sample_rate_hz: float, force_col: int, outputs: Sequence[int], *,
                   triggers: Sequence[int] | None = None, pretrigger_s: float = 0.02,
                   record_len: int | None = None, force_window: str = "force",
                   exp_window: str = "exponential", averaging: str = "linear", n_exp: int = 4,
                   double_hit_fraction: float = 0.1, min_frac: float = 0.9, min_gap_s: float = 1.0,
                   overload_samples: Sequence[int] = ()) -> tuple[Spectra, list[Hit]]:
    """Averaged spectra of the accepted hits and the list of hits with their verdicts.

    ``triggers`` default to :func:`find_triggers` on the force (hits at least ``min_gap_s`` apart, so a
    double hit stays in its record); ``record_len`` defaults to the shortest
    distance between consecutive record starts (and to the end of the data).  ``overload_samples`` are
    sample indices flagged as overloaded by the acquisition.
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
        record_len = int(min(np.min(np.diff(starts), initial=n), n - starts[-1]))
    starts, trig = starts[starts + record_len <= n], trig[starts + record_len <= n]
    if record_len < 16 or starts.size == 0:
        raise ModalError(f"impact test: records of {record_len} samples are too short")
    chans = [force_col, *outputs]
    idx = starts[:, None] + np.arange(record_len)[None, :]
    recs = np.moveaxis(samples[idx][:, :, chans], 1, 2).astype(float)   # [hit, ch, t]
    if pre >= 8:
        recs -= recs[:, :, :pre].mean(axis=-1, keepdims=True)
    w_exp = window(exp_window, record_len)
    w = np.vstack([window(force_window, record_len) * w_exp, np.repeat(w_exp[None], len(outputs), 0)])
    overloads = np.asarray(overload_samples, int)
    reasons = []
    for k, s in enumerate(starts):  # a loop over hits (a few), not samples
        if np.any((overloads >= s) & (overloads < s + record_len)) or any(_clipped(c) for c in recs[k]):
            reasons.append("overload")
        elif _double_hit(recs[k, 0, pre:], double_hit_fraction):
            reasons.append("double hit")
        else:
            reasons.append("")
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
            value = _frac(per_hit[j].ravel(), others.ravel())
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
