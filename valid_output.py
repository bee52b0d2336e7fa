"""Output paths: checked before a command does any work, and written whole or not at all.

:func:`output_file` and :func:`output_dir` prove that the target can be written by creating (and
removing) a probe file where the output will go: permission bits alone say nothing for root, read-only
mounts or ``/proc``.  :func:`hdf5_output` additionally refuses to append to an existing file that is
not HDF5 (it would be destroyed).  Failures raise the calling package's error type naming the path.

Every output file is written through :func:`atomic_path` (a temporary file in the target's folder,
moved onto the target with ``os.replace`` once complete, removed on any exception, Ctrl-C included),
so an interrupted command leaves the old file or none, never half of one.  Updates inside an existing
HDF5 file (FRFs written back into a run file) cannot be swapped whole; they run in
:func:`signals_deferred`, which holds SIGINT/SIGTERM until the update is complete.
"""

from __future__ import annotations

import os
import secrets
import signal
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from flexmodal.valid_text import ErrorType

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _probe(folder: Path, target: Path, error: ErrorType) -> None:
    try:
        fd, probe = tempfile.mkstemp(prefix=".flexmodal-probe-", dir=folder)
    except OSError as exc:
        raise error(f"{target}: cannot write in {folder} ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)


def output_file(path: str | Path, error: ErrorType, what: str = "output file") -> Path:
    """``path`` as a writable file: its folder exists and takes new files, and it is not a folder."""
    p = Path(path)
    if p.is_dir():
        raise error(f"{p}: is a directory, expected a path for the {what}")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        why = "is not a directory" if folder.exists() else "does not exist"
        raise error(f"{p}: cannot write the {what}: folder {folder} {why}")
    if p.exists() and not os.access(p, os.W_OK):
        raise error(f"{p}: the {what} exists and is not writable")
    _probe(folder, p, error)
    return p


def output_dir(path: str | Path, error: ErrorType, what: str = "output directory") -> Path:
    """``path`` as a folder that exists or can be created and takes new files (it is not created)."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise error(f"{p}: exists and is not a directory (the {what})")
    ancestor = p
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise error(f"{p}: cannot create the {what}: {ancestor} is not a directory")
    _probe(ancestor, p, error)
    return p


def hdf5_output(path: str | Path, error: ErrorType, what: str = "HDF5 output file") -> Path:
    """A writable HDF5 target: new, or an existing HDF5 file (runs are appended, nothing else is lost)."""
    p = output_file(path, error, what)
    if p.exists():
        with open(p, "rb") as fh:
            head = fh.read(len(HDF5_SIGNATURE))
        if head != HDF5_SIGNATURE:
            raise error(f"{p}: exists and is not an HDF5 file (refusing to overwrite it; choose another "
                        "--out)")
    return p


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A fresh temporary path next to ``path`` to write the whole output to; when the block ends it is
    moved onto ``path`` (``os.replace``, atomic on POSIX), and on any exception it is removed.

    The temporary file is created with the usual permissions (0666 less the umask)."""
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.part")
    os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through :func:`atomic_path`; returns ``path``."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


DEFERRED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM while the block runs (main thread only; elsewhere a no-op) and deliver
    the first one to the previous handler when it ends: for in-place updates that must not stop
    half-way (a group written into an existing HDF5 file).  Keep such blocks short (milliseconds)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    previous = {s: signal.signal(s, lambda signum, _frame: held.append(signum)) for s in DEFERRED_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if held:
            signal.raise_signal(held[0])
