"""What the device simulators share: fault plan, fault log, pty links and real-time pacing.

Faults (all optional, deterministic for a seed): each frame is corrupted with probability
``corrupt_rate`` (a flipped byte or a truncated frame); frames whose first sample falls in
[``drop_at_s``, ``drop_at_s + drop_s``) are not sent (the device's counter runs on); at
``disconnect_at_s`` the link goes away for ``disconnect_s`` (pty closed and re-created under the same
path; TCP server stopped and restarted on the same port).  Every fault is written as one JSON line to
the fault log (``--fault-log``) with the device sample indices it affected, so tests can check the
events of a run against it.
"""

from __future__ import annotations

import fcntl
import json
import os
import select
import struct
import tempfile
import termios
import time
import tty
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class FaultPlan:
    corrupt_rate: float = 0.0
    drop_at_s: float | None = None
    drop_s: float = 0.2
    disconnect_at_s: float | None = None
    disconnect_s: float = 0.5
    seed: int = 0

    def in_drop(self, t_s: np.ndarray) -> np.ndarray:
        if self.drop_at_s is None:
            return np.zeros(np.shape(t_s), bool)
        return (t_s >= self.drop_at_s) & (t_s < self.drop_at_s + self.drop_s)

    def in_disconnect(self, t_s: np.ndarray) -> np.ndarray:
        if self.disconnect_at_s is None:
            return np.zeros(np.shape(t_s), bool)
        return (t_s >= self.disconnect_at_s) & (t_s < self.disconnect_at_s + self.disconnect_s)


class FaultLog:
    """JSON-lines record of injected faults (no-op without a path)."""

    def __init__(self, path: str | Path | None) -> None:
        self._f = open(path, "a", encoding="utf-8") if path else None  # noqa: SIM115 (closed in close())

    def write(self, fault: str, **fields) -> None:
        if self._f:
            self._f.write(json.dumps({"fault": fault, **fields}) + "\n")
            self._f.flush()

    def close(self) -> None:
        if self._f:
            self._f.close()


def read_fault_log(path: str | Path) -> list[dict]:
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


class PtyLink:
    """A pty whose slave is reachable under a stable symlink ``path`` (re-pointed after a reconnect).

    The simulator writes to the master; the slave is put in raw mode at once and kept open so bytes
    written before a reader opens it wait in the pty instead of being lost.
    """

    def __init__(self, path: str | Path | None = None) -> None:
        self._own_dir = path is None
        self.path = Path(path) if path else Path(tempfile.mkdtemp(prefix="flexmodal-sim-")) / "tty"
        self.master = self._slave = -1
        self.open()

    def open(self) -> None:
        self.master, self._slave = os.openpty()
        tty.setraw(self._slave)
        tty.setraw(self.master)
        os.set_blocking(self.master, False)
        tmp = self.path.with_name(self.path.name + ".new")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(os.ttyname(self._slave))
        os.replace(tmp, self.path)

    def drain(self, timeout_s: float = 1.0, settle_s: float = 0.1) -> None:
        """Wait until the reader has taken every byte written so far (at most ``timeout_s``).

        The slave's FIONREAD counts only the line discipline's read buffer (at most 4095 bytes); bytes
        beyond that wait in the pty's flip buffer, which the kernel moves over in a worker after each
        read, so an empty read buffer is trusted only once it stayed empty for ``settle_s``.
        """
        end = time.monotonic() + timeout_s
        empty_since = time.monotonic()
        while (now := time.monotonic()) < end:
            if self._unread():
                empty_since = now
            elif now - empty_since >= settle_s:
                return
            time.sleep(0.005)

    def _unread(self) -> int:
        return struct.unpack("i", fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0"))[0]

    def close(self) -> None:
        for fd in (self.master, self._slave):
            if fd >= 0:
                os.close(fd)
        self.master = self._slave = -1

    def remove(self) -> None:
        """Close for good: also delete the symlink (and the temporary folder made for it)."""
        self.close()
        self.path.unlink(missing_ok=True)
        if self._own_dir:
            self.path.parent.rmdir()

    def write(self, data: bytes, timeout_s: float = 1.0) -> None:
        """Write all of ``data``; TimeoutError if the reader takes nothing for ``timeout_s``."""
        view = memoryview(data)
        while view:
            _, ready, _ = select.select([], [self.master], [], timeout_s)
            if not ready:
                raise TimeoutError(f"{self.path}: nobody is reading")
            try:
                n = os.write(self.master, view)
            except BlockingIOError:
                continue
            view = view[n:]

    def read_available(self, max_bytes: int = 65536) -> bytes:
        """Bytes the reader sent to the device (non-blocking; b'' if none)."""
        ready, _, _ = select.select([self.master], [], [], 0)
        return os.read(self.master, max_bytes) if ready else b""


class Pacer:
    """Real-time sample clock: ``due()`` is how many samples should have been emitted by now."""

    def __init__(self, sample_rate_hz: float) -> None:
        self.rate = sample_rate_hz
        self.t0 = time.monotonic()

    def due(self) -> int:
        return int((time.monotonic() - self.t0) * self.rate)

    def wait_until_sample(self, n: int) -> None:
        delay = self.t0 + n / self.rate - time.monotonic()
        if delay > 0:
            time.sleep(delay)
