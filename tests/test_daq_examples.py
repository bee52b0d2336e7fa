"""The worked real-device examples of docs/acquisition.md, each run against a stand-in for the device:
the microcontroller's custom serial frames on a pty, the CAN module's two DBC messages on python-can's
virtual bus (interface swapped for the test), the Modbus RTU logger as the RTU simulator on a pty pair."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import numpy as np
from polled import assert_polled
from stand_in import record_with, stream_paced

from flexmodal.daq.acquire import acquire
from flexmodal.daq.serial_frames import FrameSpec, encode_custom
from flexmodal.daq.session import load_session
from flexmodal.daq.store import read_run
from flexmodal.fixtures.sim_common import PtyLink
from flexmodal.fixtures.sim_source import sim_source

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples" / "sessions"


def _copy(tmp_path: Path, name: str, *edits: tuple[str, str]) -> Path:
    text = (EXAMPLES / name).read_text()
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / name
    path.write_text(text)
    return path


def _first(run) -> int:
    return next(iter(json.loads(run.attrs["first_index"]).values()))


def test_mcu_custom_frames_example(tmp_path):
    link = PtyLink(tmp_path / "ttyACM0")
    config = _copy(tmp_path, "mcu-serial.toml", ('"/dev/ttyACM0"', f'"{link.path}"'))
    session = load_session(config)
    spec = session.devices[0].config.frame
    assert spec == FrameSpec(b"\xa5\x5a", "<12h", 1, 2, 0, "frames", "crc16")
    counts = np.random.default_rng(4).integers(-2000, 2000, (6000, 12)).astype(float)
    counts[:, 3] = 512 + np.arange(6000) % 7  # the elbow encoder
    frames = encode_custom(spec, 0, counts)

    def device(stop: threading.Event) -> None:
        stream_paced(link, lambda a, b: frames[a * spec.length:b * spec.length], 1000.0, stop, 6000)

    try:
        run = record_with(device, session, tmp_path / "run.h5", 2.0)
    finally:
        link.remove()
    raw = counts[_first(run):_first(run) + 2000]
    gains = np.array([c.gain() for c in session.channels])
    np.testing.assert_allclose(run.samples, (raw[:, :4] * gains).astype(np.float32), rtol=0, atol=0)
    assert run.channels[3].unit == "deg" and gains[3] == 360 / 4096
    assert not [e for e in run.events if e.kind in ("gap", "corrupt", "reconnect")]


def test_can_module_example_with_its_dbc(tmp_path):
    config = _copy(tmp_path, "can-module.toml", ('interface = "socketcan"', 'interface = "virtual"'),
                   ('channel = "can0"', 'channel = "flexmodal-example"'),
                   ('dbc = "can-module.dbc"', f'dbc = "{EXAMPLES / "can-module.dbc"}"'))
    session = load_session(config)
    values = np.random.default_rng(2).integers(-20000, 20000, (20000, 8)).astype(np.int16)

    def device(stop: threading.Event) -> None:
        bus = can.Bus(interface="virtual", channel="flexmodal-example", preserve_timestamps=True)
        while len(can.interfaces.virtual.channels["flexmodal-example"]) < 2 and not stop.is_set():
            time.sleep(0.01)
        t0, k = time.time(), 0
        while not stop.is_set() and k < values.shape[0]:
            due = min(values.shape[0], int((time.time() - t0) * 500))
            for s in range(k, due):
                for m in range(2):
                    bus.send(can.Message(arbitration_id=0x200 + m, data=values[s, 4 * m:4 * m + 4].tobytes(),
                                         timestamp=t0 + s / 500 + 1e-4 * m, is_extended_id=False))
            k = due
            time.sleep(0.005)
        bus.shutdown()

    run = record_with(device, session, tmp_path / "run.h5", 2.0)
    first = int(np.flatnonzero((values[:, 0] * 0.001).astype(np.float32) == run.samples[0, 0])[0])
    expected = values[first:first + 1000][:, [0, 1, 4, 5]] * 0.001
    np.testing.assert_allclose(run.samples, expected.astype(np.float32), rtol=0, atol=0)
    assert not run.events


def test_modbus_rtu_example(tmp_path):
    sim = subprocess.Popen([sys.executable, "-m", "flexmodal", "sim", "serve", "--protocol", "modbus",
                            "--transport", "rtu", "--rate", "100", "--quiet"], cwd=REPO,
                           stdout=subprocess.PIPE, text=True)
    try:
        port = sim.stdout.readline().strip()
        config = _copy(tmp_path, "modbus-rtu.toml", ('"/dev/ttyUSB0"', f'"{port}"'))
        summary = acquire(load_session(config), tmp_path / "run.h5", duration_s=2.0, quiet=True)
    finally:
        sim.terminate()
        sim.wait(60)
    run = read_run(tmp_path / "run.h5", summary.run_id)
    src = sim_source(None, "impact", 100.0)
    steps = np.array([c.step for c in src.channels])
    assert_polled(run, 200, src.physical(0, 200)[:, [0, 6]], steps[[0, 6]])  # misses under load: gaps


def test_api_acquire_starts_an_example_sessions_simulator_with_no_extra_import(tmp_path):
    """``fm.acquire`` on examples/sessions/serial-sim.toml in a fresh interpreter that imports only
    ``flexmodal``: the simulator launcher is found (and the simulators loaded) on demand; importing
    flexmodal loads only the light simulator registry that the API re-exports, never a simulator."""
    code = ("import sys, flexmodal as fm\n"
            "assert 'flexmodal.fixtures.sim_serve' not in sys.modules\n"
            f"s = fm.acquire({str(EXAMPLES / 'serial-sim.toml')!r}, {str(tmp_path / 'run.h5')!r}, "
            "duration_s=0.5)\n"
            "print(s.run_id)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    run = read_run(tmp_path / "run.h5", proc.stdout.strip())
    assert run.samples.shape[0] >= 1024 and run.samples.shape[1] == 7
