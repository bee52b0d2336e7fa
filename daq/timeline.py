"""One timeline for all devices of a session: place blocks on the sample grid, convert, flag faults.

Alignment rule (docs/acquisition.md): every device runs at the session's sample rate.  The first block
of the session fixes row 0 at its first sample; another device's first sample goes to row
``round((t_dev - t_ref) * sample_rate_hz)`` from the two first-sample timestamps (bus or host clock).
After that each device is placed by its own sample counter, so a device's row is
``first_index - base`` and clock drift between devices is not corrected.  Rows a device did not
deliver (a sequence gap, corrupt frames, a disconnect) are NaN in its columns and are reported as a
``gap`` event (or ``corrupt`` when bad frames were dropped there) at the first missing row; rows are
released to the writer when every device has reached them, except devices the writer declares silent:
those are padded with NaN (:meth:`Timeline.pad`) and get one ``gap`` event covering the silence when they
deliver again or the run ends; samples they deliver late, for rows already released, are dropped (a
block that continues the device's counter is late, never a restart: placed at the current row, a
silent device's buffered samples were written seconds after their time).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from flexmodal.daq.devices import Block
from flexmodal.daq.errors import DaqError
from flexmodal.daq.session import source_unit_fault
from flexmodal.daq.store import Event

ANALOG_KINDS = ("acceleration", "force", "strain", "voltage")
MAX_GAP_S = 60.0  # a longer jump of a device counter is taken as a device restart, not a gap


@dataclass
class _Track:
    cols: np.ndarray  # session channel index of each column of this device
    src: np.ndarray  # device source index feeding each column
    gain: np.ndarray
    bias: np.ndarray
    full_scale: np.ndarray
    analog: np.ndarray  # converter limits mean clipping only for analogue inputs (not counters)
    base: int | None = None
    rows: int = 0  # rows delivered so far (next free row)
    parts: deque = field(default_factory=deque)
    taken: int = 0  # rows of parts[0] already handed out
    silent_from: int | None = None  # first row padded because the device was silent
    next_index: int | None = None  # the device counter's value its next block continues from


class Timeline:
    """Turns device blocks into rows of physical values [n, n_channels] and events with row indices."""

    def __init__(self, session, sources: dict[str, tuple[str, ...]],
                 units: Mapping[str, Mapping[str, str]] | None = None) -> None:
        """``sources``: each device's value names in column order; ``units``: the units a device
        labels its values with ({device: {source: unit}}, e.g. from a DBC), checked against the
        channels' scale and sensitivity (daq.session.source_unit_fault)."""
        self.fs = session.sample_rate_hz
        self.names = tuple(c.channel.name for c in session.channels)
        self.n_ch = len(self.names)
        self.tracks: dict[str, _Track] = {}
        for dev in session.devices:
            maps = [(i, c) for i, c in enumerate(session.channels) if c.device == dev.name]
            for _, c in maps:
                have = sources[dev.name]
                if c.source not in have:
                    known = ", ".join(have[:12]) + (", ..." if len(have) > 12 else "")
                    raise DaqError(f"{session.source}: channel {c.channel.name!r}: source {c.source!r} is "
                                   f"not a signal of device {dev.name!r} (it has: {known or 'none'})")
                fault = source_unit_fault(c, (units or {}).get(dev.name, {}).get(c.source, ""))
                if fault:   # a DBC signal in V read as mV under a sensitivity in mV/g: 1000x, rc 0
                    raise DaqError(f"{session.source}: channel {c.channel.name!r}: {fault}")
            src = np.array([sources[dev.name].index(c.source) for _, c in maps])
            g = np.array([c.gain() for _, c in maps])
            self.tracks[dev.name] = _Track(
                cols=np.array([i for i, _ in maps]), src=src, gain=g,
                bias=np.array([c.offset / c.channel.sensitivity * c.factor for _, c in maps]),
                full_scale=np.array([c.full_scale for _, c in maps]),
                analog=np.array([c.channel.kind in ANALOG_KINDS for _, c in maps]))
        self.t_ref: float | None = None
        self.first_index: dict[str, int] = {}
        self.released = 0

    def add(self, block: Block, clipped: np.ndarray | None = None) -> list[Event]:
        """Place ``block`` (``clipped``: bool [n, n_sources] raw values at the converter's limits)."""
        tr = self.tracks[block.device]
        events: list[Event] = []
        if tr.base is None:
            if self.t_ref is None:
                self.t_ref = block.timestamp_s
            start = int(round((block.timestamp_s - self.t_ref) * self.fs))
            tr.base = block.first_index - start
            if start > tr.rows and tr.silent_from is None:  # a later start is not a gap
                tr.parts.append(np.full((start - tr.rows, tr.cols.size), np.nan))
                tr.rows = start
            self.first_index[block.device] = block.first_index - start
        values = block.values[:, tr.src] * tr.gain + tr.bias
        row = block.first_index - tr.base
        continues = block.first_index == tr.next_index   # late samples, not a restart of the device
        tr.next_index = block.first_index + block.values.shape[0]
        resumed = tr.silent_from is not None and row >= tr.silent_from - self.fs
        if resumed:  # back after a silence (not restarted): one gap over it, late samples dropped
            end = max(row, tr.rows)
            events.append(Event("gap", tr.silent_from, end - tr.silent_from,
                                f"{block.device}: silent, {end - tr.silent_from} samples lost"))
            if row > tr.rows:
                tr.parts.append(np.full((row - tr.rows, tr.cols.size), np.nan))
                tr.rows = row
            tr.silent_from = None
        elif not continues and (row > tr.rows + MAX_GAP_S * self.fs or row < tr.rows - self.fs):
            # A restarted counter: the device was reset, or another device now answers on its port
            # (a reused pty; nothing in the stream tells them apart).  Either way the record breaks
            # here after an unknown time: one NaN row and a gap event over it, so that no spectrum
            # segment spans the splice (a "note" alone left the two streams joined as one record).
            events.extend(self.close_gaps(tr.rows, block.device))
            events.append(Event("gap", tr.rows, 1, f"{block.device}: counter jumped from "
                                                     f"{tr.base + tr.rows} to {block.first_index} (device "
                                                     "restarted, or another device on its port): record "
                                                     "discontinuous here"))
            tr.parts.append(np.full((1, tr.cols.size), np.nan))
            tr.rows += 1
            tr.base = block.first_index - tr.rows
            row = tr.rows
        if row < tr.rows:  # already have these samples (a repeated frame): keep the new ones only
            values, clipped = values[tr.rows - row:], None if clipped is None else clipped[tr.rows - row:]
            row = tr.rows
        missing = row - tr.rows
        if missing:
            tr.parts.append(np.full((missing, tr.cols.size), np.nan))
            kind = "corrupt" if block.corrupt else "gap"
            count = block.corrupt if block.corrupt else missing
            events.append(Event(kind, tr.rows, count, f"{block.device}: {missing} samples lost"))
        elif block.corrupt:
            events.append(Event("corrupt", row, block.corrupt, f"{block.device}: values lost in row"))
        n = values.shape[0]
        if n:
            over = np.abs(values) >= tr.full_scale
            if clipped is not None:
                over |= clipped[:, tr.src] & tr.analog
            for j in np.flatnonzero(over.any(axis=0)):  # one event per clipped channel in the block
                hit = np.flatnonzero(over[:, j])
                events.append(Event("overload", row + int(hit[0]), int(hit.size), self.names[tr.cols[j]]))
            tr.parts.append(values)
        tr.rows = row + n
        return events

    def at_row(self, device: str) -> int:
        """The next row ``device`` will fill (where a disconnect or reconnect is dated)."""
        return self.tracks[device].rows

    def ready(self, skip: set[str] | frozenset = frozenset()) -> int:
        """Rows every device (except those in ``skip``) has delivered that were not released yet."""
        rows = [t.rows for d, t in self.tracks.items() if d not in skip]
        return max(min(rows) - self.released, 0) if rows else 0

    def pad(self, device: str, upto: int) -> None:
        """NaN rows for ``device`` up to row ``upto`` (it is silent; the gap is reported later)."""
        tr = self.tracks[device]
        if tr.rows < upto:
            tr.parts.append(np.full((upto - tr.rows, tr.cols.size), np.nan))
            if tr.silent_from is None:
                tr.silent_from = tr.rows
            tr.rows = upto

    def close_gaps(self, upto: int, device: str | None = None) -> list[Event]:
        """``gap`` events for the silences still open (of ``device``, default all), up to row ``upto``."""
        events = []
        for d, tr in self.tracks.items():
            if tr.silent_from is not None and device in (None, d) and upto > tr.silent_from:
                events.append(Event("gap", tr.silent_from, upto - tr.silent_from,
                                    f"{d}: silent, {upto - tr.silent_from} samples lost"))
            if device in (None, d):
                tr.silent_from = None
        return events

    def take(self, n: int | None = None) -> np.ndarray:
        """Release the next ``n`` ready rows (all by default) as [n, n_channels]."""
        n = self.ready() if n is None else min(n, self.ready())
        out = np.empty((max(n, 0), self.n_ch))
        for tr in self.tracks.values():
            got = 0
            while got < n:
                part = tr.parts[0]
                k = min(n - got, part.shape[0] - tr.taken)
                out[got:got + k, tr.cols] = part[tr.taken:tr.taken + k]
                got += k
                tr.taken += k
                if tr.taken == part.shape[0]:
                    tr.parts.popleft()
                    tr.taken = 0
        self.released += max(n, 0)
        return out
