"""Modbus driver (pymodbus >= 3.10, TCP or RTU): registers polled at the session rate on a fixed schedule.

Poll ``k`` is due at ``t0 + k / sample_rate_hz`` (t0 = first connection) and its value becomes sample
``k``.  A register holds the device's latest value, so a poll sent late reads a later value than its
slot's: a poll that cannot be sent within half a period of its due time is not made (never caught up
back to back: each such read would be a later value passed off as the slot's); polling resumes at the
current slot and the slots skipped are missing samples (counted in ``missed``; the timeline records them
as a ``gap`` at their rows).  An answer arriving later than half a period plus a round-trip allowance
(``max(one period, RTT_FACTOR x the median of the last round trips)``) after its due time is dropped
likewise (its value is the device's at some moment between the poll and the answer: kept, it is the
slot's within that bound).  After a reconnect polling likewise resumes at the current slot.

With ``counter`` naming a register that holds the device's own sample counter, polls are due
``OVERSAMPLE`` times per sample period (a late one is sent at once; none is caught up) and at once
after an answer with a new sample (a buffering device may hold more), and each answer is stored at the
sample its counter names: an answer repeating the last counter (no new sample yet) is dropped, counter
values never read are missing samples (``missed``), so no value is stored twice or at another sample's
row whatever the host's delays.  The counter is unwrapped (modulo 2**16 or 2**32) to the largest value
not beyond the device's newest sample as the elapsed time predicts it (plus RESTART_LAG_S / 2); a
counter that went back, or jumped ahead to a sample lagging that newest one by more than
``RESTART_LAG_S`` plus the most the device has lagged so far (a FIFO's backlog), is a restart of the
device: its sample is placed at the wall-clock slot and counting goes on from there (the samples between
are a gap; a logger whose FIFO, deeper than that, overran is taken for a restart too).  A counter that
runs faster than ``sample_rate_hz`` (by more than ``RATE_TOLERANCE`` after ``RATE_CHECK_S``) is refused:
its samples would stretch the time axis.

An exception response counts as a corrupt frame where samples are missing after it (always without a
counter; with one, where the counter jumped across it: a device that serves the same sample again lost
nothing).  Each table's registers are read in one request per poll (``device_id=`` keyword API) and
decoded for all polls of a read at once (int16/uint16/int32/uint32/float32, big or little word order,
then value * scale + offset).
"""

from __future__ import annotations

import logging
import statistics
import time
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from flexmodal.daq.devices import SIMULATOR_PORT, Block, Device, DeviceLost, Driver
from flexmodal.daq.errors import DaqError

READ_WINDOW_S = 0.05
LATE_PERIODS = 0.5  # a poll not sent within this many poll periods of its due time is skipped
OVERSAMPLE = 2  # polls per sample period when a counter register says which sample each answer holds
ANSWER_TIMEOUT_S = 1.0  # no answer within this: the device is lost (TCP notices a closed link at once)
RTT_FACTOR = 3.0  # (no counter) an answer may come this many median round trips (at least a period) late
RTT_HISTORY = 63  # round trips the median is taken over
RESTART_LAG_S = 1.0  # (counter) a counter lagging the device's newest sample by more than this, plus its
# largest lag so far, is a restart
RATE_CHECK_S, RATE_TOLERANCE = 2.0, 0.02  # (counter) a counter faster than the rate by this is refused
MAX_REGISTERS_PER_READ = 125
RAW_RANGE = {"int16": (-(2**15), 2**15 - 1), "uint16": (0, 2**16 - 1), "int32": (-(2**31), 2**31 - 1),
             "uint32": (0, 2**32 - 1), "float32": (-np.inf, np.inf)}


REGISTER_TYPES = {"int16": 1, "uint16": 1, "int32": 2, "uint32": 2, "float32": 2}  # registers per value


