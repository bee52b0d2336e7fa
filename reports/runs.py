"""What a report shows of a stored run (docs/hdf5-format.md): metadata, channels, data quality, FRFs.

A :class:`RunSummary` holds what the caller read and computed (the ``daq.store.Run``, its FRFs and
their identification, or its output-only identification); the properties here only count and
summarise.  Impact hits come from the FRF provenance (``hits``: ``trigger``, ``accepted``,
``reason``); without it, rejected hits are the ``note`` events whose detail starts with ``rejected``.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from flexmodal.daq.store import Run
    from flexmodal.modal.frf import FrfResult
    from flexmodal.modal.identify import Modes
    from flexmodal.modal.oma import OmaResults

LOW_COHERENCE = 0.8


@dataclass(frozen=True, eq=False)
class RunSummary:
    """A run for the report: ``run`` as read, its ``frf`` (None when not computed; in SI units when its
    outputs or its inputs are stored in different units, :func:`flexmodal.modal.sources.si_frf`, and
    then ``frf_units`` names them), the ``modes`` identified from those FRFs (``modal.identify.Modes``)
    or the reason there are none (a string), and for an output-only run without FRFs its FDD and SSI
    results (``oma``, ``modal.oma.OmaResults``)."""

    run: Run
    frf: FrfResult | None = None
    modes: Modes | str | None = None
    oma: OmaResults | None = None
    frf_units: tuple[str, str] | None = None   # (outputs', inputs') unit after si_frf, when it rescaled

    @property
    def label(self) -> str:
        return f"{self.run.path.name}::{self.run.run_id}"

    @property
    def frf_unit(self) -> str:
        """Unit of the run's FRFs from its channels' units (outputs per input: ``g/N``, ``(m/s²)/N``)."""
        from flexmodal.reports.plots import frf_unit, ratio_unit

        if self.frf is None:
            return ""
        units = {c.name: c.unit for c in self.run.channels}
        if not all(n in units for n in (*self.frf.outputs, *self.frf.inputs[:1])) or not self.frf.inputs:
            return frf_unit(self.frf.quantity)
        if self.frf_units is not None:
            return ratio_unit([self.frf_units[0]], self.frf_units[1])
        return ratio_unit([units[n] for n in self.frf.outputs], units[self.frf.inputs[0]])

    @property
    def n_samples(self) -> int:
        return int(np.shape(self.run.samples)[0])

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.run.sample_rate_hz

    @cached_property
    def peak_abs(self) -> np.ndarray:
        """Largest |sample| per channel [n_channels], in the channel's unit."""
        samples = np.asarray(self.run.samples)
        return np.max(np.abs(samples), axis=0) if samples.size else np.zeros(len(self.run.channels))

    @property
    def event_counts(self) -> Counter:
        """Number of events per kind (trigger, gap, overload, corrupt, reconnect, note)."""
        return Counter(e.kind for e in self.run.events)

    @property
    def overload_samples(self) -> int:
        return int(sum(e.count for e in self.run.events if e.kind == "overload"))

    @property
    def hits(self) -> list[dict]:
        """Impact hits recorded by the FRF processing: {trigger, accepted, reason}; [] if none."""
        if self.frf is None:
            return []
        return [h for h in self.frf.provenance.get("hits", []) if isinstance(h, dict)]

    def _rejected_notes(self) -> list[str]:
        return [e.detail for e in self.run.events
                if e.kind == "note" and e.detail.lower().startswith("rejected")]

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
