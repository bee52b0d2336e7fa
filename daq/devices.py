"""The one driver interface (:class:`Driver`), a protocol's driver, the reader thread, counter unwrapping.

A protocol is a driver class (a subclass of :class:`Driver`, like python-can's ``BusABC``) plus one
registry entry (daq.protocols.register_protocol): the class reads its ``[[device]]`` table
(:meth:`Driver.parse_device`) and then streams blocks.  A driver has ``name``, ``sources`` (names of the
values it delivers, in column order), ``limits`` (raw values at or beyond which an input is clipped, or
None) and three methods: ``open()``, ``read() -> list[Block]`` (waits at most ~0.1 s) and ``close()``.
``read``/``open`` raise :class:`DeviceLost` when the device goes away; the reader thread then reconnects
with exponential back-off (0.02 s doubling to 0.25 s) and reports ``lost``/``reconnect`` notices.
"""

from __future__ import annotations

import errno
import queue
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from flexmodal.checked_io.toml_fields import Fields
from flexmodal.daq.errors import DaqError

SIMULATOR_PORT = "@simulator"  # placeholder for the endpoint of the session's own simulator
BACKOFF_START_S = 0.02
BACKOFF_MAX_S = 0.25


@dataclass(frozen=True)
class Device:
    """One ``[[device]]``: its name, its protocol and the configuration its driver parsed from the table
    (a frozen dataclass the driver owns: daq.serial_driver.SerialConfig, daq.can_driver.CanConfig,
    daq.modbus_driver.ModbusConfig, ...; docs/acquisition.md)."""

    name: str
    protocol: str
    config: Any


class DeviceLost(Exception):
    """The device stopped answering (unplugged, port closed, connection refused); ``permanent`` when
    retrying cannot help (no such interface, the protocol family missing from the kernel)."""

    def __init__(self, message: str, *, permanent: bool = False) -> None:
        super().__init__(message)
        self.permanent = permanent


PERMANENT_ERRNOS = frozenset({errno.ENODEV, errno.EAFNOSUPPORT, errno.EPROTONOSUPPORT, errno.EINVAL})


@dataclass
class Block:
    """Consecutive samples of one device: row i is device sample ``first_index + i``."""

    device: str
    first_index: int  # device sample index (unwrapped, monotonic)
    values: np.ndarray  # [n, n_sources] device units; NaN where a value did not arrive
    timestamp_s: float  # time of the first sample (bus or host clock, seconds)
    corrupt: int = 0  # bad frames dropped just before this block
    received_s: float = 0.0  # time.monotonic() when the reader thread got it from the driver


@dataclass
class Notice:
    """A device state change for the writer: kind ``lost`` or ``reconnect``; or a fatal ``error``."""

    device: str
    kind: str
    detail: str = ""
    error: BaseException | None = None


@dataclass
class ReaderStats:
    blocks: int = 0
    samples: int = 0
    dropped_blocks: int = 0
    reconnects: int = 0
    last_block_s: float = 0.0  # time.monotonic() of the newest block (0: none yet)


class Driver(ABC):
    """A device protocol: parses its ``[[device]]`` table, then opens, reads blocks and closes.

    Subclasses set ``name`` (the device name), ``sources`` (value names in column order) and ``limits``
    (``(low, high)`` raw arrays at which an input clips, or None) in ``__init__``, and
    ``source_units`` ({source: unit} of the values the device itself labels, e.g. a DBC's units).
    """

    protocol: ClassVar[str]
    name: str
    sources: tuple[str, ...]
    limits: tuple | None = None
    source_units: Mapping[str, str] = MappingProxyType({})

    @classmethod
    @abstractmethod
    def parse_device(cls, table: Fields, name: str) -> Device:
        """The validated Device of one ``[[device]]`` table (a daq.session.DeviceTable: ``get``,
        ``choice``, ``port``, ``file``; each raises DaqError naming the field)."""

    @classmethod
    def known_sources(cls, device: Device) -> tuple[str, ...] | None:
        """Source names a channel may map to (None: not known before opening, e.g. from a DBC file)."""
        return device.config.sources

    @abstractmethod
    def __init__(self, device: Device, sample_rate_hz: float) -> None: ...

    @abstractmethod
    def open(self) -> None:
        """Connect; raise DeviceLost when the device is not there."""

    @abstractmethod
    def read(self) -> list[Block]:
        """Blocks that arrived (waits at most ~0.1 s); raise DeviceLost when the device went away."""

    @abstractmethod
    def close(self) -> None:
        """Disconnect (never raises)."""

    def poll_counts(self) -> dict[str, int]:
        """What a polling driver counted of its polls (Modbus: ``missed``, ``repeated``); {} for a
        streamed protocol."""
        return {}


def with_endpoint(config, endpoint: str):
    """A device's ``config`` with the ``"@simulator"`` placeholder replaced by the simulator's endpoint:
    by the config's own ``with_endpoint`` (Modbus TCP splits ``host:port``), else in every field that
    holds the placeholder."""
    if hasattr(config, "with_endpoint"):
        return config.with_endpoint(endpoint)
    return replace(config, **{k: endpoint for k, v in vars(config).items() if v == SIMULATOR_PORT})


def unwrap(seq: int, last: int | None, modulus: int) -> int:
    """Unwrap a device counter taken modulo ``modulus`` to the index nearest ``last`` (ahead or behind)."""
    if last is None:
        return int(seq)
    step = (int(seq) - last + modulus // 2) % modulus - modulus // 2
    return last + step


def run_reader(driver, out: queue.Queue, stop: threading.Event, stats: ReaderStats,
               first_open_timeout_s: float = 10.0) -> None:
    """Read blocks from ``driver`` into ``out`` until ``stop`` is set (runs in its own thread).

    A full queue drops the block (counted in ``stats.dropped_blocks``; the writer sees the gap).  If the
    device cannot be opened at all within ``first_open_timeout_s`` an error notice ends the session.
    """
    backoff = BACKOFF_START_S
    opened = ever_opened = False
    t_start = time.monotonic()
    while not stop.is_set():
        try:
            if not opened:
                driver.open()
                opened = True
                backoff = BACKOFF_START_S
                if ever_opened:
                    stats.reconnects += 1
                    out.put(Notice(driver.name, "reconnect", f"reconnect #{stats.reconnects}"))
                ever_opened = True
            for block in driver.read():
                block.received_s = stats.last_block_s = time.monotonic()
                stats.blocks += 1
                stats.samples += block.values.shape[0]
                try:
                    out.put(block, timeout=0.5)
                except queue.Full:
                    stats.dropped_blocks += 1
        except DeviceLost as exc:
            driver.close()
            if not ever_opened and (exc.permanent or time.monotonic() - t_start > first_open_timeout_s):
                out.put(Notice(driver.name, "error", error=DaqError(f"device {driver.name!r}: {exc}")))
                return
            if opened:
                opened = False
                out.put(Notice(driver.name, "lost", str(exc)))
            stop.wait(backoff)
            backoff = min(2 * backoff, BACKOFF_MAX_S)
        except Exception as exc:  # a bug or an unexpected device error: end the session cleanly
            driver.close()
            out.put(Notice(driver.name, "error", error=exc))
            return
    driver.close()