@dataclass(frozen=True)
class Register:
    """One Modbus value: ``type`` int16|uint16|int32|uint32|float32, ``word_order`` big|little."""

    name: str
    address: int
    type: str = "int16"
    word_order: str = "big"
    scale: float = 1.0
    offset: float = 0.0
    table: str = "holding"  # holding | input

def decode_registers(words: np.ndarray, offset: int, reg) -> np.ndarray:
    """Values of register definition ``reg`` at column ``offset`` of polls ``words`` [n, n_words] uint16."""
    if reg.type in ("int16", "uint16"):
        raw = words[:, offset].astype(np.uint16).view("<i2" if reg.type == "int16" else "<u2").astype(float)
    else:
        hi, lo = (offset, offset + 1) if reg.word_order == "big" else (offset + 1, offset)
        u32 = (words[:, hi].astype(np.uint32) << np.uint32(16)) | words[:, lo].astype(np.uint32)
        raw = u32.view({"int32": "<i4", "uint32": "<u4", "float32": "<f4"}[reg.type]).astype(float)
    return raw * reg.scale + reg.offset


def _spans(registers) -> list[tuple[str, int, int]]:
    """(table, first address, count) of one read request per table."""
    spans = []
    for table in ("holding", "input"):
        regs = [r for r in registers if r.table == table]
        if regs:
            a = min(r.address for r in regs)
            b = max(r.address + _words(r) for r in regs)
            if b - a > MAX_REGISTERS_PER_READ:
                raise DaqError(f"{table} registers span {b - a} addresses (one request reads at most "
                               f"{MAX_REGISTERS_PER_READ})")
            spans.append((table, a, b - a))
    return spans


def _words(reg) -> int:
    return 1 if reg.type in ("int16", "uint16") else 2


def _refuse_overlaps(registers, where: str) -> None:
    """DaqError when two registers of one table share an address word (a typo in an address: the value
    of one would be decoded from part of the other's words, with no error at any poll)."""
    for i, r in enumerate(registers):
        for q in registers[:i]:
            if r.table == q.table and r.address < q.address + _words(q) and q.address < r.address + _words(r):
                raise DaqError(f"{where}: register {r.name!r} ({r.type} at {r.table} address {r.address}) "
                               f"overlaps register {q.name!r} ({q.type} at address {q.address})")


def _check_counter(registers, name: str, where: str) -> None:
    """DaqError unless ``name`` is one of ``registers``, an unsigned integer read as is (the counter's
    words are the sample index, unwrapped modulo 2**16 or 2**32)."""
    reg = next((r for r in registers if r.name == name), None)
    if reg is None:
        raise DaqError(f"{where}: counter {name!r} is not one of its registers")
    if reg.type not in ("uint16", "uint32") or (reg.scale, reg.offset) != (1.0, 0.0):
        raise DaqError(f"{where}: counter register {name!r} must be uint16 or uint32 with scale 1 and "
                       "offset 0 (it is the device's sample index)")


def _register(doc: dict, where: str):
    from flexmodal.daq.session import Table

    t = Table(doc, where)
    t.reject_unknown({"name", "address", "type", "word_order", "scale", "offset", "table"})
    return Register(
        name=t.get("name", str), address=t.get("address", int, check=lambda v: 0 <= v <= 65535,
                                                 why="is not a register address 0..65535"),
        type=t.choice("type", tuple(REGISTER_TYPES), "int16"),
        word_order=t.choice("word_order", ("big", "little"), "big"),
        scale=t.get("scale", float, 1.0), offset=t.get("offset", float, 0.0),
        table=t.choice("table", ("holding", "input"), "holding"))


