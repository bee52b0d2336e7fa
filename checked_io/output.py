"""Output paths: checked before a command does any work, and written whole or not at all.

:func:`output_file` and :func:`output_dir` prove that the target can be written by creating (and
removing) a probe file where the output will go: permission bits alone say nothing for root, read-only
mounts or ``/proc``.  Outputs are regular files only: a FIFO, a device, a socket, anything under
``/dev``, ``/proc`` or ``/sys`` is refused, and so is an output that is one of the command's inputs
(same file through symlinks and hard links) or, for a table or report, an existing HDF5 file (a run
store is never replaced by a CSV).  :func:`hdf5_output` refuses to append to an existing file that is
not HDF5 (it would be destroyed), nor to another tool's HDF5 file (a user block, superblock < 3).
Failures raise the calling package's error type naming the path.

Every output file is written through :func:`atomic_path` (a temporary file in the target's folder,
moved onto the target with ``os.replace`` once complete, removed on any exception, Ctrl-C included),
so an interrupted command leaves the old file or none, never half of one.  Updates inside an existing
HDF5 file (FRFs written back into a run file) cannot be swapped whole; they run in
:func:`signals_deferred`, which holds SIGINT/SIGTERM until the update is complete.
"""

from __future__ import annotations

import contextvars
import errno
import os
import re
import secrets
import signal
import stat
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from flexmodal.checked_io.signals import signal_handlers
from flexmodal.checked_io.text import ErrorType, file_kind, not_empty_path, one_line

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
SPECIAL_ROOTS = ("/dev", "/proc", "/sys")  # device and kernel files: never an output file ...
WRITABLE_ROOTS = ("/dev/shm",)              # ... except shared memory, an ordinary tmpfs
MARK_TAIL_BYTES = 4096                      # where sidecar_file looks for the mark a format ends with


