"""HDF5 run store (docs/hdf5-format.md): write runs block by block with SWMR, list them and read them back.

A file holds one or more runs under ``/runs/<run_id>``.  Each run has a chunked, resizable ``samples``
dataset [n_samples, n_channels] in physical units, a ``channels`` compound table, a resizable
``events`` compound table and the attributes ``sample_rate_hz``, ``start_time`` (ISO 8601),
``excitation`` and ``pose`` (JSON object string).  The writer opens the file with
``libver="latest"``, creates every dataset of the run, then switches to SWMR mode, so another process
can read the run while it grows (``h5py.File(path, "r", swmr=True)``) and a killed writer leaves a
readable file holding everything up to the last flush (at most ``flush_interval_s`` old).  Strings in
the tables are fixed-length UTF-8 because variable-length data cannot be appended under SWMR.
See docs/hdf5-format.md.
"""

from __future__ import annotations

import errno
import json
import os
import re
import resource
import time
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

import h5py
import numpy as np

from flexmodal.checked_io.output import hdf5_output, signals_deferred
from flexmodal.checked_io.text import available_memory_bytes, natural_order, nfc, one_line, regular_file
from flexmodal.daq.errors import DaqError
from flexmodal.daq.h5file import LOCKED, locked, open_read
from flexmodal.daq.run_schema import (
    CHANNEL_FIELDS,
    CHANNEL_KINDS,
    EVENT_DETAIL_BYTES,
    EVENT_DTYPE,
    EVENT_KINDS,
    EXCITATIONS,
    MAX_SAMPLE_RATE_HZ,
    check_run_group,
    check_run_id,
    external_link_on_path,
    kind_unit_fault,
    member,
    sample_rate_ok,
    sensitivity_fault,
    utf8,
)

CHUNK_BYTES = 1 << 20  # target size of one samples chunk
CHUNK_CACHE_BYTES = 16 << 20  # room for partly filled chunks, so appends never re-read from disk
WRITE_RESERVE_BYTES = 64 << 10  # room kept for HDF5 metadata: a new chunk leaving less is not written


@dataclass(frozen=True)
class Channel:
    """One measured channel: ``sensitivity`` is in ``sensitivity_unit`` (e.g. 10.2 mV/g, 2.25 pC/N)."""

    name: str
    kind: str
    unit: str
    sensitivity: float = 1.0
    sensitivity_unit: str = ""
    location: str = ""
    direction: str = ""

    def __post_init__(self) -> None:
        if not self.name:
            raise DaqError("channel: empty name")
        if self.kind not in CHANNEL_KINDS:
            raise DaqError(f"channel {self.name!r}: kind {self.kind!r} is not one of "
                           f"{', '.join(CHANNEL_KINDS)}")
        fault = kind_unit_fault(self.kind, self.unit) or sensitivity_fault(self.sensitivity)
        if fault:   # a force in m/s^2 made FRFs of two accelerations, stored and shown as accelerance
            raise DaqError(f"channel {self.name!r}: {fault}")


@dataclass(frozen=True)
class Event:
    """Something that happened at ``sample_index`` of a run; ``count`` samples or frames involved."""

    kind: str
    sample_index: int
    count: int = 1
    detail: str = ""

    def __post_init__(self) -> None:
        if self.kind not in EVENT_KINDS:
            raise DaqError(f"event kind {self.kind!r} is not one of {', '.join(EVENT_KINDS)}")
        if self.sample_index < 0 or self.count < 0:
            raise DaqError(f"event {self.kind}: negative sample_index or count")


@dataclass(frozen=True)
class Run:
    """A stored run read back by :func:`read_run`; ``samples`` [n_samples, n_channels] physical units."""

    path: Path
    run_id: str
    sample_rate_hz: float
    start_time: str
    excitation: str
    pose: dict
    channels: tuple[Channel, ...]
    events: tuple[Event, ...]
    samples: np.ndarray
    attrs: dict = field(default_factory=dict)


def _channel_table(channels: tuple[Channel, ...]) -> np.ndarray:
    """Channels as a compound array; string widths fit the longest UTF-8 value (at least 16 bytes)."""
    widths = {
        f: max(16, *(len(str(getattr(c, f)).encode()) for c in channels))
        for f in CHANNEL_FIELDS if f != "sensitivity"
    }
    dtype = np.dtype([(f, "f8") if f == "sensitivity" else (f, utf8(widths[f])) for f in CHANNEL_FIELDS])
    table = np.zeros(len(channels), dtype=dtype)
    for f in CHANNEL_FIELDS:
        values = [getattr(c, f) for c in channels]
        table[f] = values if f == "sensitivity" else [str(v).encode() for v in values]
    return table



