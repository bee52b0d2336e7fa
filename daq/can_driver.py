"""CAN driver: python-can bus (virtual, slcan, ...) with DBC signal decoding vectorised over frames.

The samples travel in one DBC message (``message`` in the session, default the only multiplexed one)
with a scan counter signal ``Seq`` and, optionally, a multiplexer selecting which group of signals a
frame carries; a scan is complete when every multiplexer group of one counter value has arrived.  The
counter (few bits, wraps) is unwrapped with the bus timestamps: the jump between two frames is the
counter difference plus the multiple of its modulus closest to ``dt * sample_rate``.
"""

from __future__ import annotations

import numpy as np

from flexmodal.daq.dbc import load_message
from flexmodal.daq.devices import Block, DeviceLost, Driver
from flexmodal.daq.errors import DaqError

COUNTER_SIGNAL = "Seq"
MAX_FRAMES_PER_READ = 20000


class CanDriver(Driver):
    """Samples of one DBC message on a python-can bus (see the module docstring)."""

    protocol = "can"

    @classmethod
    def parse_device(cls, t, name):
        """``interface`` (python-can), ``channel``, ``bitrate``, ``dbc`` file, ``message`` name."""
        from flexmodal.daq.session import Device

        t.reject_unknown({"interface", "channel", "bitrate", "dbc", "message"})
        interface = t.get("interface", str)
        channel = t.port("channel") if interface == "slcan" else t.get("channel", str)
        return Device(name, cls.protocol, interface=interface, channel=channel,
                      bitrate=t.get("bitrate", int, 500000), dbc=t.file("dbc", "dbc file"),
                      message=t.get("message", str, ""))

    @classmethod
    def known_sources(cls, device):
        return None  # the DBC message's signals, checked when the driver loads the DBC file

    def __init__(self, device, sample_rate_hz: float) -> None:
        self.name = device.name
        self.device = device
        self.fs = sample_rate_hz
        self.layout = load_message(device.dbc, device.message)
        names = [s.name for s in self.layout.signals]
        if COUNTER_SIGNAL not in names:
            raise DaqError(f"{device.dbc}: message has no scan counter signal {COUNTER_SIGNAL!r}")
        self.counter = self.layout.signal(COUNTER_SIGNAL)
        self.signals = tuple(s for s in self.layout.signals if s.name != COUNTER_SIGNAL)
        self.sources = tuple(s.name for s in self.signals)
        lims = np.array([s.limits for s in self.signals])
        self.limits = (lims[:, 0], lims[:, 1])
        mux_ids = sorted({i for s in self.signals for i in (s.mux_ids or ())})
        self.groups = np.array(mux_ids if self.layout.mux is not None else [0])
        self._bus = None
        self._last: tuple[int, int, float] | None = None  # (index, counter code, timestamp) of last frame
        self._held = None  # (index, group, data) of the newest, maybe unfinished scan
        self._lost: str | None = None

    def open(self) -> None:
        import can

        kwargs = {"bitrate": self.device.bitrate}
        if self.device.interface == "slcan":
            kwargs["sleep_after_open"] = 0.0
        try:
            self._bus = can.Bus(interface=self.device.interface, channel=self.device.channel, **kwargs)
        except (can.CanError, OSError, ValueError) as exc:
            raise DeviceLost(f"cannot open CAN {self.device.interface}:{self.device.channel}: {exc}") from exc
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
        try:
            msg = self._bus.recv(timeout=0.05)
            while msg is not None and len(msgs) < MAX_FRAMES_PER_READ:
                msgs.append(msg)
                msg = self._bus.recv(timeout=0)
        except (can.CanError, serial.SerialException, OSError) as exc:
            self._lost = f"CAN {self.device.channel}: {exc}"
            if not msgs:  # otherwise hand over what arrived; the next read reports the loss
                raise DeviceLost(self._lost) from exc
        return msgs

    def _unwrap(self, code: np.ndarray, ts: np.ndarray) -> np.ndarray:
        modulus = 1 << self.counter.length
        if self._last is None:
            self._last = (int(code[0]), int(code[0]), float(ts[0]))
        index0, code0, ts0 = self._last
        d = (code - np.r_[code0, code[:-1]]) % modulus
        expected = (ts - np.r_[ts0, ts[:-1]]) * self.fs
        d = d + np.maximum(np.round((expected - d) / modulus), 0).astype(np.int64) * modulus
        index = index0 + np.cumsum(d)
        self._last = (int(index[-1]), int(code[-1]), float(ts[-1]))
        return index

    def read(self) -> list[Block]:
        msgs = self._receive()
        mine = [m for m in msgs if m.arbitration_id == self.layout.frame_id]
        good = [m for m in mine if len(m.data) == self.layout.length]  # others are corrupt: their scan
        # shows the missing group
        if not good:
            return []
        data = np.zeros((len(good), 8), np.uint8)
        data[:, :self.layout.length] = np.frombuffer(b"".join(bytes(m.data) for m in good), np.uint8).reshape(
            len(good), self.layout.length)
        ts = np.array([m.timestamp for m in good])
        index = self._unwrap(self.layout.raw(data, self.counter), ts)
        mux = self.layout.mux
        group = self.layout.raw(data, mux) if mux is not None else np.zeros(len(good), np.int64)
        valid = np.isin(group, self.groups)
        index, group, data, ts = index[valid], group[valid], data[valid], ts[valid]
        if self._held is not None:
            h_index, h_group, h_data, h_ts = self._held
            index, group = np.r_[h_index, index], np.r_[h_group, group]
            data, ts = np.vstack([h_data, data]), np.r_[h_ts, ts]
        if not index.size:
            return []
        last = index == index.max()  # the newest scan may still be arriving: keep it for the next read
        self._held = (index[last], group[last], data[last], ts[last])
        index, group, data, ts = index[~last], group[~last], data[~last], ts[~last]
        if not index.size:
            return []
        return self._blocks(index, group, data, ts)

    def _blocks(self, index, group, data, ts) -> list[Block]:
        first = int(index.min())
        rows = (index - first).astype(np.int64)
        n_rows = int(rows.max()) + 1
        values = np.full((n_rows, len(self.signals)), np.nan)
        for j, sig in enumerate(self.signals):  # per signal, all frames at once
            on = np.ones(rows.size, bool) if sig.mux_ids is None else np.isin(group, sig.mux_ids)
            values[rows[on], j] = self.layout.raw(data[on], sig) * sig.scale + sig.offset
        present = np.bincount(rows, minlength=n_rows)
        t_row = np.full(n_rows, np.nan)
        t_row[rows[::-1]] = ts[::-1]  # earliest frame time of each scan
        have = present > 0
        partial = have & (present < self.groups.size)
        starts = np.flatnonzero(have & (np.r_[True, ~have[:-1]] | partial))
        ends = np.r_[starts[1:], n_rows]
        blocks = []
        for a, b in zip(starts, ends, strict=True):  # one block per run of complete scans (+ faults)
            b = a + int(np.argmin(np.r_[have[a:b], False]))  # up to the first missing scan
            blocks.append(Block(self.name, first + int(a), values[a:b], float(t_row[a]),
                                corrupt=int(self.groups.size - present[a]) if partial[a] else 0))
        return blocks
