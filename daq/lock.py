"""One writer per run file: an advisory ``fcntl.flock`` on ``RUN.h5.lock`` held while `acquire` runs.

The kernel drops the lock when the writer exits in any way (even SIGKILL), so a lock file left behind
by a killed writer is not held and does not block anyone; a live writer's is, and `acquire --recover`
(which rewrites the superblock) or a second `acquire` on the same file are refused.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from flexmodal.daq.errors import DaqError


def lock_path(path: str | Path) -> Path:
    path = Path(path)
    return path.with_name(path.name + ".lock")


def holder(path: str | Path) -> int | None:
    """The pid of the live writer holding ``path`` (0 if unknown), or None when nobody holds it."""
    lock = lock_path(path)
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        text = os.pread(fd, 32, 0).decode(errors="replace").strip()
        return int(text) if text.isdigit() else 0
    finally:
        os.close(fd)
    return None


class WriterLock:
    """Hold the writer lock of ``path`` (a context manager); DaqError if a live writer holds it."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.lock = lock_path(path)
        try:
            self._fd = os.open(self.lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            raise DaqError(f"{self.path}: cannot create the lock file {self.lock} ({exc.strerror})") from exc
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            pid = os.pread(self._fd, 32, 0).decode(errors="replace").strip()
            os.close(self._fd)
            raise DaqError(f"{self.path}: being written by a running acquire (pid {pid or '?'})") from None
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)

    def __enter__(self) -> WriterLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def release(self) -> None:
        if self._fd >= 0:
            self.lock.unlink(missing_ok=True)
            os.close(self._fd)
            self._fd = -1
