"""CAN driver: python-can bus (virtual, slcan, socketcan, pcan, ...) with DBC signal decoding vectorised
over frames.

The samples travel in one or more DBC messages (``messages`` in the session; default the only
multiplexed message), each optionally multiplexed; a *part* of a scan is one (message, multiplexer
value) and a scan is complete when all its parts arrived.  With a counter signal (``counter``, default
``Seq``) in every message, each message's counter (few bits, wraps) is unwrapped with the bus
timestamps: the jump between two frames is the counter difference plus the multiple of its modulus
closest to ``dt * sample_rate``.  Without one (``counter = ""``) the interface's timestamps place the
frames: the first frame of the first part is sample 0, and each part advances by ``round(dt *
sample_rate)`` (at least 1) from its previous frame, so a lost frame shows as a missing sample; this
needs frame timestamps accurate to well under half a sample period (hardware or kernel timestamps, as
socketcan and pcan give) and the parts of one scan sent within half a period of its first frame.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from flexmodal.daq.dbc import load_messages
from flexmodal.daq.devices import PERMANENT_ERRNOS, Block, Device, DeviceLost, Driver
from flexmodal.daq.errors import DaqError

COUNTER_SIGNAL = "Seq"
READ_SPAN_S = 0.1  # one read hands over at most this much of the stream (frames at the session's rate)


@dataclass(frozen=True)
class CanConfig:
    """A CAN device's ``[[device]]`` fields (docs/acquisition.md): the python-can ``interface`` and
    ``channel``, ``bitrate``, the ``dbc`` file, the DBC ``messages`` carrying the samples (empty: the
    only multiplexed one) and the scan ``counter`` signal ("" for none)."""

    interface: str
    channel: str
    dbc: str
    bitrate: int = 500000
    messages: tuple[str, ...] = ()
    counter: str = COUNTER_SIGNAL


class CanDriver(Driver):
    """Samples of one DBC message on a python-can bus (see the module docstring)."""

    protocol = "can"

    @classmethod
    def parse_device(cls, t, name):
        """``interface`` (python-can), ``channel``, ``bitrate``, ``dbc`` file, ``message`` name."""
        t.reject_unknown({"interface", "channel", "bitrate", "dbc", "message", "messages", "counter"})
        interface = t.get("interface", str)
        channel = t.port("channel") if interface == "slcan" else t.get("channel", str)
        if "message" in t.doc and "messages" in t.doc:
            raise DaqError(f"{t.where}: give message or messages, not both")
        messages = t.get("messages", list, [], check=lambda v: v and all(isinstance(m, str) for m in v),
                         why="must be a non-empty list of DBC message names")
        one = t.get("message", str, "")
        return Device(name, cls.protocol, CanConfig(
            interface, channel, t.file("dbc", "dbc file"), t.get("bitrate", int, 500000),
            tuple(messages) if messages else (one,) if one else (), t.get("counter", str, COUNTER_SIGNAL)))

    @classmethod
    def known_sources(cls, device):
        return None  # the DBC message's signals, checked when the driver loads the DBC file

    def __init__(self, device, sample_rate_hz: float) -> None:
        self.name = device.name
        self.config = cfg = device.config
        self.fs = sample_rate_hz
        self.layouts = load_messages(cfg.dbc, list(cfg.messages))
        counter = cfg.counter
        self.counters = []
        for lay in self.layouts:
            names = [s.name for s in lay.signals]
            if counter and counter not in names:
                raise DaqError(f"{cfg.dbc}: message {lay.name!r} has no scan counter signal {counter!r} "
                               "(name it with counter = \"...\", or counter = \"\" to place frames by "
                               "their timestamps)")
            self.counters.append(lay.signal(counter) if counter else None)
        self.signals = tuple((m, s) for m, lay in enumerate(self.layouts) for s in lay.signals
                             if s.name != counter)
        self.sources = tuple(s.name for _, s in self.signals)
        self.source_units = {s.name: s.unit for _, s in self.signals if s.unit}
        dup = sorted({n for n in self.sources if self.sources.count(n) > 1})
        if dup:
            raise DaqError(f"{cfg.dbc}: signal {dup[0]!r} is in more than one of the messages")
        lims = np.array([s.limits for _, s in self.signals])
        self.limits = (lims[:, 0], lims[:, 1])
        self.parts: dict[tuple[int, int], int] = {}  # (message, multiplexer value) -> part of a scan
        for m, lay in enumerate(self.layouts):
            mux_ids = sorted({i for mm, s in self.signals if mm == m for i in (s.mux_ids or ())})
            for g in (mux_ids if lay.mux is not None else [0]):
                self.parts[(m, g)] = len(self.parts)
        # A read hands over what arrived, READ_SPAN_S of the stream at most: a reader that drains the port
        # no faster than the device fills it (a loaded machine) still delivers blocks at once, instead of
        # going silent, for the lost-device clock, for as long as the backlog lasts.
        self.frames_per_read = max(len(self.parts), math.ceil(READ_SPAN_S * sample_rate_hz * len(self.parts)))
        self._bus = None
        self._last: dict[int, tuple[int, int, float]] = {}  # per message: (index, counter code, timestamp)
        self._part_last: dict[int, tuple[int, float]] = {}  # without counter, per part: (index, timestamp)
        self._t0: float | None = None
        self._held = None  # (index, part, message, data, ts) of the newest, maybe unfinished scan
        self._lost: str | None = None

    def open(self) -> None:
        import can

        kwargs = {"bitrate": self.config.bitrate}
        if self.config.interface == "slcan":
            kwargs["sleep_after_open"] = 0.0
        try:
            self._bus = can.Bus(interface=self.config.interface, channel=self.config.channel, **kwargs)
        except (can.CanError, OSError, ValueError) as exc:
            permanent = isinstance(exc, ValueError | can.CanInterfaceNotImplementedError) or getattr(
                exc, "errno", None) in PERMANENT_ERRNOS
            raise DeviceLost(f"cannot open CAN {self.config.interface}:{self.config.channel}: {exc}",
                             permanent=permanent) from exc
        self._lost = None

    def close(self) -> None:
        if self._bus is not None:
            try:
                self._bus.shutdown()
            except Exception:  # noqa: BLE001 (a vanished adapter may fail in many ways while closing)
                pass
            self._bus = None

    def _receive(self) -> list:
        import can
        import serial

        if self._lost:
            raise DeviceLost(self._lost)
        msgs = []
        limit = self.frames_per_read
        end = time.monotonic() + READ_SPAN_S
        try:
            msg = self._recv(0.05)
            while msg is not None:
                msgs.append(msg)
                if len(msgs) >= limit or time.monotonic() > end:
                    break
                msg = self._recv(0)
        except (can.CanError, serial.SerialException, OSError) as exc:
            self._lost = f"CAN {self.config.channel}: {exc}"
            if not msgs:  # otherwise hand over what arrived; the next read reports the loss
                raise DeviceLost(self._lost) from exc
        return msgs

    def _recv(self, timeout: float):
        """The next frame, or None.  A garbled line ends this read instead of the session: python-can's
        slcan parser raises ValueError on one (non-hex data, as when an adapter that overran drops part of
        a line); the frame is lost and its scan shows the part as missing (counted as corrupt)."""
        try:
            return self._bus.recv(timeout=timeout)
        except ValueError:
            return None

    def _unwrap(self, m: int, code: np.ndarray, ts: np.ndarray) -> np.ndarray:
        """Sample index of each frame of message ``m`` from its counter codes and timestamps."""
        modulus = 1 << self.counters[m].length
        if m not in self._last:
            self._last[m] = (int(code[0]), int(code[0]), float(ts[0]))
        index0, code0, ts0 = self._last[m]
        d = (code - np.r_[code0, code[:-1]]) % modulus
        expected = (ts - np.r_[ts0, ts[:-1]]) * self.fs
        d = d + np.maximum(np.round((expected - d) / modulus), 0).astype(np.int64) * modulus
        index = index0 + np.cumsum(d)
        self._last[m] = (int(index[-1]), int(code[-1]), float(ts[-1]))
        return index

    def _placed(self, part: np.ndarray, ts: np.ndarray) -> np.ndarray:
        """Sample index of each frame from timestamps alone (no counter): see the module docstring."""
        index = np.full(part.size, -1, np.int64)
        if self._t0 is None:
            first = np.flatnonzero(part == 0)
            if not first.size:
                return index  # wait for the first part of a scan
            self._t0 = float(ts[first[0]])
            part, ts = part.copy(), ts.copy()
            part[:first[0]] = -1  # frames before the first scan's first part are dropped
        for p in np.unique(part[part >= 0]):  # one step per part of the scan (few)
            sel = np.flatnonzero(part == p)
            i0, t0 = self._part_last.get(int(p), (None, self._t0))
            d = np.maximum(np.round(np.diff(np.r_[t0, ts[sel]]) * self.fs), 1).astype(np.int64)
            if i0 is None:  # the part's first frame: its place from the first frame of the session
                d[0], i0 = int(round((ts[sel[0]] - self._t0) * self.fs)), 0
            index[sel] = i0 + np.cumsum(d)
            self._part_last[int(p)] = (int(index[sel[-1]]), float(ts[sel[-1]]))
        return index

    def read(self) -> list[Block]:
        msgs = self._receive()
        by_id = {(lay.frame_id, lay.is_extended_frame): m for m, lay in enumerate(self.layouts)}
        keyed = [((msg.arbitration_id, bool(msg.is_extended_id)), msg) for msg in msgs]  # 0x100 and
        good = [(by_id[key], msg) for key, msg in keyed if key in by_id   # extended 0x100: two frames
                and len(msg.data) == self.layouts[by_id[key]].length]  # others are corrupt:
        if not good:  # their scan shows the missing part
            return []
        message = np.array([m for m, _ in good])
        data = np.zeros((len(good), 8), np.uint8)
        for m, lay in enumerate(self.layouts):
            rows = np.flatnonzero(message == m)
            if rows.size:
                data[rows, :lay.length] = np.frombuffer(b"".join(bytes(good[i][1].data) for i in rows),
                                                        np.uint8).reshape(rows.size, lay.length)
        ts = np.array([msg.timestamp for _, msg in good])
        group = np.zeros(len(good), np.int64)
        for m, lay in enumerate(self.layouts):
            rows = message == m
            if lay.mux is not None and rows.any():
                group[rows] = lay.raw(data[rows], lay.mux)
        lookup = self.parts.get
        part = np.array([lookup((int(m), int(g)), -1) for m, g in zip(message, group, strict=True)])
        if self.counters[0] is None:
            index = self._placed(part, ts)
        else:
            index = np.zeros(len(good), np.int64)
            for m in np.unique(message):  # one step per message
                rows = message == m
                code = self.layouts[m].raw(data[rows], self.counters[m])
                index[rows] = self._unwrap(int(m), code, ts[rows])
        valid = (part >= 0) & (index >= 0)
        index, part, message, data, ts = index[valid], part[valid], message[valid], data[valid], ts[valid]
        if self._held is not None:
            index, part, message, data, ts = (np.r_[h, x] if x.ndim == 1 else np.vstack([h, x])
                                             for h, x in zip(self._held, (index, part, message, data, ts),
                                                             strict=True))
        if not index.size:
            return []
        last = index == index.max()  # the newest scan may still be arriving: keep it for the next read
        self._held = tuple(x[last] for x in (index, part, message, data, ts))
        keep = ~last
        if not keep.any():
            return []
        return self._blocks(index[keep], part[keep], message[keep], data[keep], ts[keep])

    def _blocks(self, index, part, message, data, ts) -> list[Block]:
        first = int(index.min())
        rows = (index - first).astype(np.int64)
        n_rows = int(rows.max()) + 1
        values = np.full((n_rows, len(self.signals)), np.nan)
        for j, (m, sig) in enumerate(self.signals):  # per signal, all frames at once
            lay = self.layouts[m]
            on = message == m
            if sig.mux_ids is not None:
                on &= np.isin(lay.raw(data, lay.mux), sig.mux_ids) if lay.mux is not None else True
            values[rows[on], j] = lay.raw(data[on], sig) * sig.scale + sig.offset
        present = np.bincount(rows, minlength=n_rows)
        t_row = np.full(n_rows, np.nan)
        t_row[rows[::-1]] = ts[::-1]  # earliest frame time of each scan
        n_parts = len(self.parts)
        have = present > 0
        partial = have & (present < n_parts)
        starts = np.flatnonzero(have & (np.r_[True, ~have[:-1]] | partial))
        ends = np.r_[starts[1:], n_rows]
        blocks = []
        for a, b in zip(starts, ends, strict=True):  # one block per run of complete scans (+ faults)
            b = a + int(np.argmin(np.r_[have[a:b], False]))  # up to the first missing scan
            blocks.append(Block(self.name, first + int(a), values[a:b], float(t_row[a]),
                                corrupt=int(n_parts - present[a]) if partial[a] else 0))
        return blocks