def disk_room(path: Path) -> int:
    """Bytes ``path`` can still grow by: free space of its file system (for unprivileged users),
    capped by the process's file size limit (RLIMIT_FSIZE)."""
    st = os.statvfs(path.parent)
    room = st.f_bavail * st.f_frsize
    limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if limit != resource.RLIM_INFINITY:
        room = min(room, limit - (path.stat().st_size if path.exists() else 0))
    return int(room)


def _truncateutf8(text: str, n_bytes: int) -> bytes:
    return text.encode()[:n_bytes].decode("utf-8", "ignore").encode()


def _iso_now() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds")


class RunWriter:
    """Append one run to an HDF5 file (created if missing) under SWMR; a context manager.

    ``append(block)`` takes [n, n_channels] physical-unit samples; data and events are flushed to disk
    at least every ``flush_interval_s`` seconds (and on ``flush()``/``close()``).  ``attrs`` are extra
    run attributes (numbers or strings; anything else is stored as JSON).
    """

    def __init__(self, path: str | Path, run_id: str, *, sample_rate_hz: float, channels, excitation: str,
                 pose: dict, start_time: str | None = None, attrs: dict | None = None,
                 dtype: str = "float32", flush_interval_s: float = 0.5) -> None:
        self.path = Path(path)
        self.run_id = str(run_id)
        self.channels = tuple(channels)
        self._validate(sample_rate_hz, excitation, pose)
        self.n_channels = len(self.channels)
        self.flush_interval_s = float(flush_interval_s)
        self._file: h5py.File | None = None
        if self.path.parent.is_dir():   # else _open names the missing folder
            self._room(0)   # the run's layout is HDF5 metadata too: on a full disk it failed inside HDF5
            # and the interpreter crashed at exit (demo --out on a 64 kB file system: -11 after its line)
        try:  # a Ctrl-C while the file opens or the run is laid out is held, then the file is closed
            with signals_deferred():
                self._file = self._open()
                group = self._file.require_group("runs").create_group(self.run_id)
                group.attrs["sample_rate_hz"] = float(sample_rate_hz)
                group.attrs["start_time"] = start_time or _iso_now()
                group.attrs["excitation"] = excitation
                group.attrs["pose"] = json.dumps(pose)
                for key, value in (attrs or {}).items():
                    ok = isinstance(value, (str, int, float, bool, np.number))
                    group.attrs[key] = value if ok else json.dumps(value)
                group.create_dataset("channels", data=_channel_table(self.channels))
                rows = int(max(256, min(65536, CHUNK_BYTES // (np.dtype(dtype).itemsize * self.n_channels))))
                self._samples = group.create_dataset(
                    "samples", shape=(0, self.n_channels), maxshape=(None, self.n_channels),
                    chunks=(rows, self.n_channels), dtype=dtype, fillvalue=np.nan)  # never-written rows: NaN
                self._events = group.create_dataset("events", shape=(0,), maxshape=(None,), chunks=(256,),
                                                    dtype=EVENT_DTYPE)
                self._file.swmr_mode = True
        except BaseException:
            if self._file is not None:
                self._file.close()
            raise
        self.n_samples = 0
        self._n_events = 0
        self._last_flush = time.monotonic()
        self._tail = np.empty((rows, self.n_channels), dtype)  # rows not yet on disk as a whole chunk
        self._tail_rows = 0
        self._chunk_rows = rows
        self._disk_rows = 0  # rows stored as whole chunks (a multiple of the chunk length)
        self._failed = False  # a write failed (full disk, I/O error): the file is only closed now
        self._tail_stored = False  # the partly filled chunk already has its room on disk (a flush)

    def _room(self, n_bytes: int) -> None:
        """OSError (ENOSPC) naming the file when writing ``n_bytes`` would leave less than
        :data:`WRITE_RESERVE_BYTES` on its disk: a write HDF5 itself finds failing leaves its caches
        dirty, the file cannot be closed cleanly and the interpreter crashed at exit."""
        room, need = disk_room(self.path), n_bytes + WRITE_RESERVE_BYTES
        if room < need:
            st = os.statvfs(self.path.parent)
            full = st.f_bavail * st.f_frsize < need   # else the file size limit (ulimit -f) is what binds
            reason = "No space left on device" if full else "File too large (the file size limit, ulimit -f)"
            left = f"{max(room, 0) / 1e6:.2f} MB left, {need / 1e6:.2f} MB needed"
            raise OSError(errno.ENOSPC if full else errno.EFBIG, f"{reason}: {left}", str(self.path))

    @contextmanager
    def _writing(self) -> Iterator[None]:
        """Mark the writer failed when a write inside raises (its buffers no longer match the file)."""
        if self._failed:
            raise DaqError(f"{self.path}: run {self.run_id!r}: an earlier write failed; nothing more is "
                           "written")
        try:
            yield
        except BaseException:
            self._failed = True
            raise

    def _validate(self, sample_rate_hz: float, excitation: str, pose: dict) -> None:
        where = f"{self.path}: run {self.run_id!r}"
        check_run_id(self.run_id, f"{self.path}: run id")
        if not self.channels or not all(isinstance(c, Channel) for c in self.channels):
            raise DaqError(f"{where}: channels must be a non-empty sequence of Channel")
        names = [c.name for c in self.channels]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise DaqError(f"{where}: duplicate channel name {dup[0]!r}")
        if not sample_rate_ok(float(sample_rate_hz)):
            raise DaqError(f"{where}: sample_rate_hz must be > 0 and <= {MAX_SAMPLE_RATE_HZ:g} Hz, got "
                           f"{sample_rate_hz}")
        if excitation not in EXCITATIONS:
            raise DaqError(f"{where}: excitation {excitation!r} is not one of {', '.join(EXCITATIONS)}")
        if not isinstance(pose, dict):
            raise DaqError(f"{where}: pose must be a dict, got {type(pose).__name__}")

    def _open(self) -> h5py.File:
        if self.path.exists() or self.path.is_symlink():  # a FIFO or device would block or be destroyed
            regular_file(self.path, DaqError, "run file")
            if self.path.exists():
                hdf5_output(self.path, DaqError, "run file")
        try:
            f = h5py.File(self.path, "a", libver="latest", rdcc_nbytes=CHUNK_CACHE_BYTES)
        except OSError as exc:
            if not self.path.parent.is_dir():
                raise DaqError(f"{self.path}: directory {self.path.parent} does not exist") from exc
            if locked(exc):
                raise DaqError(f"{self.path}: {LOCKED}") from None
            if "already open for write" in str(exc):
                raise DaqError(f"{self.path}: file is open by another writer or was not closed cleanly "
                               "(readable as it is; if no writer is running, `flexmodal acquire --recover` "
                               "or flexmodal.daq.h5file.recover() makes it writable)") from exc
            raise DaqError(f"{self.path}: cannot open for writing ({exc})") from exc
        try:   # member by member: 'runs/r1' in f opens an external link at 'runs' (a FIFO: hang)
            runs = member(f, "runs", str(self.path))
            exists = isinstance(runs, h5py.Group) and runs.get(self.run_id, getlink=True) is not None
        except DaqError:
            f.close()
            raise
        if exists:
            f.close()
            raise DaqError(f"{self.path}: run {self.run_id!r} already exists")
        return f

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Close; a write that failed inside the block or in the close (a full disk, an I/O error: h5py
        raises OSError or RuntimeError) becomes one DaqError naming the file, and the file is closed."""
        try:
            self.close()
        except (OSError, RuntimeError) as err:
            if exc is None:
                raise self._write_error(err) from None
        if isinstance(exc, OSError | RuntimeError):
            raise self._write_error(exc) from None

    def _write_error(self, exc: BaseException) -> DaqError:
        found = re.search(r"error message = '([^']*)'", str(exc))
        reason = found.group(1) if found else (getattr(exc, "strerror", None) or one_line(exc))
        return DaqError(f"{self.path}: run {self.run_id!r}: writing failed after {self.n_samples} samples "
                        f"({reason}); what was flushed before is intact")

    def append(self, block: np.ndarray) -> None:
        """Append samples [n, n_channels] (physical units).

        Rows are gathered into whole chunks, which go to disk with ``write_direct_chunk`` (no chunk
        cache, no read-modify-write); a partly filled chunk is written at each flush.
        """
        block = np.asarray(block, dtype=self._tail.dtype)
        if block.ndim != 2 or block.shape[1] != self.n_channels:
            raise DaqError(f"{self.path}: run {self.run_id!r}: block shape {block.shape} is not "
                           f"[n, {self.n_channels}]")
        i, n = 0, block.shape[0]
        with self._writing():
            while i < n:  # one step per chunk (about 1 MiB)
                k = min(self._chunk_rows - self._tail_rows, n - i)
                self._tail[self._tail_rows:self._tail_rows + k] = block[i:i + k]
                self._tail_rows += k
                i += k
                if self._tail_rows == self._chunk_rows:
                    end = self._disk_rows + self._chunk_rows
                    if self._samples.shape[0] < end:
                        self._samples.resize(end, axis=0)
                    self._room(0 if self._tail_stored else self._tail.nbytes)
                    self._samples.id.write_direct_chunk((self._disk_rows, 0), self._tail)
                    self._disk_rows, self._tail_rows, self._tail_stored = end, 0, False
            self.n_samples += n
            self._maybe_flush()

    def add_event(self, event: Event) -> None:
        """Record an event (written at once, flushed with the samples)."""
        self.add_events((event,))

    def add_events(self, events) -> None:
        """Record several events in one resize."""
        with self._writing():
            events = tuple(events)
            if not events:
                return
            rec = np.zeros(len(events), dtype=EVENT_DTYPE)
            rec["kind"] = [e.kind.encode() for e in events]
            rec["sample_index"] = [e.sample_index for e in events]
            rec["count"] = [e.count for e in events]
            rec["detail"] = [_truncateutf8(e.detail, EVENT_DETAIL_BYTES) for e in events]
            self._events.resize(self._n_events + len(events), axis=0)
            self._events[self._n_events:] = rec
            self._n_events += len(events)
            self._maybe_flush()

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Make everything appended so far visible to readers and durable against a crash."""
        with self._writing():
            self._room(0 if self._tail_stored or not self._tail_rows else self._tail.nbytes)
            if self._samples.shape[0] < self.n_samples:
                self._samples.resize(self.n_samples, axis=0)
            if self._tail_rows:
                self._samples[self._disk_rows:self.n_samples] = self._tail[:self._tail_rows]
                self._tail_stored = True
            self._samples.flush()
            self._events.flush()
            self._file.flush()
            self._last_flush = time.monotonic()

    def close(self) -> None:
        with signals_deferred():  # the last flush and the close complete, Ctrl-C or not
            if self._file.id.valid:
                try:
                    if not self._failed:
                        self.flush()
                finally:
                    self._close_file()

    def _close_file(self) -> None:
        """Close the file; after a failed write quietly (the failure is what is reported), with the
        datasets closed first: left to the garbage collector, their ids crashed the interpreter."""
        if not self._failed:
            self._file.close()
            return
        for d in (self._samples, self._events):
            try:
                d.id.close()
            except (OSError, RuntimeError, ValueError):
                pass
        try:
            self._file.close()
        except (OSError, RuntimeError, ValueError):
            pass


def list_runs(path: str | Path) -> list[str]:
    """Run ids stored in ``path`` in natural order (``theta30`` before ``theta120``).  A run group
    reached under several names (an HDF5 hard or soft link to another run) is listed once, under its
    first name: it is one run, not two."""
    with open_read(path) as f:
        runs = member(f, "runs", str(path))
        if runs is not None and not isinstance(runs, h5py.Group):
            raise DaqError(f"{path}: '/runs' is not a group of runs")
        ids, seen = [], set()
        for name in natural_order(runs.keys()) if runs is not None else []:
            try:
                obj = runs[name] if external_link_on_path(runs, name) is None else None   # never another file
            except (KeyError, RuntimeError, OSError, ValueError):  # a broken link: reading it names it
                obj = None
            if obj is not None and obj.id in seen:
                continue
            if obj is not None:
                seen.add(obj.id)
            ids.append(name)
        return ids


def _text(value) -> str:
    """A stored text as str, in Unicode normal form C (as daq.run_schema checks names and
    checked_io.text reads tables: a sensor name spelt decomposed is the rig's and the table's name)."""
    return nfc(value.decode() if isinstance(value, bytes) else str(value))


@contextmanager
def open_run(path: str | Path, run_id: str) -> Iterator[Run]:
    """One run with its ``samples`` left on disk: an h5py dataset, valid inside the ``with`` block
    (read it in blocks, e.g. ``samples[a:b]``, so memory does not grow with the record).  The run's
    structure is checked first (:func:`flexmodal.daq.run_schema.check_run_group`)."""
    with open_read(path) as f:
        runs = member(f, "runs", str(path))
        g = member(runs, run_id, f"{path}: run {run_id!r}") if isinstance(runs, h5py.Group) else None
        if g is None:
            known = ", ".join(sorted(runs)) if isinstance(runs, h5py.Group) else "none"
            raise DaqError(f"{path}: no run {run_id!r} (runs: {known})")
        check_run_group(g, f"{path}: run {run_id!r}")
        try:
            run = _checked_run(g, Path(path), run_id)
        except DaqError as exc:  # a channel or event record with a value out of its vocabulary
            raise DaqError(f"{path}: run {run_id!r}: {exc}") from None
        except (OSError, UnicodeDecodeError) as exc:  # a damaged chunk, a field that is not UTF-8
            raise DaqError(f"{path}: run {run_id!r}: cannot read ({_reason(exc)})") from None
        yield run


def _reason(exc: Exception) -> str:
    return " ".join(str(exc).split())[:200]


def _checked_run(g: h5py.Group, path: Path, run_id: str) -> Run:
    """The run in group ``g`` (structure already checked); ``samples`` stays an h5py dataset."""
    table = g["channels"][()]
    channels = tuple(
        Channel(**{k: float(r[k]) if k == "sensitivity" else _text(r[k]) for k in CHANNEL_FIELDS})
        for r in table)
    events = tuple(Event(_text(r["kind"]), int(r["sample_index"]), int(r["count"]), _text(r["detail"]))
                   for r in g["events"][()])
    attrs = {k: (_text(v) if isinstance(v, bytes) else v) for k, v in g.attrs.items()}
    return Run(path=path, run_id=run_id, sample_rate_hz=float(attrs.pop("sample_rate_hz")),
               start_time=_text(attrs.pop("start_time")), excitation=_text(attrs.pop("excitation")),
               pose=json.loads(attrs.pop("pose")), channels=channels, events=events,
               samples=g["samples"], attrs=attrs)


def read_run(path: str | Path, run_id: str) -> Run:
    """Read one run completely into memory (refused when its samples would not fit: stream them with
    :func:`open_run`)."""
    with open_run(path, run_id) as run:
        need, room = run.samples.size * run.samples.dtype.itemsize, available_memory_bytes()
        if need > room // 2:
            raise DaqError(f"{path}: run {run_id!r}: {need / 2**30:.1f} GiB of samples do not fit in the "
                           f"{room / 2**30:.1f} GiB of memory available (frf streams a run in blocks)")
        try:
            return replace(run, samples=run.samples[()])
        except OSError as exc:  # a damaged chunk
            raise DaqError(f"{path}: run {run_id!r}: cannot read the samples ({_reason(exc)})") from None


def run_entries(runs: object) -> list:
    """``runs`` as a list of run entries, or TypeError when it is one path (a string would be taken
    letter by letter, each letter a file) or not a sequence at all."""
    if isinstance(runs, str | bytes | os.PathLike) or not isinstance(runs, Iterable):
        raise TypeError(f"runs must be a list of run entries (paths, 'FILE::RUN_ID' or (path, run id)), "
                        f"got {type(runs).__name__} {runs!r}: for one run file write [{runs!r}]")
    return list(runs)


def expand_runs(runs: Sequence[str | Path | tuple[str | Path, str]]) -> list[tuple[Path, str]]:
    """(file, run id) for every entry: a file means all its runs; ``FILE::RUN`` or (file, run) one run;
    a run named twice is refused (:func:`runs_named_once`)."""
    out: list[tuple[Path, str]] = []
    for entry in run_entries(runs):
        if isinstance(entry, tuple):
            if len(entry) != 2 or not isinstance(entry[0], str | Path) or not isinstance(entry[1], str):
                raise TypeError(f"a run entry must be a path, 'FILE::RUN_ID' or (path, run id), got "
                                f"{entry!r}")
            out.append((Path(entry[0]), entry[1]))
            continue
        text = str(entry)
        file, sep, run_id = text.partition("::")
        path = regular_file(file, DaqError, "run file")
        if sep:
            out.append((path, run_id))
            continue
        try:
            ids = list_runs(path)
        except OSError as exc:
            raise DaqError(f"{path}: not a readable HDF5 run file ({exc})") from None
        if not ids:
            raise DaqError(f"{path}: holds no runs (expected groups under /runs)")
        out += [(path, r) for r in ids]
    return runs_named_once(out)


def runs_named_once(jobs: list[tuple[Path, str]]) -> list[tuple[Path, str]]:
    """``jobs`` (file, run id), or DaqError when one run is in it twice (the same file by another path
    or a hard link): it would be computed and written twice."""
    seen: dict[tuple[int, int, str], Path] = {}
    for path, run_id in jobs:
        try:
            st = path.stat()
        except OSError:
            continue   # a missing file is named where it is opened
        first = seen.setdefault((st.st_dev, st.st_ino, run_id), path)
        if first is not path:
            also = "" if str(first) == str(path) else f" (also as {first})"
            raise DaqError(f"{path}:{run_id}: this run is named twice{also}; name each run once")
    return jobs
