"""`flexmodal acquire`: reader threads -> one bounded queue -> one writer appending to the run store.

Each device runs in its own reader thread (daq.devices.run_reader) which puts blocks on a bounded
queue; the main thread places them on the session timeline (daq.timeline), records faults as events,
appends rows to the HDF5 run (daq.store.RunWriter, flushed at least every 0.5 s) and refreshes a live
display on stderr.  It stops at the duration or on Ctrl-C with everything flushed.  If the session has a
``[simulator]``, that simulator is started first (a `flexmodal sim serve` child process, or for a CAN
virtual bus a thread in this process) and stopped at the end.
"""

from __future__ import annotations

import dataclasses
import json
import os
import queue
import re
import select
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from flexmodal.daq.devices import Block, ReaderStats, make_driver, run_reader
from flexmodal.daq.errors import DaqError
from flexmodal.daq.session import SIMULATOR_PORT, Session
from flexmodal.daq.store import Event, RunWriter, list_runs
from flexmodal.daq.timeline import Timeline

QUEUE_BLOCKS = 4096


class WriteFailed(DaqError):
    """The run store could not be written (disk full, I/O error); the file holds the last flush.

    The HDF5 library is left in an unusable state for this file, so the CLI exits at once without
    closing it (closing would try to write again and can crash).
    """
SIM_START_TIMEOUT_S = 60.0
NO_DATA_TIMEOUT_S = 15.0  # a session whose devices deliver nothing for this long is an error


@dataclass(frozen=True)
class Summary:
    path: Path
    run_id: str
    n_samples: int
    n_channels: int
    sample_rate_hz: float
    events: Counter
    dropped_blocks: int

    def line(self) -> str:
        ev = ", ".join(f"{k} {v}" for k, v in sorted(self.events.items())) or "none"
        return (f"{self.path}\t{self.run_id}\t{self.n_samples} samples x {self.n_channels} channels at "
                f"{self.sample_rate_hz:g} Hz ({self.n_samples / self.sample_rate_hz:.2f} s)\tevents: {ev}")


class SimulatorProcess:
    """The session's own simulator: `flexmodal sim serve` as a child; its first stdout line: the endpoint."""

    def __init__(self, session: Session, quiet: bool) -> None:
        sim = session.simulator
        dev = next(d for d in session.devices if d.protocol == sim.protocol)
        cmd = [sys.executable, "-m", "flexmodal", "sim", "serve", "--protocol", sim.protocol,
               "--test", sim.test,
               "--rate", repr(session.sample_rate_hz), "--exit-with-parent"]
        if sim.rig:
            cmd += ["--rig", sim.rig]
        if sim.protocol == "serial":
            cmd += ["--framing", dev.framing]
        if sim.protocol == "modbus":
            cmd += ["--transport", dev.transport]
        cmd += list(sim.args)
        repo = Path(__file__).resolve().parents[1]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, cwd=repo, text=True, start_new_session=True,
                                     stderr=subprocess.DEVNULL if quiet else None)
        ready, _, _ = select.select([self.proc.stdout], [], [], SIM_START_TIMEOUT_S)
        line = self.proc.stdout.readline().strip() if ready else ""
        if not line:
            self.stop()
            raise DaqError(f"{session.source}: simulator ({' '.join(cmd[3:])}) did not start")
        self.endpoint = line

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def _with_endpoint(session: Session, endpoint: str) -> Session:
    """The session with the '@simulator' placeholder replaced by the simulator's endpoint."""
    devices = []
    for d in session.devices:
        if d.protocol == "modbus" and d.transport == "tcp" and d.port == SIMULATOR_PORT:
            host, port = endpoint.rsplit(":", 1)
            d = dataclasses.replace(d, host=host, tcp_port=int(port), port=port)
        elif d.port == SIMULATOR_PORT:
            d = dataclasses.replace(d, port=endpoint)
        elif d.channel == SIMULATOR_PORT:
            d = dataclasses.replace(d, channel=endpoint)
        devices.append(d)
    return dataclasses.replace(session, devices=tuple(devices))


def _start_simulator(session: Session, quiet: bool):
    """Start the session's simulator; returns (session with endpoints filled in, stop function)."""
    sim = session.simulator
    if sim is None:
        return session, lambda: None
    virtual = [d for d in session.devices if d.protocol == "can" and d.interface == "virtual"]
    if sim.protocol == "can" and virtual:
        from flexmodal.fixtures.sim_can import start_virtual

        return session, start_virtual(virtual[0].channel, sim, session.sample_rate_hz)
    proc = SimulatorProcess(session, quiet)
    return _with_endpoint(session, proc.endpoint), proc.stop


