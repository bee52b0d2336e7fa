"""A serial reader starved of CPU loses nothing the device sent: `flexmodal acquire` frozen (SIGSTOP) for
2 s while a paced stand-in keeps streaming CSV lines over a pty.

The pty holds about 22 kB unread here (measured on Linux 6.18: a 4096-byte read buffer plus flip
buffers), 0.3 s of this stream; the stand-in's writes then wait (a real device's UART would overrun, a
pty never drops), and the acquisition reads the backlog when it runs again.  Every row must be the
sample its index names, with no gap: the freeze shows only as an ``overrun`` event (the writer was
behind real time).  Deterministic at any load: the freeze is a signal, not a race, and nothing here is
bounded by wall-clock time but the hang guards.
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
                             "--out", str(out), "--duration", "3"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + 240  # hang guard: a niced acquire on a loaded machine starts slowly
        while stored(out) == 0 and proc.poll() is None and time.monotonic() < end:
            time.sleep(0.05)
        assert stored(out) > 0, f"no sample stored: {proc.poll()} {proc.stderr.read() if proc.poll() else ''}"
        os.kill(proc.pid, signal.SIGSTOP)
        try:
            time.sleep(FREEZE_S)  # the stand-in streams on: the pty fills, then its writes wait
        finally:
            os.kill(proc.pid, signal.SIGCONT)
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
            proc.kill()
            proc.communicate()
        stop.set()
        device.join(5)
        link.remove()
    assert proc.returncode == 0, err
    run = read_run(out, list_runs(out)[0])
    first = json.loads(run.attrs["first_index"])["mcu"]
    assert run.samples.shape == (int(3 * RATE), N_CH)
    np.testing.assert_array_equal(run.samples, _values(first + np.arange(run.samples.shape[0])))
    kinds = [e.kind for e in run.events]
    assert "overrun" in kinds  # the freeze happened while the run was recording (>= 1 s behind)
    assert not {"gap", "corrupt", "reconnect", "device_lost"} & set(kinds), run.events
