"""`flexmodal acquire`: reader threads -> one bounded queue -> one writer appending to the run store.

Each device runs in its own reader thread (daq.devices.run_reader) which puts blocks on a bounded
queue; the main thread places them on the session timeline (daq.timeline), records faults as events,
appends rows to the HDF5 run (daq.store.RunWriter, flushed at least every 0.5 s) and refreshes a live
display on stderr.  Rows go to the file as soon as every device that is delivering has reached them: a
device silent for ``STALL_S`` is left behind (its columns NaN, one ``gap`` event when it resumes or the
run ends), so one device never holds back another; silent for the session's ``reconnect_timeout_s`` it
is lost (``device_lost`` event) and the session ends unless ``continue_on_device_loss``.

It stops at the duration, on SIGINT (Ctrl-C), SIGTERM or SIGHUP (all the same clean way: flush, close,
summary), when a device is lost, or when the disk is nearly full (``DISK_RESERVE_BYTES`` left: the run is
closed intact with a ``stopped`` event).  A writer lagging real time by more than ``OVERRUN_S`` records
an ``overrun`` event and shows a warning.  While it runs the output file is locked (daq.lock).  If the
session has a ``[simulator]`` it is started first through the launcher registered in daq.hooks (by
flexmodal.fixtures) and stopped at the end.
"""

from __future__ import annotations

import dataclasses
import json
import os
import queue
import re
import signal
import threading
import time
from collections import Counter
from contextlib import ExitStack
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from flexmodal.checked_io.output import signals_deferred
from flexmodal.checked_io.signals import signal_handlers
from flexmodal.daq.devices import Block, ReaderStats, run_reader, with_endpoint
from flexmodal.daq.errors import DaqError
from flexmodal.daq.hits import HitMonitor, sparkline
from flexmodal.daq.hooks import simulator_launcher
from flexmodal.daq.lock import WriterLock
from flexmodal.daq.protocols import make_driver
from flexmodal.daq.session import Session
from flexmodal.daq.store import Event, RunWriter, disk_room, list_runs
from flexmodal.daq.timeline import Timeline

QUEUE_BLOCKS = 4096
NO_DATA_TIMEOUT_S = 15.0  # a session whose devices deliver nothing for this long is an error
STALL_S = 0.5  # a device silent this long no longer holds back the rows of the others
OVERRUN_S = 1.0  # the writer this far behind real time: an `overrun` event and a warning
DISK_RESERVE_BYTES = 8 << 20  # stop cleanly when less room than this is left (a chunk + metadata fit)
DISK_CHECK_S = 0.25
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class WriteFailed(DaqError):
    """The run store could not be written (I/O error); the file holds the last flush.

    The HDF5 library is left in an unusable state for this file, so the CLI exits at once without
    closing it (closing would try to write again and can crash).
    """


class Stopped(DaqError):
    """A stop signal (``signum``) ended the session before any sample was stored: the CLI exits
    128 + signum with this one line."""

    def __init__(self, message: str, signum: int) -> None:
        super().__init__(message)
        self.signum = signum


@dataclass(frozen=True)
class Summary:
    """What a session stored; ``signal`` the number of the signal that stopped it (0: none) and
    ``error`` why it ended early (a lost device, a full disk; empty when it did not)."""

    path: Path
    run_id: str
    n_samples: int
    n_channels: int
    sample_rate_hz: float
    events: Counter
    dropped_blocks: int
    signal: int = 0
    error: str = ""
    bounded: bool = False  # the session had a duration (a signal then stopped it early)
    polls: dict = dataclasses.field(default_factory=dict)  # polled devices: {name: {polls, missed}}
    by_slot: tuple[str, ...] = ()  # polled devices without a counter register (answers placed by slot)

    @property
    def exit_code(self) -> int:
        """The command's exit code: 128 + the signal that stopped a session before its duration, else 0
        (a session without a duration ends by a signal as planned)."""
        return 128 + self.signal if self.signal and self.bounded else 0

    def line(self) -> str:
        ev = ", ".join(f"{k} {v}" for k, v in sorted(self.events.items())) or "none"
        return (f"{self.path}\t{self.run_id}\t{self.n_samples} samples x {self.n_channels} channels at "
                f"{self.sample_rate_hz:g} Hz ({self.n_samples / self.sample_rate_hz:.2f} s)\tevents: {ev}")

    def polls_line(self) -> str:
        """One line naming the polled devices that missed samples (polls too late or too few: their rows
        are gaps), with a hint for those without a ``counter`` register; empty when none missed any."""
        missed = [d for d, c in self.polls.items() if c["missed"]]
        if not missed:
            return ""
        lost = "; ".join(f"{d} {self.polls[d]['missed']} samples missed in {self.polls[d]['polls']} polls"
                         for d in missed)
        uncounted = ", ".join(d for d in missed if d in self.by_slot)
        hint = (f"; a counter = \"<register>\" field (the device's sample counter) in [[device]] {uncounted} "
                "lets the poller place late answers") if uncounted else ""
        return f"polls: {lost} (too late to read them: recorded as gaps){hint}"


