"""End to end: protocol simulator + `flexmodal acquire` -> HDF5, compared with what the simulator emitted.

Each run uses the real stack: a pty for serial, an slcan adapter on a pty through python-can for CAN,
a pymodbus TCP server on 127.0.0.1 for Modbus.  The simulators emit ``fixtures.sim_source.sim_source``
sample by sample, so the stored rows are checked against that signal within one quantisation step, and
the injected faults (logged by the simulators) against the run's events.
"""

from __future__ import annotations

import functools
import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from cpu_wait import CpuWait
from polled import assert_polled

from flexmodal.daq.store import list_runs, read_run
from flexmodal.fixtures.sim_common import read_fault_log
from flexmodal.fixtures.sim_source import sim_source

REPO = Path(__file__).resolve().parents[1]
SESSIONS = REPO / "examples" / "sessions"
DURATION_S = 5.0
FAULTS = {"corrupt_rate": 0.01, "disconnect_after_s": 2.0, "disconnect_s": 0.5}  # 1 %, 0.5 s
IN_FLIGHT_S = 0.25  # data written into a link just before it goes away may be lost with it (as on a real
# unplug); the simulators drain the link first, so this bounds a gap's early start only under heavy load


def _session(tmp_path: Path, protocol: str, sim: dict | None = None, rate: float | None = None) -> Path:
    """A copy of the example session with absolute paths, extra simulator options and optional rate."""
    text = (SESSIONS / f"{protocol}-sim.toml").read_text()
    text = text.replace('rig = "../rigs/', f'rig = "{REPO}/examples/rigs/')
    text = text.replace('dbc = "../../fixtures/', f'dbc = "{REPO}/fixtures/')
    sim = {"overrun_after_s": 600.0, **(sim or {})}  # a starved reader loses nothing (test_daq_shutdown)
    if protocol == "modbus":  # a logger whose FIFO holds 10 min (its default holds the latest sample only)
        sim = {"modbus_fifo_s": 600.0, **sim}
    extra = "".join(f"{k} = {json.dumps(v)}\n" for k, v in sim.items())
    text = text.replace('test = "impact"\n', f'test = "impact"\n{extra}', 1)
    if rate:
        text = re.sub(r"sample_rate_hz = [0-9.]+", f"sample_rate_hz = {rate}", text, count=1)
    path = tmp_path / f"{protocol}.toml"
    path.write_text(text)
    return path


def _acquire(config: Path, out: Path, duration_s: float = DURATION_S, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flexmodal", "--quiet", "acquire", "--config", str(config),
                           "--out", str(out), "--duration", str(duration_s)], cwd=REPO, capture_output=True,
                          text=True, timeout=240, **kw)


def _run(path: Path):
    run = read_run(path, list_runs(path)[0])
    first = next(iter(json.loads(run.attrs["first_index"]).values()))
    return run, first


@functools.lru_cache
def _reference(protocol: str, rate: float):
    src = sim_source(None, "impact", rate)
    return src, np.array([c.step for c in src.channels])


def _acquired(config: Path, duration_s: float = DURATION_S):
    """Acquire ``config`` into run.h5 beside it, which must exit 0: the finished process, the stored run
    and the simulator's sample index of the run's first row."""
    out = config.parent / "run.h5"
    done = _acquire(config, out, duration_s)
    assert done.returncode == 0, done.stderr
    return (done, *_run(out))


def _assert_emitted(run, first: int, protocol: str, rate: float, n: int) -> None:
    """The run holds the ``n`` samples the simulator emitted from ``first`` on, cleanly (see below)."""
    src, steps = _reference(protocol, rate)
    _assert_clean(run, src.physical(first, n), steps, n)


def _assert_clean(run, expected: np.ndarray, steps: np.ndarray, n: int) -> None:
    assert run.samples.shape[0] == n  # same count
    assert not np.isnan(run.samples).any()  # no gaps
    assert not [e for e in run.events if e.kind in ("gap", "corrupt", "reconnect")]
    err = np.abs(run.samples - expected) / steps
    assert err.max() <= 1.0  # within one quantisation step (float32 storage: ~1e-3 step here)