@dataclass(frozen=True)
class ModbusConfig:
    """A Modbus device's ``[[device]]`` fields (docs/acquisition.md): ``transport`` tcp (``host``,
    ``tcp_port``) or rtu (``port``, ``baud``), the unit ``device_id``, the ``registers`` polled and the
    ``counter`` register (the device's sample counter, an integer register read unscaled; "" none)."""

    transport: str
    registers: tuple[Register, ...]
    device_id: int = 1
    host: str = "127.0.0.1"
    tcp_port: int = 502
    port: str = ""  # rtu: the serial port; tcp: the "@simulator" placeholder until the simulator starts
    baud: int = 19200
    counter: str = ""  # the register holding the device's own sample counter ("": none, place by slot)

    @property
    def sources(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.registers)

    def with_endpoint(self, endpoint: str) -> ModbusConfig:
        """Over TCP the simulator's endpoint is ``host:port``; over RTU, its pty."""
        if self.port != SIMULATOR_PORT:
            return self
        if self.transport == "tcp":
            host, port = endpoint.rsplit(":", 1)
            return replace(self, host=host, tcp_port=int(port), port=port)
        return replace(self, port=endpoint)


class ModbusDriver(Driver):
    """Registers polled at the session rate (see the module docstring)."""

    protocol = "modbus"

    @classmethod
    def parse_device(cls, t, name):
        """``transport`` tcp (``host``, ``port``) or rtu (``port``, ``baud``), ``device_id``, registers."""
        t.reject_unknown({"transport", "host", "port", "baud", "device_id", "register", "counter"})
        transport = t.choice("transport", ("tcp", "rtu"), "tcp")
        regs = t.get("register", list, check=bool, why="must list at least one register")
        registers = tuple(_register(r, f"{t.where}: register {i + 1}") for i, r in enumerate(regs))
        names = [r.name for r in registers]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise DaqError(f"{t.where}: duplicate register name {dup[0]!r}")
        _refuse_overlaps(registers, t.where)
        unit = t.get("device_id", int, 1)
        counter = t.get("counter", str, "")
        if counter:
            _check_counter(registers, counter, t.where)
        if transport == "tcp":
            port = t.get("port", (int, str), 502)
            if isinstance(port, str) and port != SIMULATOR_PORT:
                raise DaqError(f"{t.where}: port {port!r} is not a TCP port number")
            return Device(name, cls.protocol, ModbusConfig(
                transport, registers, unit, host=t.get("host", str, "127.0.0.1"),
                tcp_port=port if isinstance(port, int) else 0, port=str(port), counter=counter))
        return Device(name, cls.protocol, ModbusConfig(transport, registers, unit, port=t.port("port"),
                                                       baud=t.get("baud", int, 19200), counter=counter))

    def __init__(self, device, sample_rate_hz: float) -> None:
        self.name = device.name
        self.config = cfg = device.config
        self.fs = sample_rate_hz
        self.sources = cfg.sources
        self.spans = _spans(cfg.registers)
        base = {t: sum(c for _, _, c in self.spans[:i]) - a for i, (t, a, c) in enumerate(self.spans)}
        self.columns = [base[r.table] + r.address for r in cfg.registers]
        lims = np.array([sorted((lo * r.scale + r.offset, hi * r.scale + r.offset))
                         for r in cfg.registers for lo, hi in [RAW_RANGE[r.type]]])
        self.limits = (lims[:, 0], lims[:, 1])
        self._counter = next(((c, r) for c, r in zip(self.columns, cfg.registers, strict=True)
                              if r.name == cfg.counter), None)
        self._period_s = 1 / (sample_rate_hz * (OVERSAMPLE if self._counter else 1))
        self._client = None
        self._t0: float | None = None
        self._slot = 0
        self._last: int | None = None  # the sample index of the last answer kept (counter mode)
        self._shift = 0  # (counter mode) sample index - counter, modulo the counter's range (restarts)
        self._phase = -np.inf  # (counter mode) max of index - t * fs: the newest sample is t * fs + this
        self._lag = 0.0  # (counter mode) the most the device's answers lagged its newest sample [samples]
        self._rate_from: tuple[float, int] | None = None  # (counter mode) (time, index) of the first repeat
        self._rtts: deque[float] = deque(maxlen=RTT_HISTORY)  # round trips of the last polls [s]
        self._fresh = False  # (counter mode) the last answer held a new sample
        self._lost: str | None = None
        self._bad = 0  # polls answered with an exception since the last answer kept
        self._polls = 0  # polls sent
        self._exceptions = 0  # polls answered with an exception
        self._missed = 0  # samples never read: slots skipped, or (counter) counter values not seen
        self._pymodbus_level: int | None = None  # pymodbus's log level before open, put back by close

    def open(self) -> None:
        from pymodbus.client import ModbusSerialClient, ModbusTcpClient

        if self._pymodbus_level is None:  # failures become events, not log noise, while open
            logger = logging.getLogger("pymodbus")
            self._pymodbus_level = logger.level
            logger.setLevel(logging.CRITICAL)
        d = self.config
        if d.transport == "tcp":
            client = ModbusTcpClient(d.host, port=d.tcp_port, timeout=ANSWER_TIMEOUT_S, retries=0)
        else:
            client = ModbusSerialClient(d.port, baudrate=d.baud, timeout=ANSWER_TIMEOUT_S, retries=0)
        if not client.connect():
            client.close()
            where = f"{d.host}:{d.tcp_port}" if d.transport == "tcp" else d.port
            raise DeviceLost(f"cannot connect to Modbus {d.transport} {where}")
        self._client = client
        self._lost = None
        if self._t0 is None:
            self._t0 = time.monotonic()
        else:  # after a reconnect, polling resumes at the current slot: the missed ones are a gap
            self._skip_to(int((time.monotonic() - self._t0) / self._period_s))

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._pymodbus_level is not None:
            logging.getLogger("pymodbus").setLevel(self._pymodbus_level)
            self._pymodbus_level = None

    def _poll(self) -> list[int] | None:
        """One poll of every span: the words, or None for an exception response."""
        words = []
        for table, address, count in self.spans:
            read = (self._client.read_holding_registers if table == "holding"
                    else self._client.read_input_registers)
            rr = read(address, count=count, device_id=self.config.device_id)
            if rr.isError():
                return None
            words += rr.registers
        return words

    def poll_counts(self) -> dict[str, int]:
        """``polls`` sent, of them answered with an ``exceptions``, and samples ``missed`` (never read:
        their rows are gaps)."""
        return {"polls": self._polls, "exceptions": self._exceptions, "missed": self._missed}

    def _skip_to(self, slot: int) -> None:
        """Go on at ``slot``; the slots skipped are samples missed (counter mode: counted by the counter)."""
        if slot > self._slot:
            self._missed += 0 if self._counter else slot - self._slot
            self._slot = slot

    def read(self) -> list[Block]:
        from pymodbus.exceptions import ModbusException

        if self._lost:
            raise DeviceLost(self._lost)
        index, rows, stamps, bad = [], [], [], []
        end = time.monotonic() + READ_WINDOW_S
        while time.monotonic() < end:
            due = self._t0 + self._slot * self._period_s
            now = time.monotonic()
            if self._fresh:  # the last answer was a new sample: the device may hold more, ask at once
                pass
            elif now < due:
                time.sleep(due - now)
            elif not self._counter and now > due + LATE_PERIODS * self._period_s:  # too late for its value
                self._skip_to(int(np.ceil((now - self._t0) / self._period_s - LATE_PERIODS)))
                continue
            try:
                self._polls += 1
                sent = time.monotonic()
                words = self._poll()
            except (ModbusException, OSError) as exc:
                self._lost = f"Modbus poll failed: {exc}"
                break
            answered = time.monotonic()
            self._rtts.append(answered - sent)
            # counter mode: the next poll at the next due time, none caught up (it would read a repeat)
            self._slot = int((time.monotonic() - self._t0) / self._period_s) + 1 if self._counter else \
                self._slot + 1
            if words is None:
                self._bad += 1
                self._exceptions += 1
                continue
            if not self._counter and answered - due > LATE_PERIODS * self._period_s + self._rtt_allowance_s():
                self._missed += 1  # too late to be the slot's value: its row is part of the gap
                continue
            prev = self._last
            at = self._sample_index(words, answered)
            if at is None:
                continue
            index.append(at)
            rows.append(words)
            stamps.append(time.time())
            # exception answers cost samples only where the index jumps (a device that keeps its sample
            # for the next read, as its counter shows, lost nothing)
            bad.append(self._bad if prev is None or at != prev + 1 or not self._counter else 0)
            self._bad = 0
        blocks = self._blocks(np.array(index, np.int64), np.array(rows, np.uint16), np.array(stamps),
                              np.array(bad, np.int64))
        if not blocks and self._lost:
            raise DeviceLost(self._lost)
        return blocks

    def _rtt_allowance_s(self) -> float:
        """How late after half a period an answer may still come: a period, or RTT_FACTOR median round
        trips if longer (a slow link such as RTU, 2-5 ms a poll, keeps its samples)."""
        return max(self._period_s, RTT_FACTOR * statistics.median(self._rtts))

    def _sample_index(self, words: list[int], now: float) -> int | None:
        """The sample an answer received at ``now`` (monotonic, s) holds: its slot, or (counter mode) the
        device counter, unwrapped (module docstring); None for an answer repeating the last one kept (the
        device had no new sample)."""
        if self._counter is None:
            return self._slot - 1
        col, reg = self._counter
        modulus = 1 << (16 * _words(reg))
        raw = int(decode_registers(np.array([words], np.uint16), col, reg)[0])
        if self._last is None:
            at = raw
        else:
            newest = now * self.fs + self._phase  # the device's newest sample, by elapsed time
            top = int(np.floor(newest + self.fs * RESTART_LAG_S / 2))
            at = top - (top - raw - self._shift) % modulus  # the largest index <= top with this counter
            if at == self._last:  # no new sample: the device holds no backlog, its rate is measured from here
                self._rate_from = self._rate_from or (now, at)
                self._fresh = False
                return None
            if at < self._last or (at > self._last + 1 and newest - at > self.fs * RESTART_LAG_S + self._lag):
                at = max(int(round(newest)), self._last + 1)
                self._phase, self._rate_from = -np.inf, None
            self._missed += at - self._last - 1
        self._shift = (at - raw) % modulus
        self._fresh = True
        self._last = at
        self._phase = max(self._phase, at - now * self.fs)
        self._lag = max(self._lag, now * self.fs + self._phase - at)
        self._check_rate(now, at)
        return at

    def _check_rate(self, now: float, at: int) -> None:
        """DaqError when the counter has run faster than ``sample_rate_hz`` (by more than RATE_TOLERANCE
        and a second of samples, RATE_CHECK_S after its first repeated answer since the start or a
        restart: a logger draining a backlog runs ahead of the clock only until then)."""
        if self._rate_from is None:
            return
        t, first = self._rate_from
        if now - t >= RATE_CHECK_S and at - first > (now - t) * self.fs * (1 + RATE_TOLERANCE) + self.fs:
            raise DaqError(f"{self.name}: counter {self.config.counter!r} advanced {at - first} samples in "
                           f"{now - t:.1f} s, {(at - first) / (now - t):.0f} Hz, not the session's "
                           f"{self.fs:g} Hz (sample_rate_hz must be the device's sampling rate)")

    def _blocks(self, index, words, stamps, bad) -> list[Block]:
        """Runs of consecutive samples; a run also ends before an answer that follows exception answers
        (those are its block's ``corrupt`` count)."""
        if not index.size:
            return []
        values = np.column_stack([decode_registers(words, c, r)
                                  for c, r in zip(self.columns, self.config.registers, strict=True)])
        split = np.flatnonzero((np.diff(index) != 1) | (bad[1:] > 0)) + 1
        return [Block(self.name, int(index[a]), values[a:b], float(stamps[a]), corrupt=int(bad[a]))
                for a, b in zip(np.r_[0, split], np.r_[split, index.size], strict=True)]