def _with_endpoint(session: Session, endpoint: str | None) -> Session:
    """The session with the '@simulator' placeholder replaced by the simulator's endpoint."""
    if endpoint is None:
        return session
    return dataclasses.replace(session, devices=tuple(
        dataclasses.replace(d, config=with_endpoint(d.config, endpoint)) for d in session.devices))


def _start_simulator(session: Session, out: Path, quiet: bool):
    """Start the session's simulator; returns (session with endpoints filled in, stop function).

    A fault log goes into the run file's folder (the session names only the file)."""
    sim = session.simulator
    if sim is None:
        return session, lambda: None
    if sim.fault_log:
        sim = dataclasses.replace(sim, fault_log=str(out.resolve().parent / sim.fault_log))
    endpoint, stop = simulator_launcher()(sim, session, quiet)
    return _with_endpoint(session, endpoint), stop


class StopSignals:
    """While active (a context manager, main thread only) SIGINT, SIGTERM and SIGHUP set ``event``
    instead of killing the process; ``signum`` is the first one received."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signum = 0
        self._handlers = ExitStack()

    def _handle(self, signum, _frame) -> None:
        self.signum = self.signum or signum
        self.event.set()

    def __enter__(self) -> StopSignals:
        self._handlers.enter_context(signal_handlers(self._handle, STOP_SIGNALS))
        return self

    def __exit__(self, *exc) -> None:
        self._handlers.close()


SPARK_COLS = (16, 64)   # fewest and most columns of the live |H1| and coherence sparklines


class Display:
    """Live status on stderr: elapsed, samples, rate, drops, faults and per-channel level / overloads."""

    def __init__(self, names: tuple[str, ...], units: tuple[str, ...], quiet: bool) -> None:
        self.names, self.units = names, units
        self.live = None
        self.t0 = time.monotonic()
        self.level = np.zeros(len(names))
        self.peak = np.zeros(len(names))
        self.overloads = np.zeros(len(names), int)
        self.behind_s = 0.0  # > 0: the writer lags real time by this much (overrun)
        self.monitor: HitMonitor | None = None  # impact sessions: hit verdicts and the running H1
        self.response = ""
        self.fs = 1.0
        self._last = 0.0
        if not quiet:
            from rich.console import Console
            from rich.live import Live

            # refreshed by update() only: no background thread writing to a terminal that may go away;
            # stdout is the command's result (the run line) and is never routed into the display
            self.live = Live(console=Console(stderr=True), auto_refresh=False, transient=False,
                             redirect_stdout=False)
            self.live.start()

    def rows(self, rows: np.ndarray) -> None:
        if rows.size:
            n = np.isfinite(rows).sum(axis=0)  # a silent device's all-NaN columns: level NaN, no warning
            self.level = np.sqrt(np.nansum(rows**2, axis=0) / np.where(n, n, np.nan))
            self.peak = np.maximum(self.peak, np.nanmax(np.abs(rows), axis=0, initial=0))

    def update(self, n_samples: int, rate_hz: float, dropped: int, events: Counter,
               force: bool = False, lost: list[str] = ()) -> None:
        if self.live is None or (not force and time.monotonic() - self._last < 0.25):
            return
        try:
            self._update(n_samples, rate_hz, dropped, events, lost)
        except OSError:  # the terminal went away (SIGHUP): go on without a display
            self.close()

    def _update(self, n_samples: int, rate_hz: float, dropped: int, events: Counter, lost) -> None:
        from rich.console import Group
        from rich.table import Table
        from rich.text import Text

        self._last = time.monotonic()
        elapsed = time.monotonic() - self.t0
        # two lines of their own above the table, each under 80 columns: as the table's title they were
        # wrapped to its width and centred (three ragged lines on any terminal, and in a log)
        status = [Text(f"acquiring  {elapsed:6.1f} s   {n_samples} samples   "
                       f"{n_samples / max(elapsed, 1e-9):,.0f} S/s (nominal {rate_hz:g})"),
                  Text(f"  drops {dropped}   corrupt {events['corrupt']}   gaps {events['gap']}   "
                       f"reconnects {events['reconnect']}   triggers {events['trigger']}")]
        table = Table(caption="\n".join(
                          ([f"OVERRUN: the file lags real time by {self.behind_s:.1f} s"] if self.behind_s
                           else []) + [f"DEVICE LOST: {d}" for d in lost]) or None,
                      caption_style="bold red")
        for col in ("channel", "unit", "rms", "peak", "overloads"):
            table.add_column(col, justify="right" if col not in ("channel", "unit") else "left")
        for i, name in enumerate(self.names):
            style = "bold red" if self.overloads[i] else None
            table.add_row(name, self.units[i], f"{self.level[i]:.4g}", f"{self.peak[i]:.4g}",
                          str(self.overloads[i]), style=style)
        more = [] if self.monitor is None else self._impact_lines(Text)
        self.live.update(Group(*status, table, *more), refresh=True)

    def _impact_lines(self, text) -> list:
        """The last hits with their verdicts, then |H1| (dB) and coherence at the chosen response."""
        m = self.monitor
        lines = [text(f"hits: {len(m.hits)}, accepted {m.accepted}", style="bold")]
        unit = self.units[m.force] if m.force < len(self.units) else ""
        for h in m.hits[-6:]:
            ok = h.verdict == "accepted"
            peak = f"{h.peak:8.4g} {unit}" if np.isfinite(h.peak) else f"{'-':>8} {' ' * len(unit)}"
            lines.append(text(f"  hit at {h.row / self.fs:8.3f} s  peak {peak}  "
                              f"{'ACCEPTED' if ok else 'REJECTED: ' + h.reason}",
                              style="green" if ok else "bold red"))
        if m.accepted:
            f, h, coh = m.h1()
            db = 20 * np.log10(np.where(h > 0, h, np.nan))
            top = np.nanmax(db[1:]) if np.isfinite(db[1:]).any() else 0.0
            # the sparklines fill what the console has left (80 columns off a terminal: rich's fallback),
            # so the |H1| line never wraps; both lines the same width, so they stay aligned
            n = max(SPARK_COLS[0], min(SPARK_COLS[1], self.live.console.width - 40 - len(self.response)))
            lines.append(text(f"  |H1| {self.response}  {sparkline(db[1:], n, top - 60, top)}  "
                              f"0-{f[-1]:g} Hz, top {top:.1f} dB"))
            pad = " " * len(self.response)
            lines.append(text(f"  coh  {pad}  {sparkline(coh[1:], n, 0, 1, np.nanmin)}  "
                              f"0..1, min {np.nanmin(coh[1:]):.2f}"))
        return lines

    def close(self) -> None:
        """End the live view, once; a terminal that went away is fine (rich's stop gives sys.stderr
        back before it writes its last frame, so later messages never go through the dead display)."""
        live, self.live = self.live, None
        if live is not None:
            try:
                live.stop()
                if self._last and not live.console.is_terminal:  # rich ends a terminal's last frame only:
                    live.console.line()                          # a message below starts afresh
            except OSError:
                pass


class TriggerDetector:
    """Level crossings on one channel (rising or falling), at most one per hold-off interval."""

    def __init__(self, column: int, level: float, slope: str, holdoff: int) -> None:
        self.column, self.level, self.holdoff = column, level, holdoff
        self.sign = 1 if slope == "rising" else -1
        self._prev = np.nan
        self._last = -(10**18)

    def find(self, rows: np.ndarray, row0: int) -> list[int]:
        x = self.sign * np.r_[self._prev, rows[:, self.column]]
        level = self.sign * self.level
        hits = np.flatnonzero((x[:-1] < level) & (x[1:] >= level)) + row0
        if rows.shape[0]:
            self._prev = rows[-1, self.column]
        out = []
        for h in hits:  # crossings are few (one per hit)
            if h - self._last >= self.holdoff:
                out.append(int(h))
                self._last = h
        return out


def _hit_monitor(session: Session, names: tuple[str, ...]) -> HitMonitor:
    """The hit screening of an impact session: force = the trigger channel, response = the trigger's
    ``response`` (default the first acceleration channel, else the first other channel)."""
    t = session.trigger
    force = names.index(t.channel)
    kinds = [c.channel.kind for c in session.channels]
    response = (names.index(t.response) if t.response else
                kinds.index("acceleration") if "acceleration" in kinds else (force + 1) % len(names))
    fs = session.sample_rate_hz
    return HitMonitor(force, response, fs, int(round(t.window_s * fs)), t.pretrigger_samples,
                      t.min_peak if t.min_peak is not None else 2 * abs(t.level),
                      (session.channels[force].full_scale, session.channels[response].full_scale))


def _clipped(block: Block, limits) -> np.ndarray | None:
    if limits is None:
        return None
    lo, hi = limits
    return (block.values <= lo) | (block.values >= hi)


def _check_output(path: Path, run_id: str, need_bytes: int) -> None:
    if not path.parent.is_dir():
        raise DaqError(f"{path}: directory {path.parent} does not exist")
    if not os.access(path.parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise DaqError(f"{path}: not writable")
    if path.exists() and run_id in list_runs(path):
        raise DaqError(f"{path}: run {run_id!r} already exists")
    room = disk_room(path)
    if room < need_bytes + DISK_RESERVE_BYTES:
        raise DaqError(f"{path}: only {room / 1e6:.1f} MB free for it; the run needs "
                       f"{need_bytes / 1e6:.1f} MB + {DISK_RESERVE_BYTES / 1e6:.0f} MB reserve")


def acquire(session: Session, out: str | Path, *, duration_s: float | None = None, quiet: bool = False,
            run_id: str | None = None) -> Summary:
    """Run an acquisition session into run ``run_id`` of ``out``; returns its summary.

    SIGINT, SIGTERM and SIGHUP (when called from the main thread) end it cleanly like the duration
    does, with ``Summary.signal`` set; a lost device or a full disk end it cleanly with
    ``Summary.error`` set.  Raises DaqError for bad input and WriteFailed when a write fails.
    """
    out = Path(out)
    stamp = datetime.now(UTC)
    run_id = run_id or session.run_id or f"{session.source.stem}-{stamp:%Y%m%dT%H%M%S}"
    given = "--duration" if duration_s is not None else "duration_s"
    duration_s = duration_s if duration_s is not None else session.duration_s
    if duration_s is not None and duration_s * session.sample_rate_hz < 1.0:
        where = given if given == "--duration" else f"{session.source}: duration_s ="
        raise DaqError(f"{where} {duration_s:g} s is shorter than one sample at {session.sample_rate_hz:g} "
                       f"Hz ({1 / session.sample_rate_hz:.3g} s): it would record nothing")
    if duration_s is not None and not duration_s * session.sample_rate_hz < 2.0**53:
        raise DaqError(f"--duration {duration_s:g} s at {session.sample_rate_hz:g} Hz: "
                       f"{duration_s * session.sample_rate_hz:.3g} samples, more than any run can hold")
    if session.simulator is not None:
        session.simulator.faults.check_within(duration_s, given, DaqError,
                                              lambda name: f"{session.source}: simulator: {name}")
    target = None if duration_s is None else int(round(duration_s * session.sample_rate_hz))
    need = 0 if target is None else int(target * len(session.channels) * 4 * 1.02)
    _check_output(out, run_id, need)
    with WriterLock(out) as lock, StopSignals() as stopper:
        session, stop_sim = _start_simulator(session, out, quiet)
        try:
            return _Recorder(session, out, run_id, stamp, target, quiet, stopper).run()
        except WriteFailed:
            lock.release()  # the CLI leaves at once: nobody writes the file any more
            raise
        finally:
            stop_sim()


class _Recorder:
    """One acquisition: reader threads, timeline, trigger, writer, display, and every way it stops."""

    def __init__(self, session: Session, out: Path, run_id: str, stamp: datetime, target: int | None,
                 quiet: bool, stopper: StopSignals) -> None:
        self.session, self.out, self.run_id, self.stamp = session, out, run_id, stamp
        self.target, self.stopper = target, stopper
        self.drivers = {d.name: make_driver(d, session.sample_rate_hz) for d in session.devices}
        self.timeline = Timeline(session, {k: v.sources for k, v in self.drivers.items()},
                                 {k: v.source_units for k, v in self.drivers.items()})
        self.queue: queue.Queue = queue.Queue(maxsize=QUEUE_BLOCKS)
        self.stop = threading.Event()
        self.stats = {name: ReaderStats() for name in self.drivers}
        self.names = self.timeline.names
        self.display = Display(self.names, tuple(c.channel.unit for c in session.channels), quiet)
        self.trig = None
        if session.trigger is not None:
            t = session.trigger
            self.trig = TriggerDetector(self.names.index(t.channel), t.level, t.slope,
                                        int(round(t.holdoff_s * session.sample_rate_hz)))
            if session.excitation == "impact":
                self.display.monitor = _hit_monitor(session, self.names)
                self.display.response, self.display.fs = session.channels[
                    self.display.monitor.response].channel.name, session.sample_rate_hz
        self.counts: Counter = Counter()
        self.writer: RunWriter | None = None
        self.pending: list[Event] = []  # events dated in timeline rows (row 0 = the session's first sample)
        self.written = 0
        self.waiting = session.trigger is not None and session.trigger.start
        self.start_row = 0  # timeline row stored as row 0 (the first trigger's, when the run starts on one)
        self.held: list[np.ndarray] = []  # the last pretrigger rows while waiting for the first trigger
        self.lost: set[str] = set()
        self.error = ""
        self.t_first: float | None = None  # monotonic time of the first block
        self.t_begin = time.monotonic()  # when the readers started (reset by run)
        self.lag_base = np.inf  # smallest delay of the rows behind real time seen so far (start-up latency)
        self.overrun = False
        self.disk_stopped = False
        self.pose_cols = {v: self.names.index(c) for v, c in session.pose_from.items()}
        self.pose_sums = np.zeros((len(self.pose_cols), 5))  # n, sum, sum of squares, min, max
        self.pose_sums[:, 3:] = (np.inf, -np.inf)

    # -- what the reader threads deliver ---------------------------------------------------------------
    def handle(self, item) -> None:
        if isinstance(item, Block):
            if self.t_first is None:
                self.t_first = item.received_s or time.monotonic()
            self.pending.extend(self.timeline.add(item, _clipped(item, self.drivers[item.device].limits)))
            if item.device in self.lost:
                self.lost.discard(item.device)
                self.note(item.device, "delivers again")
        elif item.kind == "error":
            raise item.error
        elif item.kind == "reconnect":
            self.pending.append(Event("reconnect", self.timeline.at_row(item.device), 1,
                                      f"{item.device}: {item.detail}"))
        elif item.kind == "lost":
            self.note(item.device, f"disconnected ({item.detail})")

    def note(self, device: str, text: str, kind: str = "note") -> None:
        self.pending.append(Event(kind, self.timeline.at_row(device), 1, f"{device}: {text}"))

    def drain(self, timeout_s: float) -> None:
        try:
            self.handle(self.queue.get(timeout=timeout_s))
            while True:
                self.handle(self.queue.get_nowait())
        except queue.Empty:
            pass

    # -- health of devices, writer and disk ----------------------------------------------------------
    def silent(self, now: float) -> set[str]:
        """Devices that delivered nothing for STALL_S (once any device delivered); newly lost ones are
        recorded, and end the session unless it continues without them.

        A device's lost-device clock starts at its own first block: one still starting up (a simulator
        importing on a cold, loaded machine) is not lost while others deliver; it has NO_DATA_TIMEOUT_S
        from the session's start to deliver, and is lost then."""
        if self.t_first is None:
            return set()
        quiet_s = {d: now - (s.last_block_s or self.t_first) for d, s in self.stats.items()}
        for d, q in quiet_s.items():
            started = self.stats[d].blocks > 0
            if d not in self.lost and (q > self.session.reconnect_timeout_s if started
                                       else now - self.t_begin > NO_DATA_TIMEOUT_S):
                self.lost.add(d)
                self.note(d, f"lost: no samples for {q:.1f} s", "device_lost")
                if not self.session.continue_on_device_loss or self.lost == set(self.drivers):
                    self.error = (f"{self.session.source}: device {d!r} lost (no samples for "
                                  f"{self.session.reconnect_timeout_s:g} s); the run holds everything before"
                                  if started else f"{self.session.source}: no samples from device {d!r} "
                                  f"within {NO_DATA_TIMEOUT_S:g} s of the start; the run holds the others'")
        return {d for d, q in quiet_s.items() if q > STALL_S}

    def check_overrun(self, now: float) -> None:
        """Compare the rows on the timeline with real time since the first block."""
        if self.t_first is None:
            return
        ahead = max(t.rows for t in self.timeline.tracks.values())
        lag = (now - self.t_first) - ahead / self.session.sample_rate_hz
        self.lag_base = min(self.lag_base, lag)
        behind = lag - self.lag_base
        if behind > OVERRUN_S and not self.overrun:
            self.overrun = True
            self.pending.append(Event("overrun", ahead, int(behind * self.session.sample_rate_hz),
                                      f"{behind:.1f} s behind real time"))
        elif behind < OVERRUN_S / 2:
            self.overrun = False
        self.display.behind_s = behind if self.overrun else 0.0

    def disk_full(self) -> bool:
        room = disk_room(self.out)
        if room >= DISK_RESERVE_BYTES:
            return False
        self.disk_stopped = True
        self.error = (f"{self.out}: disk full ({room / 1e6:.1f} MB left): stopped after "
                      f"{self.written} samples; the run is intact up to there")
        return True

    # -- storing rows ---------------------------------------------------------------------------------
    def write(self, rows: np.ndarray, row0: int) -> None:
        """Store timeline rows ``row0`` .. (waiting for the first trigger first, if so configured)."""
        session, target = self.session, self.target
        if self.trig is not None:
            t = session.trigger
            found = self.trig.find(rows, row0)
            self.pending.extend(Event("trigger", i, 1, f"{t.channel} {t.slope} {t.level:g}") for i in found)
            if self.display.monitor is not None:
                self.judged(self.display.monitor.add(rows, row0, found))
        if self.waiting:
            buf = np.vstack([*self.held, rows])
            buf0 = row0 + rows.shape[0] - buf.shape[0]
            hits = sorted(e.sample_index for e in self.pending if e.kind == "trigger")
            if not hits:
                self.held[:] = [buf[max(0, buf.shape[0] - session.trigger.pretrigger_samples):]]
                keep_from = buf0 + buf.shape[0] - self.held[0].shape[0]
                self.pending[:] = [e for e in self.pending if e.sample_index >= keep_from]
                return
            self.waiting = False
            self.start_row = max(hits[0] - session.trigger.pretrigger_samples, buf0)
            rows = buf[self.start_row - buf0:]
            self.held.clear()
        if target is not None:
            rows = rows[:target - self.written]
        if self.writer is None and rows.shape[0]:
            first = {k: v + self.start_row for k, v in self.timeline.first_index.items()}
            self.writer = _open_writer(session, self.out, self.run_id, self.stamp, rows, self.names, first)
        keep = [_within(dataclasses.replace(e, sample_index=e.sample_index - self.start_row), target)
                for e in self.pending if e.sample_index >= self.start_row
                and (target is None or e.sample_index - self.start_row < target)]
        if self.writer is None:  # nothing to store yet
            return
        self.pending.clear()
        self.guarded(lambda: (self.writer.append(rows), self.writer.add_events(keep)))
        self.written += rows.shape[0]
        self.add_pose(rows)
        self.display.rows(rows)
        for e in keep:
            self.counts[e.kind] += 1
            if e.kind == "overload":
                self.display.overloads[self.names.index(e.detail)] += e.count

    def judged(self, hits) -> None:
        """Rejected hits become notes (the verdicts show in the live view as they come)."""
        self.pending.extend(Event("note", h.row, 1, f"hit rejected: {h.reason}") for h in hits
                            if h.verdict == "rejected")
        if hits:
            self.update_display(force=True)

    def add_pose(self, rows: np.ndarray) -> None:
        """Running statistics of the encoder channels the pose is taken from (finite values only)."""
        for k, col in enumerate(self.pose_cols.values()):
            x = rows[:, col].astype(np.float64)
            x = x[np.isfinite(x)]
            if x.size:
                n, s1, s2, lo, hi = self.pose_sums[k]
                self.pose_sums[k] = (n + x.size, s1 + x.sum(), s2 + (x * x).sum(), min(lo, x.min()),
                                     max(hi, x.max()))

    def pose(self) -> tuple[dict, dict]:
        """Pose variables from their encoder channels: mean over the run, and spread (std, min, max)."""
        mean, spread = {}, {}
        for (var, _), (n, s1, s2, lo, hi) in zip(self.pose_cols.items(), self.pose_sums, strict=True):
            if n:
                m = s1 / n
                mean[var] = float(m)
                spread[var] = {"std": float(np.sqrt(max(s2 / n - m * m, 0.0))), "min": float(lo),
                               "max": float(hi), "n": int(n)}
        return mean, spread

    def guarded(self, step) -> None:
        """Run a write step; a failure becomes WriteFailed and the file is not touched again."""
        try:
            step()
        except (OSError, RuntimeError) as exc:
            reason = re.search(r"error message = '([^']*)'", str(exc))
            reason = reason.group(1) if reason else " ".join(str(exc).split())[:120]
            n = self.writer.n_samples
            self.writer = None
            raise WriteFailed(f"{self.out}: writing failed after {n} samples ({reason}); the samples "
                              "flushed before this point are intact, rows not written read as NaN") from exc

    def release(self, silent: set[str]) -> None:
        """Write the rows every delivering device has reached; silent devices get NaN up to there."""
        tl = self.timeline
        ready = tl.ready(skip=silent)
        n = ready if self.target is None or self.waiting else min(ready, self.target - self.written)
        if n <= 0:
            return
        row0 = tl.released
        for d in silent:
            tl.pad(d, row0 + n)
        self.write(tl.take(n), row0)

    # -- the session ----------------------------------------------------------------------------------
    def done(self) -> bool:
        return ((self.target is not None and self.written >= self.target) or self.stopper.event.is_set()
                or bool(self.error))

    def run(self) -> Summary:
        # a device that never opens ends the session within the reconnect timeout, or the duration if shorter
        wait_s = self.session.reconnect_timeout_s if self.target is None else min(
            self.session.reconnect_timeout_s, self.target / self.session.sample_rate_hz)
        threads = [threading.Thread(target=run_reader, name=f"reader-{name}", daemon=True,
                                    args=(drv, self.queue, self.stop, self.stats[name], wait_s))
                   for name, drv in self.drivers.items()]
        self.t_begin = next_disk = time.monotonic()
        for th in threads:
            th.start()
        try:
            while not self.done():
                self.drain(0.1)
                now = time.monotonic()
                silent = self.silent(now)
                self.release(silent)
                self.check_overrun(now)
                if now >= next_disk:
                    next_disk = now + DISK_CHECK_S
                    if self.disk_full():
                        break
                if self.timeline.released == 0 and now - self.t_begin > NO_DATA_TIMEOUT_S:
                    none = [d for d, s in self.stats.items() if s.samples == 0] or list(self.drivers)
                    raise DaqError(f"{self.session.source}: no samples from device "
                                   f"{', '.join(map(repr, none))} within {NO_DATA_TIMEOUT_S:g} s")
                self.update_display()
            self.finish(threads)
        finally:
            self.stop.set()
            self.display.close()
            if self.writer is not None:
                writer, self.writer = self.writer, None
                self.guarded_close(writer)
        extra = {"polls": self.polls()} if self.polls() else {}
        if self.pose_cols:
            mean, spread = self.pose()
            extra |= {"pose": {**self.session.pose, **mean}, "pose_spread": spread}
        if extra and self.written:
            _store_attrs(self.out, self.run_id, extra)
        return self.summary()

    def polls(self) -> dict:
        """{device: {polls, missed}} of the devices whose drivers count their polls."""
        return {name: counts for name, drv in self.drivers.items() if (counts := drv.poll_counts())}

    def finish(self, threads: list[threading.Thread]) -> None:
        """Stop the readers, store what they delivered, close open gaps, record why the run stopped."""
        self.stop.set()
        for th in threads:
            th.join(timeout=1.0)
        if not self.disk_stopped:
            self.drain(0.0)
            self.release(self.silent(time.monotonic()) if len(self.drivers) > 1 else set())
        self.pending.extend(self.timeline.close_gaps(self.timeline.released))
        if self.display.monitor is not None:
            self.judged(self.display.monitor.finish())
        unwritten = self.timeline.ready()
        why = (f"stopped by {signal.Signals(self.stopper.signum).name}" if self.stopper.signum
               else self.error)
        if why and self.writer is not None:
            self.pending.append(Event("stopped", self.timeline.released, unwritten,
                                      f"{why[:150]}; {unwritten} samples in hand not written"))
        if self.writer is not None:
            keep = [_within(dataclasses.replace(e, sample_index=max(e.sample_index - self.start_row, 0)),
                            self.target) for e in self.pending
                    if self.target is None or e.sample_index - self.start_row < self.target]
            self.pending.clear()
            self.guarded(lambda: self.writer.add_events(keep))
            self.counts.update(e.kind for e in keep)
        self.update_display(force=True)

    def guarded_close(self, writer: RunWriter) -> None:
        self.writer = writer
        self.guarded(writer.close)
        self.writer = None

    def update_display(self, force: bool = False) -> None:
        self.display.update(self.written, self.session.sample_rate_hz,
                            sum(s.dropped_blocks for s in self.stats.values()), self.counts, force=force,
                            lost=sorted(self.lost))

    def summary(self) -> Summary:
        if self.writer is None and self.written == 0:
            if self.stopper.signum:
                raise Stopped(f"{self.session.source}: stopped by "
                              f"{signal.Signals(self.stopper.signum).name} before any sample was stored",
                              self.stopper.signum)
            if self.waiting:
                t = self.session.trigger
                raise DaqError(f"{self.session.source}: trigger: no {t.slope} crossing of {t.level:g} on "
                               f"{t.channel!r}")
            raise DaqError(self.error or f"{self.session.source}: no samples arrived from "
                                         f"{', '.join(self.drivers)}")
        return Summary(self.out, self.run_id, self.written, len(self.names), self.session.sample_rate_hz,
                       self.counts, sum(s.dropped_blocks for s in self.stats.values()), self.stopper.signum,
                       self.error, self.target is not None, self.polls(),
                       tuple(d for d in self.polls() if not getattr(self.drivers[d].config, "counter", "")))

