"""Ctrl-C right after an HDF5 file is opened for writing never leaves it open: every writer opens (and
closes) its file with SIGINT deferred (checked_io.output.signals_deferred), so the file is closed before
the process ends, even when it ends with ``os._exit`` as the CLI does after a Ctrl-C.

Deterministic: the child process is held inside ``h5py.File`` just after the file is open (a pipe it
waits on), the signal is sent while it waits, and only then is it released; no timing is assumed.
Before the fix the signal arrived between the open and the ``with``, and the file kept its
open-for-writing superblock flags (``OSError: file is already open for write``).
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys

import h5py
import numpy as np
import pytest

from flexmodal.daq.store import Channel, RunWriter

WAIT_S = 300.0  # generous bound for a loaded machine; nothing below depends on it being short

CHILD = r"""
import os, sys
import h5py
import numpy as np

ready, go, writer, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]


class HeldAfterOpen(h5py.File):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        if self.mode != "r":  # opened for writing: say so, then wait for the parent's go
            os.write(ready, b"1")
            os.read(go, 1)


h5py.File = HeldAfterOpen
try:
    if writer == "write_frf":
        from flexmodal.modal.frf import FrfResult
        from flexmodal.modal.runs_io import write_frf

        write_frf(out, "r1", FrfResult(np.arange(5.0), np.ones((2, 1, 5), complex), np.ones((2, 5)),
                                       "H1", "hann", 8, 3, 64.0, "accelerance", ("a1", "a2"), ("F",)))
    elif writer == "RunWriter":
        from flexmodal.daq.store import Channel, RunWriter

        with RunWriter(out, "r2", sample_rate_hz=64.0, channels=[Channel("F", "force", "N")],
                       excitation="random", pose={}) as w:
            w.append(np.zeros((10, 1)))
    else:
        from flexmodal.daq.acquire import _store_attrs

        _store_attrs(out, "r0", {"pose": {"theta_deg": 1.0}, "pose_spread": {}})
except KeyboardInterrupt:
    sys.stdout.flush()
    os._exit(130)  # as the CLI ends after a Ctrl-C: no interpreter tear-down, no garbage collection
os._exit(0)
"""


@pytest.mark.parametrize("writer", ["write_frf", "RunWriter", "store_pose"])
def test_sigint_right_after_the_open_leaves_the_file_closed(writer, tmp_path):
    out = tmp_path / "runs.h5"
    with RunWriter(out, "r0", sample_rate_hz=64.0, channels=[Channel("F", "force", "N")],
                   excitation="random", pose={}) as w:
        w.append(np.ones((10, 1)))
    ready_r, ready_w = os.pipe()
    go_r, go_w = os.pipe()
    child = subprocess.Popen([sys.executable, "-c", CHILD, str(ready_w), str(go_r), writer, str(out)],
                             pass_fds=(ready_w, go_r), stderr=subprocess.PIPE, text=True)
    os.close(ready_w)
    os.close(go_r)
    try:
        readable, _, _ = select.select([ready_r], [], [], WAIT_S)
        assert readable and os.read(ready_r, 1) == b"1", "the child never opened the file for writing"
        child.send_signal(signal.SIGINT)  # while it is held just after the open
        os.write(go_w, b"1")
        _, err = child.communicate(timeout=WAIT_S)
    finally:
        os.close(ready_r)
        os.close(go_w)
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == 130, err[-2000:]  # the signal was delivered, as a KeyboardInterrupt
    with h5py.File(out, "r") as f:  # plain h5py, no SWMR: fails if the superblock says "open for write"
        assert np.array_equal(f["runs/r0/samples"][:], np.ones((10, 1), np.float32))
        runs = sorted(f["runs"])
    if writer == "write_frf":  # the deferred signal let the update finish: the group is whole
        from flexmodal.modal.runs_io import read_frf

        assert read_frf(out, "r1").H.shape == (2, 1, 5)
    if writer == "RunWriter":  # laid out whole before the signal was delivered, then closed
        assert runs == ["r0", "r2"]