def _probe(folder: Path, target: Path, error: ErrorType) -> None:
    try:
        fd, probe = tempfile.mkstemp(prefix=".flexmodal-probe-", dir=folder)
    except OSError as exc:
        raise error(f"{target}: cannot write in {folder} ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)


def _under(path: Path, roots: Iterable[str]) -> bool:
    return any(str(path) == root or str(path).startswith(root + "/") for root in roots)


def _same_file(a: os.stat_result, b: os.stat_result) -> bool:
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _given(path: str | Path, error: ErrorType, what: str) -> Path:
    """``path`` as a Path, unless it is an empty text (``--out ""``, a script's unset variable), which
    Path would read as the current folder."""
    not_empty_path(path, error, what)
    if str(path) == "-":
        raise error(f"the {what} path is '-': it would be a file named '-', not standard output (name a "
                    "file; ./- if that is the name meant)")
    return Path(path)


def _regular_target(path: str | Path, error: ErrorType, what: str,
                    inputs: Iterable[str | Path | None]) -> Path:
    """``path`` (through symlinks) is new or a regular file, under neither /dev nor /proc, and none of
    ``inputs`` (same device and inode, symlinks and hard links included; same resolved path if new)."""
    p = _given(path, error, what)
    if str(path).endswith(os.sep):
        raise error(f"{path}: ends with '{os.sep}', the path of a folder, not of the {what} (name a file)")
    real = Path(os.path.realpath(p))
    if any(_under(q, SPECIAL_ROOTS) and not _under(q, WRITABLE_ROOTS)
           for q in (Path(os.path.abspath(p)), real)):
        raise error(f"{p}: is a device or process file ({real}), not a regular file for the {what}")
    try:
        st: os.stat_result | None = os.stat(p)
    except FileNotFoundError:   # new (or a dangling symlink: its target is created)
        st = None
    except OSError as exc:   # a symlink loop, a path through a file, a name too long
        raise error(f"{p}: cannot be the {what} ({exc.strerror or one_line(exc)})") from None
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise error(f"{p}: is a directory, expected a path for the {what}")
    if st is not None and not stat.S_ISREG(st.st_mode):
        raise error(f"{p}: is {file_kind(st.st_mode)}, not a regular file for the {what} (refusing to "
                    "write there)")
    for source in inputs:
        if source is None or str(source) in ("", "-"):
            continue
        try:
            same = st is not None and _same_file(st, os.stat(source))
        except OSError:
            same = False
        if same or Path(os.path.realpath(source)) == real:
            raise error(f"{p}: is also an input or output of this command ({source}); refusing to "
                        f"overwrite it with the {what}")
    return p


def hdf5_superblock(path: str | Path) -> tuple[int, int] | None:
    """Where ``path`` holds the HDF5 signature and its superblock's version byte, ``(offset,
    version)``, or None when it holds none.  HDF5 looks at byte 0, then after a user block at 512,
    1024, 2048, ... bytes (a MATLAB v7.3 ``.mat`` file has a 512-byte one), as ``H5Fis_accessible``
    does; only 9 bytes at each place are read (HDF5 File Format Specification, version 3.0, II.A).

    Parameters
    ----------
    path : str or Path
        The file to look into; one that cannot be read holds none.

    Returns
    -------
    tuple of (int, int) or None
        The signature's offset [bytes] and the superblock version (0-3; -1 when the file ends right
        after the signature), or None.

    Examples
    --------
    >>> import os, tempfile, h5py
    >>> folder = tempfile.mkdtemp()
    >>> with h5py.File(os.path.join(folder, "a.h5"), "w", libver="latest") as f:
    ...     pass
    >>> with h5py.File(os.path.join(folder, "b.mat"), "w", userblock_size=512) as f:
    ...     pass
    >>> [hdf5_superblock(os.path.join(folder, n)) for n in ("a.h5", "b.mat", "nothing")]
    [(0, 3), (512, 0), None]
    """
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            offset = 0
            while offset + len(HDF5_SIGNATURE) <= size:
                fh.seek(offset)
                head = fh.read(len(HDF5_SIGNATURE) + 1)
                if head[:len(HDF5_SIGNATURE)] == HDF5_SIGNATURE:
                    return offset, head[len(HDF5_SIGNATURE)] if len(head) > len(HDF5_SIGNATURE) else -1
                offset = max(512, 2 * offset)
    except OSError:
        return None
    return None


def _is_hdf5(path: Path) -> bool:
    return hdf5_superblock(path) is not None


def _writable(path: str | Path, error: ErrorType, what: str, inputs: Iterable[str | Path | None]) -> Path:
    p = _regular_target(path, error, what, inputs)
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        why = "is not a directory" if folder.exists() else "does not exist"
        raise error(f"{p}: cannot write the {what}: folder {folder} {why}")
    if p.exists() and not os.access(p, os.W_OK):
        raise error(f"{p}: the {what} exists and is not writable")
    real_folder = Path(os.path.realpath(p)).parent
    _probe(real_folder, p, error)
    return p


def output_file(path: str | Path, error: ErrorType, what: str = "output file", *,
                inputs: Iterable[str | Path | None]) -> Path:
    """``path`` as a writable file that may be replaced whole: new or a regular file (a symlink is
    followed: its target is written), its folder exists and takes new files, it is none of the
    command's ``inputs`` and not an HDF5 file (a run store is never replaced by a table).  ``inputs``
    has no default: every writer names what it read (``()`` only where it read no file)."""
    p = _writable(path, error, what, inputs)
    if p.exists() and _is_hdf5(p):
        raise error(f"{p}: is an HDF5 file (a run store?); refusing to replace it with the {what}; "
                    "choose another path")
    return p


def output_dir(path: str | Path, error: ErrorType, what: str = "output directory", *,
               files: Iterable[str] = (), inputs: Iterable[str | Path | None] = ()) -> Path:
    """``path`` as a folder that exists or can be created and takes new files (it is not created);
    the ``files`` the command writes into it are checked as :func:`output_file` checks a file."""
    p = _given(path, error, what)
    if p.exists() and not p.is_dir():
        raise error(f"{p}: exists and is not a directory (the {what})")
    ancestor = p
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise error(f"{p}: cannot create the {what}: {ancestor} is not a directory")
    _probe(ancestor, p, error)
    inputs = list(inputs)
    for name in files:
        if p.is_dir():
            output_file(p / name, error, f"{what} file {name}", inputs=inputs)
    return p


def sidecar_file(path: str | Path, error: ErrorType, what: str, signature: bytes, mark: bytes = b"",
                 older: Iterable[re.Pattern[bytes]] = ()) -> None:
    """A file a command writes beside its named output (``MODES.synthesis.csv`` beside ``MODES.csv``)
    replaces only a file that starts with ``signature`` and, when ``mark`` is given, holds ``mark`` in
    its last :data:`MARK_TAIL_BYTES` bytes (a format whose start every other tool writes too, such as
    PDF's ``%PDF-``, is recognised by the mark flexmodal appends), or whose first
    :data:`MARK_TAIL_BYTES` bytes match one of the patterns ``older`` (what older flexmodal versions
    wrote before the mark): one flexmodal wrote there.  A file of the user's own is never replaced
    (``error`` naming it).  Check :func:`output_file` first."""
    p = Path(path)
    if not p.is_file():
        return
    try:
        with open(p, "rb") as f:
            head = f.read(max(len(signature), MARK_TAIL_BYTES))
            f.seek(max(0, p.stat().st_size - MARK_TAIL_BYTES))
            tail = f.read()
    except OSError as exc:
        raise error(f"{p}: cannot read it to check it is a {what} ({exc.strerror or exc})") from None
    if any(pattern.match(head) for pattern in older):
        return
    if not head.startswith(signature) or mark not in tail:
        raise error(f"{p}: exists and is not a {what} flexmodal wrote; refusing to replace it (move it, or "
                    "choose another --out)")


def hdf5_output(path: str | Path, error: ErrorType, what: str = "HDF5 output file") -> Path:
    """A writable HDF5 target: new, or an existing HDF5 file flexmodal can append runs to without
    harm (nothing else in it is lost).  One rule for ``acquire --out``, ``frf --out``, ``store=True``
    and :class:`~flexmodal.daq.store.RunWriter`: refused (``error`` naming the file) are a file that is
    not HDF5, one whose HDF5 part follows a user block (a MATLAB v7.3 ``.mat``, an ``.h5`` inside a
    ``.tar``: appending would write into the other format), and one of superblock version < 3 (h5py's
    default, MATLAB, PyTables: no SWMR, and latest-format objects would be added to another tool's
    file)."""
    p = _writable(path, error, what, ())
    if not p.exists():
        return p
    found = hdf5_superblock(p)
    if found is None:
        raise error(f"{p}: exists and is not an HDF5 file (refusing to overwrite it with the {what}; "
                    "choose another path)")
    offset, version = found
    if offset > 0:
        raise error(f"{p}: an HDF5 file after a {offset}-byte user block (a MATLAB v7.3 .mat, an "
                    "archive?); refusing to write into it: choose a new path")
    if version < 3:   # h5py's default, MATLAB, PyTables: no SWMR
        raise error(f"{p}: an HDF5 file of another tool (superblock version {version}); runs are "
                    "appended only to files of superblock version 3 (HDF5 1.10, as flexmodal writes "
                    "them): choose a new path")
    return p


def write_failed(path: str | Path, exc: OSError) -> OSError:
    """An ``OSError`` naming ``path`` for a write that failed (disk full, I/O error): the CLI prints it
    as one line, ``PATH: reason``."""
    reason = exc.strerror or one_line(exc)
    return OSError(exc.errno or errno.EIO, f"{reason} (nothing was written)", str(path))


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A fresh temporary path next to ``path`` to write the whole output to; when the block ends it is
    moved onto ``path`` (``os.replace``, atomic on POSIX), and on any exception it is removed.  A
    symlink ``path`` stays a link: its target is replaced.  An ``OSError`` inside the block (disk full,
    I/O error) is raised again naming ``path`` (:func:`write_failed`).

    The temporary file is created with the usual permissions (0666 less the umask)."""
    target = Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)
    if target.exists() and not target.is_file():
        raise OSError(errno.EINVAL, "not a regular file (refusing to replace it)", str(path))
    tmp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.part")
    try:
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except OSError as exc:
        raise write_failed(path, exc) from None
    try:
        yield tmp
        group = _GROUP.get()
        if group is None:
            os.replace(tmp, target)
        else:   # moved with the rest of its set when the group ends (atomic_group)
            group.append((tmp, target))
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if exc.filename == str(path):
            raise
        raise write_failed(path, exc) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


_GROUP: contextvars.ContextVar[list[tuple[Path, Path]] | None] = contextvars.ContextVar("atomic_group",
                                                                                        default=None)


@contextmanager
def atomic_group() -> Iterator[None]:
    """Files written inside through :func:`atomic_path` are moved onto their targets together when
    the block ends, and all removed when it raises: a set of outputs (a modal table and the synthesis,
    diagrams and UFF beside it; diagnosis.json and .html) is complete or absent, never a table
    without its sidecars because the disk filled up after it was written."""
    pending: list[tuple[Path, Path]] = []
    token = _GROUP.set(pending)
    try:
        yield
    except BaseException:
        for tmp, _ in pending:
            tmp.unlink(missing_ok=True)
        raise
    finally:
        _GROUP.reset(token)
    for tmp, target in pending:
        os.replace(tmp, target)


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
    held: list[int] = []
    try:
        with signal_handlers(lambda signum, _frame: held.append(signum), DEFERRED_SIGNALS):
            yield
    finally:
        if held:
            signal.raise_signal(held[0])
