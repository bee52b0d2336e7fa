"""A serial reader starved of CPU loses nothing the device sent: `flexmodal acquire` frozen (SIGSTOP) for
2 s while a paced stand-in keeps streaming CSV lines over a pty.

The pty holds about 22 kB unread here (measured on Linux 6.18: a 4096-byte read buffer plus flip
buffers), about 0.5 s of this stream; the stand-in's writes then wait (a real device's UART would overrun, a
pty never drops), and the acquisition reads the backlog when it runs again.  Every row must be the
sample its index names, with no gap (the freeze may show as an ``overrun`` event: the writer was behind
real time).  Deterministic at any load: the freeze is a signal, the run ends on Ctrl-C once the frozen
stretch is stored, and nothing here is bounded by wall-clock time but the hang guards.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
from stand_in import stream_paced
from test_daq_shutdown import stored

from flexmodal.daq.serial_frames import encode_csv
from flexmodal.daq.store import list_runs, read_run
from flexmodal.fixtures.sim_common import PtyLink

RATE = 2048.0
N_CH = 3
FREEZE_S = 2.0


def _values(k: np.ndarray) -> np.ndarray:
    """Sample ``k`` of the stand-in: integers that name their index (exact through CSV and float)."""
    return (k[:, None] * np.arange(3, 3 + N_CH)) % 2003 - 1000.0


def _until(done, limit_s: float = 240.0) -> bool:
    """Wait for ``done()`` (hang guard ``limit_s``: a niced process on a loaded machine starts slowly)."""
    end = time.monotonic() + limit_s
    while not done() and time.monotonic() < end:
        time.sleep(0.05)
    return done()


def test_a_frozen_acquisition_loses_no_line_of_a_paced_serial_device(tmp_path):
    link = PtyLink(tmp_path / "tty")
    names = [f"c{i}" for i in range(N_CH)]
    config = tmp_path / "mcu.toml"
    channels = "".join(f'[[channel]]\nname = "{c}"\nkind = "voltage"\nunit = "count"\ndevice = "mcu"\n'
                       for c in names)
    config.write_text(f'sample_rate_hz = {RATE}\nreconnect_timeout_s = 120\n[[device]]\nname = "mcu"\n'
                      f'protocol = "serial"\nport = "{link.path}"\nframing = "csv"\n'
                      f'sources = {json.dumps(names)}\n{channels}')
    out = tmp_path / "run.h5"
    stop = threading.Event()
    device = threading.Thread(target=stream_paced, daemon=True,
                              args=(link, lambda a, b: encode_csv(a, _values(np.arange(a, b))), RATE, stop))
    device.start()
    proc = subprocess.Popen([sys.executable, "-m", "flexmodal", "--quiet", "acquire", "--config", str(config),
                             "--out", str(out), "--duration", "600"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert _until(lambda: stored(out) > 0 or proc.poll() is not None), "no sample stored"
        assert proc.poll() is None, proc.communicate()[1]
        before = stored(out)
        os.kill(proc.pid, signal.SIGSTOP)
        try:
            time.sleep(FREEZE_S)  # the stand-in streams on: the pty fills, then its writes wait
        finally:
            os.kill(proc.pid, signal.SIGCONT)
        # the run ends on Ctrl-C once it stored the frozen stretch (whatever the load: no race with its end)
        assert _until(lambda: stored(out) >= before + FREEZE_S * RATE or proc.poll() is not None)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
            proc.kill()
            proc.communicate()
        stop.set()
        device.join(5)
        link.remove()
    assert proc.returncode == 128 + signal.SIGINT, err
    run = read_run(out, list_runs(out)[0])
    first = json.loads(run.attrs["first_index"])["mcu"]
    assert run.samples.shape[0] >= before + FREEZE_S * RATE  # the frozen stretch is in the run
    np.testing.assert_array_equal(run.samples, _values(first + np.arange(run.samples.shape[0])))
    # (the freeze fell inside the run: samples were stored before it and 2 s of them after; the run's
    # `overrun` event, when its writer noticed the lag before the backlog was read, is no loss)
    assert not {"gap", "corrupt", "reconnect", "device_lost"} & {e.kind for e in run.events}, run.events