class Display:
    """Live status on stderr: elapsed, samples, rate, drops, faults and per-channel level / overloads."""

    def __init__(self, names: tuple[str, ...], units: tuple[str, ...], quiet: bool) -> None:
        self.names, self.units = names, units
        self.live = None
        self.t0 = time.monotonic()
        self.level = np.zeros(len(names))
        self.peak = np.zeros(len(names))
        self.overloads = np.zeros(len(names), int)
        self._last = 0.0
        if not quiet:
            from rich.console import Console
            from rich.live import Live

            self.live = Live(console=Console(stderr=True), refresh_per_second=4, transient=False)
            self.live.start()

    def rows(self, rows: np.ndarray) -> None:
        if rows.size:
            self.level = np.sqrt(np.nanmean(rows**2, axis=0))
            self.peak = np.maximum(self.peak, np.nanmax(np.abs(rows), axis=0, initial=0))

    def update(self, n_samples: int, rate_hz: float, dropped: int, events: Counter,
               force: bool = False) -> None:
        if self.live is None or (not force and time.monotonic() - self._last < 0.25):
            return
        from rich.table import Table

        self._last = time.monotonic()
        elapsed = time.monotonic() - self.t0
        table = Table(title=f"acquiring  {elapsed:6.1f} s   {n_samples} samples   "
                            f"{n_samples / max(elapsed, 1e-9):,.0f} S/s (nominal {rate_hz:g})   "
                            f"drops {dropped}   corrupt {events['corrupt']}   gaps {events['gap']}   "
                            f"reconnects {events['reconnect']}   triggers {events['trigger']}")
        for col in ("channel", "unit", "rms", "peak", "overloads"):
            table.add_column(col, justify="right" if col not in ("channel", "unit") else "left")
        for i, name in enumerate(self.names):
            style = "bold red" if self.overloads[i] else None
            table.add_row(name, self.units[i], f"{self.level[i]:.4g}", f"{self.peak[i]:.4g}",
                          str(self.overloads[i]), style=style)
        self.live.update(table)

    def close(self) -> None:
        if self.live is not None:
            self.live.stop()


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


def _clipped(block: Block, limits) -> np.ndarray | None:
    if limits is None:
        return None
    lo, hi = limits
    return (block.values <= lo) | (block.values >= hi)