@pytest.mark.parametrize("protocol,rate", [("serial", 2048.0), ("can", 512.0)])
def test_streamed_samples_equal_emitted(tmp_path, protocol, rate):
    done, run, first = _acquired(_session(tmp_path, protocol))
    assert done.stdout.count("\n") == 1 and str(tmp_path / "run.h5") in done.stdout  # one summary line
    _assert_emitted(run, first, protocol, rate, int(DURATION_S * rate))
    assert run.channels[1].sensitivity_unit == "mV/g" and run.channels[1].unit == "m/s^2"
    assert [e.kind for e in run.events].count("trigger") >= 2  # impacts every 2 s detected on F


@pytest.mark.slow
def test_serial_csv_lines(tmp_path):
    config = _session(tmp_path, "serial")
    config.write_text(config.read_text().replace('framing = "binary"', 'framing = "csv"'))
    _, run, first = _acquired(config, 3.0)
    _assert_emitted(run, first, "serial", 2048.0, 6144)


def test_modbus_polled_samples_equal_emitted(tmp_path):
    """Every polled sample sits at its index (the device's sample counter register, stored as a
    channel); polls missed by a starved poller are reported gaps (tests/polled.py)."""
    _, run, _ = _acquired(_session(tmp_path, "modbus"))
    n = int(DURATION_S * 200)
    src, steps = _reference("modbus", 200.0)
    assert_polled(run, n, src.physical(0, n), steps)


@pytest.mark.slow
def test_run_starts_pretrigger_samples_before_the_first_impact(tmp_path):
    config = _session(tmp_path, "serial")
    text = config.read_text().replace("pretrigger_samples = 64\n", "pretrigger_samples = 64\nstart = true\n")
    config.write_text(text)
    _, run, first = _acquired(config, 3.0)
    _assert_emitted(run, first, "serial", 2048.0, 6144)
    triggers = [e.sample_index for e in run.events if e.kind == "trigger"]
    assert triggers[0] == 64  # the pretrigger samples come first
    assert run.samples[63, 0] < 5.0 <= run.samples[64, 0]  # F crosses the 5 N level there
    assert all(b - a >= 0.5 * 2048 for a, b in zip(triggers, triggers[1:], strict=False))  # hold-off


def test_modbus_rtu_over_a_pty_pair(tmp_path):
    config = _session(tmp_path, "modbus")
    text = config.read_text().replace('transport = "tcp"', 'transport = "rtu"\nbaud = 115200')
    config.write_text(text.replace('host = "127.0.0.1"\n', ""))
    _, run, _ = _acquired(config, 3.0)
    src, steps = _reference("modbus", 200.0)
    assert_polled(run, 600, src.physical(0, 600), steps)  # polls missed under load: reported gaps


def test_can_on_the_virtual_bus_in_one_process(tmp_path):
    config = _session(tmp_path, "can")
    text = re.sub(r'interface = "slcan".*\n', 'interface = "virtual"\n', config.read_text())
    config.write_text(re.sub(r'channel = "@simulator".*\n', 'channel = "flexmodal-test"\n', text))
    _, run, first = _acquired(config, 3.0)
    _assert_emitted(run, first, "can", 512.0, 1536)


def _fault_window(log: list[dict]) -> tuple[int, int]:
    down = next(f["first_index"] for f in log if f["fault"] == "disconnect")
    up = next(f["first_index"] for f in log if f["fault"] == "reconnect")
    return down, up


def _nan_runs(rows_nan: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.r_[0, rows_nan.astype(int), 0]))
    return list(zip(edges[::2], edges[1::2], strict=True))


