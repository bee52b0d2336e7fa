"""The one small driver interface, the reader thread that runs a driver, and sequence unwrapping.

A driver has ``name``, ``sources`` (names of the values it delivers, in column order), ``limits``
(raw values at or beyond which an input is clipped, or None) and three methods: ``open()``,
``read() -> list[Block]`` (waits at most ~0.1 s) and ``close()``.  ``read``/``open`` raise
:class:`DeviceLost` when the device goes away; the reader thread then reconnects with exponential
back-off (0.02 s doubling to 0.25 s) and reports ``lost``/``reconnect`` notices.
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass

import numpy as np

from flexmodal.daq.errors import DaqError

BACKOFF_START_S = 0.02
BACKOFF_MAX_S = 0.25


class DeviceLost(Exception):
    """The device stopped answering (unplugged, port closed, connection refused)."""


@dataclass
class Block:
    """Consecutive samples of one device: row i is device sample ``first_index + i``."""

    device: str
    first_index: int  # device sample index (unwrapped, monotonic)
    values: np.ndarray  # [n, n_sources] device units; NaN where a value did not arrive
    timestamp_s: float  # time of the first sample (bus or host clock, seconds)
    corrupt: int = 0  # bad frames dropped just before this block


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
                stats.blocks += 1
                stats.samples += block.values.shape[0]
                try:
                    out.put(block, timeout=0.5)
                except queue.Full:
                    stats.dropped_blocks += 1
        except DeviceLost as exc:
            driver.close()
            if not ever_opened and time.monotonic() - t_start > first_open_timeout_s:
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


def make_driver(device, session):
    """The driver for ``device`` (a daq.session.Device) of ``session``."""
    if device.protocol == "serial":
        from flexmodal.daq.serial_driver import SerialDriver
        return SerialDriver(device, session.sample_rate_hz)
    if device.protocol == "can":
        from flexmodal.daq.can_driver import CanDriver
        return CanDriver(device, session.sample_rate_hz)
    from flexmodal.daq.modbus_driver import ModbusDriver
    return ModbusDriver(device, session.sample_rate_hz)