def _check_output(path: Path, run_id: str) -> None:
    if not path.parent.is_dir():
        raise DaqError(f"{path}: directory {path.parent} does not exist")
    if not os.access(path.parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise DaqError(f"{path}: not writable")
    if path.exists() and run_id in list_runs(path):
        raise DaqError(f"{path}: run {run_id!r} already exists")


def acquire(session: Session, out: str | Path, *, duration_s: float | None = None, quiet: bool = False,
            run_id: str | None = None) -> Summary:
    """Run an acquisition session into run ``run_id`` of ``out``; returns its summary."""
    out = Path(out)
    stamp = datetime.now(UTC)
    run_id = run_id or session.run_id or f"{session.source.stem}-{stamp:%Y%m%dT%H%M%S}"
    _check_output(out, run_id)
    duration_s = duration_s if duration_s is not None else session.duration_s
    target = None if duration_s is None else int(round(duration_s * session.sample_rate_hz))
    session, stop_sim = _start_simulator(session, quiet)
    try:
        return _record(session, out, run_id, stamp, target, quiet)
    finally:
        stop_sim()


def _record(session: Session, out: Path, run_id: str, stamp: datetime, target: int | None,
            quiet: bool) -> Summary:
    drivers = {d.name: make_driver(d, session) for d in session.devices}
    timeline_ = Timeline(session, {k: v.sources for k, v in drivers.items()})
    q: queue.Queue = queue.Queue(maxsize=QUEUE_BLOCKS)
    stop = threading.Event()
    stats = {name: ReaderStats() for name in drivers}
    threads = [threading.Thread(target=run_reader, args=(drv, q, stop, stats[name]), name=f"reader-{name}",
                                daemon=True) for name, drv in drivers.items()]
    names = timeline_.names
    display = Display(names, tuple(c.channel.unit for c in session.channels), quiet)
    trig = None
    if session.trigger is not None:
        t = session.trigger
        trig = TriggerDetector(names.index(t.channel), t.level, t.slope,
                               int(round(t.holdoff_s * session.sample_rate_hz)))
    counts: Counter = Counter()
    writer: RunWriter | None = None
    pending: list[Event] = []  # events dated in timeline rows (row 0 = the first sample of the session)
    written = 0
    waiting = session.trigger is not None and session.trigger.start
    start_row = 0  # timeline row stored as row 0 (set at the first trigger when the run starts on one)
    held: list[np.ndarray] = []  # the last pretrigger rows while waiting for the first trigger
    t_begin = time.monotonic()
    for th in threads:
        th.start()

    def handle(item) -> None:
        if isinstance(item, Block):
            pending.extend(timeline_.add(item, _clipped(item, drivers[item.device].limits)))
        elif item.kind == "error":
            raise item.error
        elif item.kind == "reconnect":
            pending.append(Event("reconnect", timeline_.at_row(item.device), 1,
                                 f"{item.device}: {item.detail}"))
        elif item.kind == "lost":
            pending.append(Event("note", timeline_.at_row(item.device), 1,
                                 f"{item.device}: disconnected ({item.detail})"))

    def write(rows: np.ndarray, row0: int) -> None:
        """Store timeline rows ``row0`` .. (waiting for the first trigger first, if so configured)."""
        nonlocal writer, written, waiting, start_row
        if trig is not None:
            t = session.trigger
            pending.extend(Event("trigger", i, 1, f"{t.channel} {t.slope} {t.level:g}")
                           for i in trig.find(rows, row0))
        if waiting:
            buf = np.vstack([*held, rows])
            buf0 = row0 + rows.shape[0] - buf.shape[0]
            hits = sorted(e.sample_index for e in pending if e.kind == "trigger")
            if not hits:
                held[:] = [buf[max(0, buf.shape[0] - session.trigger.pretrigger_samples):]]
                pending[:] = [e for e in pending if e.sample_index >= buf0 + buf.shape[0] - held[0].shape[0]]
                return
            waiting = False
            start_row = max(hits[0] - session.trigger.pretrigger_samples, buf0)
            rows = buf[start_row - buf0:]
            held.clear()
        if target is not None:
            rows = rows[:target - written]
        if writer is None and rows.shape[0]:
            first = {k: v + start_row for k, v in timeline_.first_index.items()}
            writer = _open_writer(session, out, run_id, stamp, rows, names, first)
        keep = [dataclasses.replace(e, sample_index=e.sample_index - start_row) for e in pending
                if e.sample_index >= start_row and (target is None or e.sample_index - start_row < target)]
        if writer is None:  # nothing to store yet
            return
        pending.clear()
        try:
            writer.append(rows)
            writer.add_events(keep)
        except (OSError, RuntimeError) as exc:
            reason = re.search(r"error message = '([^']*)'", str(exc))
            reason = reason.group(1) if reason else " ".join(str(exc).split())[:120]
            raise WriteFailed(f"{out}: writing failed after {writer.n_samples} samples ({reason}); "
                              "the samples flushed before this point are intact") from exc
        written += rows.shape[0]
        display.rows(rows)
        for e in keep:
            counts[e.kind] += 1
            if e.kind == "overload":
                display.overloads[names.index(e.detail)] += e.count

    def due_rows() -> int:
        return timeline_.ready() if target is None or waiting else min(timeline_.ready(), target - written)

    try:
        try:
            while target is None or written < target:
                try:
                    handle(q.get(timeout=0.1))
                    while True:
                        handle(q.get_nowait())
                except queue.Empty:
                    pass
                n = due_rows()
                if n > 0:
                    row0 = timeline_.released
                    write(timeline_.take(n), row0)
                elif timeline_.released == 0 and time.monotonic() - t_begin > NO_DATA_TIMEOUT_S:
                    silent = [d for d, s in stats.items() if s.samples == 0] or list(drivers)
                    raise DaqError(f"{session.source}: no samples from device {', '.join(map(repr, silent))} "
                                   f"within {NO_DATA_TIMEOUT_S:g} s")
                display.update(written, session.sample_rate_hz, sum(s.dropped_blocks for s in stats.values()),
                               counts)
        except KeyboardInterrupt:
            pass
        stop.set()
        for th in threads:
            th.join(timeout=5)
        while True:  # what the readers delivered before they stopped
            try:
                item = q.get_nowait()
            except queue.Empty:
                break
            if isinstance(item, Block):
                handle(item)
        row0 = timeline_.released
        write(timeline_.take(max(due_rows(), 0)), row0)
        display.update(written, session.sample_rate_hz, sum(s.dropped_blocks for s in stats.values()),
                       counts, force=True)
    except WriteFailed:
        writer = None  # do not touch the file again
        raise
    finally:
        stop.set()
        display.close()
        if writer is not None:
            writer.close()
    if writer is None and waiting:
        t = session.trigger
        raise DaqError(f"{session.source}: trigger: no {t.slope} crossing of {t.level:g} on {t.channel!r}")
    if writer is None:
        raise DaqError(f"{session.source}: no samples arrived from {', '.join(drivers)}")
    return Summary(out, run_id, written, len(names), session.sample_rate_hz, counts,
                   sum(s.dropped_blocks for s in stats.values()))


def _open_writer(session: Session, out: Path, run_id: str, stamp: datetime, first_rows: np.ndarray,
                 names: tuple[str, ...], first_index: dict) -> RunWriter:
    """Create the run; a pose taken from encoder channels uses their first sample (degrees)."""
    pose = dict(session.pose)
    for var, channel in session.pose_from.items():
        pose[var] = float(first_rows[0, names.index(channel)])
    attrs = {"session": str(session.source), "notes": session.notes, "first_index": json.dumps(first_index),
             "devices": json.dumps({d.name: d.protocol for d in session.devices})}
    if session.trigger is not None:
        attrs["trigger"] = json.dumps(dataclasses.asdict(session.trigger))
    return RunWriter(out, run_id, sample_rate_hz=session.sample_rate_hz,
                     channels=tuple(c.channel for c in session.channels), excitation=session.excitation,
                     pose=pose, start_time=stamp.isoformat(timespec="microseconds"), attrs=attrs,
                     flush_interval_s=0.5)