def _faulted_run(tmp_path, protocol: str, duration_s: float = DURATION_S):
    """Acquire from a simulator injecting FAULTS; the run, its first device index and the fault log."""
    log_path = tmp_path / "faults.jsonl"  # beside the run file, where the session's fault_log goes
    config = _session(tmp_path, protocol, {**FAULTS, "fault_log": log_path.name})
    out = tmp_path / "run.h5"
    done = _acquire(config, out, duration_s)
    assert done.returncode == 0, done.stderr
    run, first = _run(out)
    return run, first, read_fault_log(log_path)


@pytest.mark.slow
def test_serial_faults_are_events_at_their_samples(tmp_path):
    run, first, log = _faulted_run(tmp_path, "serial", 6.0)
    n = run.samples.shape[0]
    down, up = (i - first for i in _fault_window(log))
    rows_nan = np.isnan(run.samples).any(axis=1)
    events = {e.sample_index: e for e in run.events if e.kind in ("corrupt", "gap")}
    gaps = [e for e in events.values() if e.kind == "gap"]
    assert len(gaps) == 1, f"not one gap: {sorted(events.items())}"
    gap = gaps[0]  # the disconnect: a gap from the first sample not received ...
    assert down - IN_FLIGHT_S * 2048 <= gap.sample_index <= down, f"gap not at {down}: {gap}"
    # ... which is the simulator's first sample not sent unless frames still in the pty were lost
    corrupt = [f["first_index"] - first for f in log if f["fault"] == "corrupt"]
    corrupt = [c for c in corrupt if 0 <= c < n and not gap.sample_index <= c < gap.sample_index + gap.count]
    assert len(corrupt) >= 1
    for c in corrupt:  # each corrupted frame: a corrupt event at its first sample, its 32 rows empty
        hit = [e for e in events.values() if e.kind == "corrupt" and e.sample_index <= c < e.sample_index
               + 32 * e.count]
        assert hit, f"no corrupt event covers frame at row {c}"
        assert rows_nan[c:c + 32].all()
    assert up <= gap.sample_index + gap.count <= up + int(0.5 * 2048)  # until the reconnect (+ back-off)
    assert any(e.kind == "reconnect" for e in run.events)
    expected_nan = np.zeros(n, bool)
    for e in events.values():
        expected_nan[e.sample_index:e.sample_index + (32 * e.count if e.kind == "corrupt" else e.count)] = 1
    np.testing.assert_array_equal(rows_nan, expected_nan)  # nothing missing beyond the faults
    src, steps = _reference("serial", 2048.0)
    good = ~rows_nan  # every good sample stored, exactly
    assert (np.abs(run.samples[good] - src.physical(first, n)[good]) / steps).max() <= 1.0


@pytest.mark.slow
def test_can_faults_are_events_at_their_samples(tmp_path):
    run, first, log = _faulted_run(tmp_path, "can", 6.0)
    n = run.samples.shape[0]
    down, up = (i - first for i in _fault_window(log))
    gaps = [e for e in run.events if e.kind == "gap"]
    assert len(gaps) == 1, gaps
    gap = gaps[0]  # from the first scan not received: the simulator's first not sent, or one in flight
    assert down - IN_FLIGHT_S * 512 <= gap.sample_index <= down
    assert up <= gap.sample_index + gap.count <= up + 256
    corrupt: dict[int, set] = {}
    for f in log:
        row = f["first_index"] - first
        if f["fault"] == "corrupt" and 0 <= row < n and not gap.sample_index <= row < up:
            corrupt.setdefault(row, set()).add(f["group"])
    assert len(corrupt) >= 10
    ev = {e.sample_index: e for e in run.events if e.kind == "corrupt"}
    n_lost = 0
    for row, groups in corrupt.items():  # the bad frame's channels (3 a frame) are empty in that scan only
        assert ev[row].count == len(groups)
        cols = [3 * g + k for g in groups for k in range(3) if 3 * g + k < run.samples.shape[1]]
        assert np.isnan(run.samples[row, cols]).all()
        assert np.isfinite(np.delete(run.samples[row], cols)).all()
        n_lost += len(cols)
    src, steps = _reference("can", 512.0)
    good = ~np.isnan(run.samples)
    assert (np.abs(run.samples - src.physical(first, n))[good] / np.broadcast_to(steps, good.shape)[good]
            ).max() <= 1.0
    assert (~good).sum() == n_lost + 7 * gap.count  # nothing else missing


