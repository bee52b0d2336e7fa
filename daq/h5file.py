"""The HDF5 file under the run store: opening a run file for reading without waiting on a truncated one,
and clearing the open-for-writing flags a killed writer left in its superblock (HDF5 file format
specification, superblock version 2/3; like ``h5clear -s``).  The run store (daq.store) and the run
schema (daq.run_schema) read through :func:`open_read`.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import h5py

from flexmodal.checked_io.text import regular_file
from flexmodal.daq.errors import DaqError

# lookup3's mixing rounds as (x, y, z, k) on the state (a, b, c) = (0, 1, 2): in ``mix`` each round is
# ``x = (x - y) ^ rot(y, k); y += z``, in ``final`` it is ``x = (x ^ y) - rot(y, k)`` (lookup3.c).
_LOOKUP3_MIX = ((0, 2, 1, 4), (1, 0, 2, 6), (2, 1, 0, 8), (0, 2, 1, 16), (1, 0, 2, 19), (2, 1, 0, 4))
_LOOKUP3_FINAL = ((2, 1, 14), (0, 2, 11), (1, 0, 25), (2, 1, 16), (0, 2, 4), (1, 0, 14), (2, 1, 24))


def _lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle``, the checksum of HDF5 metadata (superblock v2/v3)."""
    m = 0xFFFFFFFF

    def rot(x: int, k: int) -> int:
        return ((x << k) | (x >> (32 - k))) & m

    def absorb(state: list[int], block: bytes) -> None:
        for j in range(3):
            state[j] = (state[j] + int.from_bytes(block[4 * j:4 * j + 4], "little")) & m

    state = [(0xDEADBEEF + len(data) + initval) & m] * 3
    i = 0
    while len(data) - i > 12:  # a 48-byte superblock: not a hot path
        absorb(state, data[i:i + 12])
        for x, y, z, k in _LOOKUP3_MIX:
            state[x] = ((state[x] - state[y]) & m) ^ rot(state[y], k)
            state[y] = (state[y] + state[z]) & m
        i += 12
    if i == len(data):
        return state[2]
    absorb(state, data[i:] + bytes(12 - (len(data) - i)))
    for x, y, k in _LOOKUP3_FINAL:
        state[x] = ((state[x] ^ state[y]) - rot(state[y], k)) & m
    return state[2]


def recover(path: str | Path) -> bool:
    """Clear the "open for writing" flags a killed writer left in the superblock (like ``h5clear -s``).

    Only for a file that no process is writing any more (a live `acquire`'s lock is refused, see
    daq.lock); afterwards it opens normally and takes new runs.  Returns False when the flags were
    already clear.
    """
    from flexmodal.daq.lock import holder

    path = Path(path)
    pid = holder(path)
    if pid is not None:
        raise DaqError(f"{path}: being written by a running acquire (pid {pid or '?'}); not recovered")
    with open(path, "r+b") as f:
        head = f.read(48)
        if head[:8] != b"\x89HDF\r\n\x1a\n" or head[8] not in (2, 3) or head[9] != 8:
            raise DaqError(f"{path}: not an HDF5 file with a version 2/3 superblock")
        if head[11] == 0:
            return False
        sb = head[:11] + b"\x00" + head[12:44]
        f.seek(0)
        f.write(sb + _lookup3(sb).to_bytes(4, "little"))
    return True


SUPERBLOCK_BYTES = 48  # a version 2/3 superblock with 8-byte addresses, checksum included
LIVE_RECHECK_S = 0.2  # a live writer grows its file to the stored end-of-file at every flush


def _superblock(path: Path) -> tuple[bytes, int]:
    """The first bytes of ``path`` and its size; DaqError when it is missing or not a regular file (a
    FIFO would block the open, a device never end)."""
    regular_file(path, DaqError, "run file")
    try:
        with open(path, "rb") as fh:
            return fh.read(SUPERBLOCK_BYTES), os.fstat(fh.fileno()).st_size
    except FileNotFoundError:
        raise DaqError(f"{path}: run file not found") from None
    except OSError as exc:
        raise DaqError(f"{path}: cannot read the run file ({exc.strerror or exc})") from None


def open_read(path: str | Path) -> h5py.File:
    """Open a run file for reading, failing at once on a truncated or foreign file.

    A cleanly closed file (superblock status flags clear) opens without SWMR, so HDF5 runs its
    end-of-file check.  A file with the open-for-writing flags set (a live writer, or a killed one)
    opens in SWMR read mode, which skips that check and would retry a truncated file's missing
    metadata for ever; its size is therefore first compared with the end-of-file address the
    superblock stores (HDF5 file format specification, superblock version 2/3, 8-byte addresses:
    bytes 28-35).
    """
    p = Path(path)
    head, size = _superblock(p)
    if head[:8] != b"\x89HDF\r\n\x1a\n":
        if not h5py.is_hdf5(p):  # a user block moves the signature to 512, 1024, ... bytes
            raise DaqError(f"{p}: not a readable HDF5 run file (no HDF5 signature)")
        return _h5_open(p, swmr=False)
    if len(head) > 8 and head[8] not in (2, 3):  # superblock 0/1: never SWMR; HDF5 checks the size
        return _h5_open(p, swmr=False)
    if len(head) < SUPERBLOCK_BYTES:
        raise DaqError(f"{p}: truncated HDF5 file ({size} bytes, not even a superblock)")
    live = head[11] != 0
    stored_eof = int.from_bytes(head[28:36], "little")
    if size < stored_eof and live:
        time.sleep(LIVE_RECHECK_S)
        head, size = _superblock(p)
        stored_eof = int.from_bytes(head[28:36], "little")
    if size < stored_eof:
        raise DaqError(f"{p}: truncated HDF5 file ({size} of {stored_eof} bytes)")
    return _h5_open(p, swmr=live)


LOCKED = ("in use by another process (HDF5 file lock: a program has it open, for writing, or for reading "
          "while this one would write); try again once it is closed")


def locked(exc: BaseException) -> bool:
    """Whether an h5py open failed because another process holds the file's lock (HDF5 file locking:
    ``flock`` on the file, EAGAIN), not because the file is damaged: the message then says
    :data:`LOCKED` instead of "not readable"."""
    return "unable to lock file" in str(exc)


def _h5_open(path: Path, *, swmr: bool) -> h5py.File:
    try:
        return h5py.File(path, "r", libver="latest", swmr=swmr)
    except OSError as exc:
        if locked(exc):
            raise DaqError(f"{path}: {LOCKED}") from None
        text = " ".join(str(exc).split())
        if "truncated file" in text:
            raise DaqError(f"{path}: truncated HDF5 file ({text.partition('(')[2].rstrip(')')})") from None
        raise DaqError(f"{path}: not a readable HDF5 file ({text[:200]})") from None
