"""What a report shows of a stored run (CONTRACT §6): metadata, channels, data quality, FRFs.

Runs are read with ``daq.store.read_run`` and their FRF group with ``modal.runs_io.read_frf``.  Impact
hits come from the FRF provenance (``hits``: ``trigger``, ``accepted``, ``reason``); without it,
rejected hits are the ``note`` events whose detail starts with ``rejected``.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexmodal.daq.store import Channel, Event, read_run
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.runs_io import read_frf

LOW_COHERENCE = 0.8


@dataclass(frozen=True)
class RunSummary:
    path: Path
    run_id: str
    sample_rate_hz: float
    start_time: str
    excitation: str
    pose: dict
    n_samples: int
    channels: tuple[Channel, ...]
    events: tuple[Event, ...]
    attrs: dict
    peak_abs: np.ndarray  # [n_channels] largest |sample| per channel, in the channel's unit
    frf: FrfResult | None

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.sample_rate_hz

    @property
    def event_counts(self) -> Counter:
        """Number of events per kind (trigger, gap, overload, corrupt, reconnect, note)."""
        return Counter(e.kind for e in self.events)

    @property
    def overload_samples(self) -> int:
        return int(sum(e.count for e in self.events if e.kind == "overload"))

    @property
    def hits(self) -> list[dict]:
        """Impact hits recorded by the FRF processing: {trigger, accepted, reason}; [] if none."""
        if self.frf is None:
            return []
        return [h for h in self.frf.provenance.get("hits", []) if isinstance(h, dict)]

    def _rejected_notes(self) -> list[str]:
        return [e.detail for e in self.events if e.kind == "note" and e.detail.lower().startswith("rejected")]

    @property
    def rejected_hits(self) -> int:
        if self.hits:
            return sum(1 for h in self.hits if not h.get("accepted", True))
        return len(self._rejected_notes())

    @property
    def rejection_reasons(self) -> list[str]:
        """Distinct reasons given for rejected hits."""
        reasons = [str(h.get("reason", "")) for h in self.hits if not h.get("accepted", True)]
        return list(dict.fromkeys(r for r in reasons + self._rejected_notes() if r))

    def coherence_stats(self) -> tuple[float, float] | None:
        """Mean coherence [-] and share of (output, line) values below LOW_COHERENCE [%]; None without FRF."""
        if self.frf is None or self.frf.coherence is None:
            return None
        coh = self.frf.coherence[:, self.frf.freq_hz > 0]
        return float(np.mean(coh)), float(100.0 * np.mean(coh < LOW_COHERENCE))


def summarise_run(path: str | Path, run_id: str) -> RunSummary:
    """Read one run and what the report needs of it."""
    run = read_run(path, run_id)
    samples = np.asarray(run.samples)
    peak = np.max(np.abs(samples), axis=0) if samples.size else np.zeros(len(run.channels))
    return RunSummary(Path(path), run_id, run.sample_rate_hz, run.start_time, run.excitation, dict(run.pose),
                      int(samples.shape[0]), run.channels, run.events, dict(run.attrs), peak,
                      read_frf(path, run_id))