@pytest.mark.slow
def test_modbus_faults_are_events_at_their_samples(tmp_path):
    """The logger keeps a sample whose poll was answered with an exception, and its FIFO holds the
    samples of the 0.5 s disconnect: polled by its counter, every sample is stored at its row, except at
    most the one answer in flight as the server stopped (a one-row gap there); the exception answers
    are counted in the run's ``polls`` attribute."""
    run, _, log = _faulted_run(tmp_path, "modbus")
    n = run.samples.shape[0]
    counter = run.samples[:, 0]
    good = ~np.isnan(counter)
    np.testing.assert_array_equal(counter[good], np.flatnonzero(good))  # every good sample at its row
    down = next(f["first_index"] for f in log if f["fault"] == "disconnect")
    lost = np.flatnonzero(~good)
    assert lost.size <= 1 and set(lost) <= {down - 1, down}  # consumed, answer lost as the server stopped
    assert {e.sample_index: e.count for e in run.events if e.kind in ("corrupt", "gap")} == {
        int(r): 1 for r in lost}
    src, steps = _reference("modbus", 200.0)
    assert (np.abs(run.samples[good, 1:] - src.physical(0, n)[good]) / steps).max() <= 1.0
    corrupt = [f for f in log if f["fault"] == "corrupt" and f["first_index"] < n]
    assert len(corrupt) >= 1 and json.loads(run.attrs["polls"])["plc"]["exceptions"] >= len(corrupt)


def test_sigkill_of_acquire_keeps_all_but_last_second(tmp_path):
    out = tmp_path / "run.h5"
    config = _session(tmp_path, "serial")
    proc = subprocess.Popen([sys.executable, "-m", "flexmodal", "--quiet", "acquire", "--config", str(config),
                             "--out", str(out), "--duration", "60"], cwd=REPO, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    seen: list[tuple[float, int]] = []  # (time, samples visible to a SWMR reader)
    deadline = time.monotonic() + 300  # a hang guard: a niced acquire's start alone took 20 s at load 20
    try:
        with CpuWait(proc.pid) as waits:
            while time.monotonic() < deadline and (not seen or seen[-1][1] < 5 * 2048):
                time.sleep(0.1)
                assert proc.poll() is None
                try:
                    with h5py.File(out, "r", libver="latest", swmr=True) as f:  # read while it grows
                        seen.append((time.monotonic(), next(iter(f["runs"].values()))["samples"].shape[0]))
                except (OSError, KeyError, StopIteration):
                    continue
            t_kill = time.monotonic()
            proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    (t0, n0), (t1, n1) = next(x for x in seen if x[1] > 0), seen[-1]
    assert n1 >= 5 * 2048
    rate = (n1 - n0) / (t1 - t0)  # how fast samples arrived (2048/s unless the machine is starved)
    # + what was not flushed yet when last seen; the time acquire (or this test) waited for a CPU between
    # the last look and the kill not counted (tests/cpu_wait.py)
    in_hand = n1 + rate * waits.unloaded(t1, t_kill) + 0.5 * rate
    run, first = _run(out)
    n = run.samples.shape[0]
    assert n >= in_hand - 2048  # all but at most the last second
    src, steps = _reference("serial", 2048.0)
    assert (np.abs(run.samples - src.physical(first, n)) / steps).max() <= 1.0


def test_unwritable_output_is_a_clear_error(tmp_path):
    done = _acquire(_session(tmp_path, "serial"), tmp_path / "missing" / "run.h5")
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "does not exist" in done.stderr
