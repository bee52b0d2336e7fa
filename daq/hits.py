"""Live screening of impact-hammer hits and a running H1 estimate, for the acquisition display.

Each trigger (daq.acquire.TriggerDetector) is a hit.  ``HIT_LOOK_S`` after it the hit is judged on the
stored rows [hit - pretrigger, hit + HIT_LOOK_S): rejected as an *overload* when the force or the chosen
response reaches its ``full_scale``, a *double hit* when the force, after falling below
``DOUBLE_LOW`` x its peak, rises again above ``DOUBLE_HIGH`` x the peak (the hammer bounced), *too weak*
when the force peak is below ``min_peak``; once ``window`` samples after the hit are in, a hit not
rejected is *cut short* when the next hit or missing samples (NaN) fall inside its window (at once
when its pretrigger would begin before the run's first row), else *accepted* and added to the H1
estimate at the response channel (Ewins, Modal Testing, 2000, sec. 3.7):
H1 = sum(conj(F) X) / sum(|F|^2), coherence = |sum(conj(F) X)|^2 / (sum|F|^2 sum|X|^2), rectangular
windows of ``window`` samples starting ``pretrigger`` samples before the hit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HIT_LOOK_S = 0.1  # rejections that show in the pulse are reported this long after the hit
DOUBLE_LOW, DOUBLE_HIGH = 0.1, 0.2


@dataclass(frozen=True)
class Hit:
    """One judged hit: ``row`` of the trigger, ``verdict`` accepted|rejected, ``reason`` for a rejection."""

    row: int
    peak: float
    verdict: str
    reason: str = ""


def double_hit(force: np.ndarray, peak_at: int) -> bool:
    """True when ``force`` falls below DOUBLE_LOW x its peak after ``peak_at`` and later exceeds
    DOUBLE_HIGH x the peak again (sign of the main pulse)."""
    f = force * np.sign(force[peak_at]) / abs(force[peak_at])
    after = f[peak_at:]
    low = np.flatnonzero(after < DOUBLE_LOW)
    return bool(low.size) and bool((after[low[0]:] > DOUBLE_HIGH).any())


class HitMonitor:
    """Judges hits on rows as they are stored and keeps the running H1 of ``response`` over ``force``."""

    def __init__(self, force: int, response: int, fs: float, window: int, pretrigger: int, min_peak: float,
                 full_scale: tuple[float, float]) -> None:
        self.force, self.response, self.fs = force, response, fs
        self.window, self.pre, self.min_peak = window, pretrigger, min_peak
        self.full_scale = full_scale
        self.look = int(round(HIT_LOOK_S * fs))
        self.rows = np.zeros((0, 2))  # stored rows of force and response, from row self.row0
        self.row0 = 0
        self.first_row: int | None = None  # the first row stored (the run's start)
        self.pending: list[int] = []  # hits not judged yet (rows)
        self.early: dict[int, Hit] = {}  # hits passed the pulse checks, waiting for their window
        self.hits: list[Hit] = []
        self.freq_hz = np.fft.rfftfreq(window, 1 / fs)
        self.sff = np.zeros(self.freq_hz.size)
        self.sxx = np.zeros(self.freq_hz.size)
        self.sfx = np.zeros(self.freq_hz.size, complex)

    def add(self, rows: np.ndarray, row0: int, triggers: list[int]) -> list[Hit]:
        """Take stored rows ``row0 ..`` (all channels) and the hits in them; returns the hits judged now."""
        if self.first_row is None:
            self.first_row = row0
        if not self.rows.size:
            self.row0 = row0
        self.rows = np.vstack([self.rows, rows[:, [self.force, self.response]]])
        self.pending += triggers
        judged = [h for h in (self._judge(t) for t in list(self.pending)) if h is not None]
        keep_from = min([t - self.pre for t in self.pending], default=self.row0 + self.rows.shape[0]
                        - self.pre - self.window)
        cut = max(0, min(keep_from - self.row0, self.rows.shape[0]))
        self.rows, self.row0 = self.rows[cut:], self.row0 + cut
        self.hits += judged
        return judged

    def _segment(self, t: int, n: int) -> np.ndarray | None:
        a = t - self.pre - self.row0
        return self.rows[a:a + n] if a >= 0 and a + n <= self.rows.shape[0] else None

    def _judge(self, t: int) -> Hit | None:
        if t - self.pre < self.first_row:  # its pretrigger is before the run: never a whole window
            return self._done(t, Hit(t, float("nan"), "rejected", "cut short"))
        if t not in self.early:
            seg = self._segment(t, self.pre + self.look)
            if seg is None:
                return None
            f = seg[:, 0]
            if np.isnan(seg).any():
                return self._done(t, Hit(t, float(np.nanmax(np.abs(f), initial=0)), "rejected", "cut short"))
            peak_at = int(np.argmax(np.abs(f)))
            peak = float(abs(f[peak_at]))
            over = (np.abs(seg) >= np.array(self.full_scale)).any()
            reason = ("overload" if over else "double hit" if double_hit(f, peak_at)
                      else "too weak" if peak < self.min_peak else "")
            if reason:
                return self._done(t, Hit(t, peak, "rejected", reason))
            self.early[t] = Hit(t, peak, "accepted")
        seg = self._segment(t, self.window)
        later = [u for u in self.pending if t < u < t - self.pre + self.window]
        if later or (seg is not None and np.isnan(seg).any()):
            return self._done(t, Hit(t, self.early.pop(t).peak, "rejected", "cut short"))
        if seg is None:
            return None
        spectra = np.fft.rfft(seg, axis=0)
        f, x = spectra[:, 0], spectra[:, 1]
        self.sff += np.abs(f) ** 2
        self.sxx += np.abs(x) ** 2
        self.sfx += np.conj(f) * x
        return self._done(t, self.early.pop(t))

    def _done(self, t: int, hit: Hit) -> Hit:
        self.pending.remove(t)
        return hit

    def finish(self) -> list[Hit]:
        """Hits whose window never completed (the run ended): cut short."""
        out = [Hit(t, self.early.pop(t).peak if t in self.early else float("nan"), "rejected", "cut short")
               for t in self.pending]
        self.pending.clear()
        self.hits += out
        return out

    @property
    def accepted(self) -> int:
        return sum(h.verdict == "accepted" for h in self.hits)

    def h1(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(frequency Hz, |H1| response units per force unit, coherence) over the accepted hits."""
        with np.errstate(divide="ignore", invalid="ignore"):
            h = np.abs(self.sfx) / self.sff
            coh = np.abs(self.sfx) ** 2 / (self.sff * self.sxx)
        return self.freq_hz, h, coh


BARS = " ▁▂▃▄▅▆▇█"


def sparkline(values: np.ndarray, width: int, lo: float, hi: float, reduce=np.nanmax) -> str:
    """``values`` in ``width`` columns (``reduce`` per column) as block characters from ``lo`` to ``hi``."""
    cols = np.array_split(np.asarray(values, float), width)
    level = np.array([reduce(c) if c.size and np.isfinite(c).any() else np.nan for c in cols])
    idx = np.clip(np.round((level - lo) / (hi - lo) * (len(BARS) - 1)), 0, len(BARS) - 1)
    return "".join(" " if np.isnan(v) else BARS[int(i)]
                   for v, i in zip(level, np.nan_to_num(idx), strict=True))
