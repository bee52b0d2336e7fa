"""The writer lock of a run file: held only while its process lives, so --recover and a second acquire
are refused for a live writer and allowed after a killed one."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from flexmodal.daq.errors import DaqError
from flexmodal.daq.h5file import recover
from flexmodal.daq.lock import WriterLock, holder, lock_path

HOLD = ("import sys, time\nfrom flexmodal.daq.lock import WriterLock\nlock = WriterLock(sys.argv[1])\n"
        "print('locked', flush=True)\ntime.sleep(60)\n")


def test_lock_is_held_by_a_live_writer_only(tmp_path):
    path = tmp_path / "run.h5"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "locked"
        assert holder(path) == proc.pid
        with pytest.raises(DaqError, match=f"being written by a running acquire \\(pid {proc.pid}\\)"):
            WriterLock(path)
        with pytest.raises(DaqError, match=f"pid {proc.pid}"):
            recover(path)
    finally:
        proc.kill()
        proc.wait()
    assert lock_path(path).exists() and holder(path) is None  # left behind by the killed writer: stale
    with WriterLock(path):
        assert holder(path) == os.getpid()
    assert not lock_path(path).exists()