def _within(event: Event, target: int | None) -> Event:
    """``event`` with a gap's count cut at the run's last row ``target`` (rows beyond are not stored)."""
    if target is None or event.kind != "gap":
        return event
    return dataclasses.replace(event, count=min(event.count, target - event.sample_index))


def _store_attrs(out: Path, run_id: str, attrs: dict) -> None:
    """Set the run's attributes ``attrs`` (each as JSON) once the writer has closed the file: the pose
    (encoder means) and ``pose_spread`` (per variable std, min, max and number of samples), or the
    ``polls`` a driver counted."""
    import h5py

    with signals_deferred(), h5py.File(out, "r+") as f:  # opened and closed whole, Ctrl-C or not
        group = f[f"runs/{run_id}"].attrs
        for key, value in attrs.items():
            group[key] = json.dumps(value)


def device_attrs(session: Session) -> dict[str, str]:
    """Which device each channel came from, for the run's attributes (JSON texts): ``devices`` (name:
    protocol), ``device_config`` (name: protocol and the scalar fields of its configuration - port, baud,
    host, interface, DBC file ...) and ``channel_sources`` (channel: [device, source]), so a run says
    where each column was read even after the session file has changed.

    Examples
    --------
    >>> from flexmodal.daq.session import load_session
    >>> attrs = device_attrs(load_session("examples/sessions/serial-sim.toml"))
    >>> json.loads(attrs["channel_sources"])["F"], json.loads(attrs["device_config"])["adc"]["baud"]
    (['adc', 'ch0'], 3000000)
    """
    def scalars(config: object) -> dict:
        if not dataclasses.is_dataclass(config):
            return {}
        values = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
        return {k: v for k, v in values.items() if isinstance(v, str | int | float)}   # bool is an int

    return {"devices": json.dumps({d.name: d.protocol for d in session.devices}),
            "device_config": json.dumps({d.name: {"protocol": d.protocol, **scalars(d.config)}
                                         for d in session.devices}),
            "channel_sources": json.dumps({c.channel.name: [c.device, c.source] for c in session.channels})}


def _open_writer(session: Session, out: Path, run_id: str, stamp: datetime, first_rows: np.ndarray,
                 names: tuple[str, ...], first_index: dict) -> RunWriter:
    """Create the run; a pose taken from encoder channels starts as their first sample (degrees) and
    becomes their mean over the run when it ends (a killed run keeps the first sample)."""
    pose = dict(session.pose)
    for var, channel in session.pose_from.items():
        x = first_rows[:, names.index(channel)]
        if np.isfinite(x).any():
            pose[var] = float(x[np.isfinite(x)][0])
    attrs = {"session": str(session.source), "notes": session.notes, "first_index": json.dumps(first_index),
             **device_attrs(session)}
    if session.trigger is not None:
        attrs["trigger"] = json.dumps(dataclasses.asdict(session.trigger))
    return RunWriter(out, run_id, sample_rate_hz=session.sample_rate_hz,
                     channels=tuple(c.channel for c in session.channels), excitation=session.excitation,
                     pose=pose, start_time=stamp.isoformat(timespec="microseconds"), attrs=attrs,
                     flush_interval_s=0.5)
