"""Clean ends of `flexmodal acquire` under signals, lost devices, a full disk and a concurrent --recover.

Real stack only: each protocol's example session with its simulator process (pty / slcan pty / Modbus
TCP on 127.0.0.1), the real HDF5 file, read back with plain h5py (no SWMR flag, no flexmodal) after the
process ended.  Waits are bounded; assertions are on counts and events.
"""

from __future__ import annotations

import fcntl
import json
import os
import pty
import random
import re
import select
import signal
import subprocess
import sys
import termios
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from cpu_wait import CpuWait
from interrupt_support import exit_seen
from polled import assert_missing_rows_are_reported_gaps

REPO = Path(__file__).resolve().parents[1]
SESSIONS = REPO / "examples" / "sessions"
RATES = {"serial": 2048.0, "can": 512.0, "modbus": 200.0}
# Waits for a process to start, store or end: generous, as on a loaded machine a niced acquire needed
# 20 s to store its first CAN sample (26 Nov, load 20 and two busy loops); the bounds that are promises
# are checked on their own clock (tests/cpu_wait.py)
START_S = 240.0
pytestmark = pytest.mark.timeout(1200)


# A device counts as lost after reconnect_timeout_s (10 s by default) without a sample, on the wall
# clock; a simulator starved of CPU that long on a loaded machine would end a session that is meant to
# meet a signal, so those sessions wait 120 s (the lost-device cases set their own timeout).
PATIENT = "reconnect_timeout_s = 120.0\n"
# and a serial/slcan simulator drops what its reader leaves unread for overrun_after_s (1 s by default): a
# reader starved that long lost samples (forced: acquire frozen 2.5 s, a 32-row gap); these runs must not
# (the Modbus simulator is made a logger whose FIFO holds 600 s: by default it holds the latest sample)
PATIENT_SIM = "overrun_after_s = 600.0\n"


def session_file(tmp_path: Path, protocol: str, extra: str = PATIENT, sim: str = PATIENT_SIM) -> Path:
    """The example session of ``protocol`` with absolute paths; ``extra`` top-level keys, ``sim`` lines
    added to its [simulator] block."""
    text = (SESSIONS / f"{protocol}-sim.toml").read_text()
    text = text.replace('rig = "../rigs/', f'rig = "{REPO}/examples/rigs/')
    text = text.replace('dbc = "../../fixtures/', f'dbc = "{REPO}/fixtures/')
    if protocol == "modbus" and sim == PATIENT_SIM:  # a logger with a FIFO, not the latest-value default
        sim += "modbus_fifo_s = 600.0\n"
    text = text.replace("[simulator]\n", f"[simulator]\n{sim}", 1)
    path = tmp_path / f"{protocol}.toml"
    path.write_text(extra + text)
    return path


def start_acquire(config: Path, out: Path, duration_s: float, *extra: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "flexmodal", "--quiet", "acquire", "--config", str(config),
                             "--out", str(out), "--duration", str(duration_s), *extra], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def stored(out: Path) -> int:
    """Samples a SWMR reader sees now (0 while the run is not there yet)."""
    try:
        with h5py.File(out, "r", libver="latest", swmr=True) as f:
            return next(iter(f["runs"].values()))["samples"].shape[0]
    except (OSError, KeyError, StopIteration):
        return 0


def wait_for(predicate, timeout_s: float, step_s: float = 0.05) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(step_s)
    return predicate()


def children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        out += [int(c) for c in (task / "children").read_text().split()]
    return out


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def plain_run(out: Path) -> tuple[np.ndarray, list[tuple[str, int, int, str]]]:
    """Samples and events read with plain h5py in another process (no SWMR, no flexmodal)."""
    code = ("import h5py, json, sys\n"
            "f = h5py.File(sys.argv[1], 'r')\n"
            "run = next(iter(f['runs'].values()))\n"
            "ev = [[e['kind'].decode(), int(e['sample_index']), int(e['count']), e['detail'].decode()] "
            "for e in run['events'][()]]\n"
            "import numpy; numpy.save(sys.argv[2], run['samples'][()])\n"
            "print(json.dumps(ev))\n")
    npy = out.with_suffix(".npy")
    done = subprocess.run([sys.executable, "-c", code, str(out), str(npy)], capture_output=True, text=True,
                          timeout=START_S, cwd=out.parent)
    assert done.returncode == 0, done.stderr
    return np.load(npy), [tuple(e) for e in json.loads(done.stdout)]


@pytest.mark.parametrize("protocol", ["serial", "can", "modbus"])
def test_sigterm_closes_the_run_cleanly(tmp_path, protocol):
    """Stops within 3 s of SIGTERM, keeping every sample but those of the last second before it; both
    counted without the time acquire's processes (and this test) were runnable but waiting for a CPU
    (tests/cpu_wait.py): the wall time on a quiet machine, whatever the load."""
    out = tmp_path / "run.h5"
    proc = start_acquire(session_file(tmp_path, protocol), out, 60)
    try:
        with CpuWait(proc.pid) as waits:
            assert wait_for(lambda: stored(out) > 0 or proc.poll() is not None, START_S), \
                f"no samples within {START_S} s"
            assert proc.poll() is None, f"ended before the signal: {proc.communicate()[1][-2000:]}"
            t_first = time.monotonic()
            time.sleep(random.Random(protocol).uniform(1.0, 3.0))  # a fixed moment per protocol
            sim = children(proc.pid)
            t_term = time.monotonic()
            proc.send_signal(signal.SIGTERM)
            t_exit = exit_seen(proc.pid, START_S)
            waits.sample()  # the zombie's counters (not reaped yet)
        stdout, stderr = proc.communicate(timeout=START_S)
    finally:
        proc.kill()
    elapsed, took = waits.unloaded(t_first, t_term), waits.unloaded(t_term, t_exit)
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    print(f"{protocol}: SIGTERM after {elapsed:.2f} s ({t_term - t_first:.2f} s wall) stopped in "
          f"{took:.2f} s ({t_exit - t_term:.2f} s wall)")
    assert took <= 3.0, f"took {took:.2f} s to stop ({t_exit - t_term:.2f} s wall)"
    assert str(out) in stdout and not stderr  # the summary line, no traceback
    assert sim and not any(alive(p) for p in sim)  # the simulator went with it
    samples, events = plain_run(out)
    print(f"{protocol}: kept {samples.shape[0] / RATES[protocol]:.2f} s of samples")
    assert samples.shape[0] >= (elapsed - 1.0) * RATES[protocol]
    assert ("stopped", samples.shape[0]) == events[-1][:2] and "SIGTERM" in events[-1][3]
    assert_complete(samples, events, protocol)
    assert not out.with_name("run.h5.lock").exists()


def test_sighup_and_sigint_stop_the_same_way(tmp_path):
    for sig in (signal.SIGHUP, signal.SIGINT):
        out = tmp_path / f"run-{sig.name}.h5"
        proc = start_acquire(session_file(tmp_path, "serial"), out, 60)
        try:
            assert wait_for(lambda o=out: stored(o) > 2048, START_S)
            proc.send_signal(sig)
            stdout, stderr = proc.communicate(timeout=START_S)
        finally:
            proc.kill()
        assert proc.returncode == 128 + sig, stderr
        samples, events = plain_run(out)
        assert samples.shape[0] > 2048 and events[-1][0] == "stopped" and sig.name in events[-1][3]


@pytest.mark.parametrize("protocol,device", [("serial", "adc"), ("can", "can0"), ("modbus", "plc")])
def test_killed_simulator_is_a_lost_device_and_ends_the_session(tmp_path, protocol, device):
    out = tmp_path / "run.h5"
    config = session_file(tmp_path, protocol, "reconnect_timeout_s = 5.0\n")  # 2 s: a starved CAN simulator
    # was lost before it had stored its first second (26 Nov, load 20 and two busy loops)
    proc = start_acquire(config, out, 60)
    try:
        assert wait_for(lambda: stored(out) > RATES[protocol] or proc.poll() is not None, START_S)
        assert proc.poll() is None, f"ended before its simulator was killed: {proc.communicate()[1]}"
        with CpuWait(proc.pid) as waits:
            for pid in children(proc.pid):
                os.kill(pid, signal.SIGKILL)
            t_kill = time.monotonic()
            t_exit = exit_seen(proc.pid, START_S)
            waits.sample()
        stdout, stderr = proc.communicate(timeout=START_S)
    finally:
        proc.kill()
    took = waits.unloaded(t_kill, t_exit)  # not counting time spent waiting for a CPU (tests/cpu_wait.py)
    assert proc.returncode == 2, stderr[-3000:]
    assert stderr.count("\n") == 1 and f"device {device!r} lost" in stderr
    print(f"{protocol}: session ended {took:.2f} s ({t_exit - t_kill:.2f} s wall) after the simulator was "
          "killed (timeout 5 s)")
    assert took <= 5.0 + 7.0  # the timeout, plus generous room
    samples, events = plain_run(out)
    kinds = [e[0] for e in events]
    assert "device_lost" in kinds and kinds[-1] == "stopped"
    assert_complete(samples, events, protocol)  # nothing padded after the last sample of the only device


def test_recover_refuses_a_file_a_live_acquire_is_writing(tmp_path):
    """The live acquire runs until this test stops it (SIGTERM), so the second command meets it live
    however long its own start takes under load."""
    out = tmp_path / "run.h5"
    proc = start_acquire(session_file(tmp_path, "serial"), out, 600)
    try:
        assert wait_for(lambda: stored(out) > 2048, START_S)
        second = subprocess.run([sys.executable, "-m", "flexmodal", "--quiet", "acquire", "--recover",
                                 "--config", str(session_file(tmp_path, "serial")), "--out", str(out),
                                 "--duration", "1", "--run-id", "second"], cwd=REPO, capture_output=True,
                                text=True, timeout=START_S)
        assert proc.poll() is None, "the live acquire ended before the second command was refused"
        before = stored(out)
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=START_S)
    finally:
        proc.kill()
    assert second.returncode == 2 and second.stderr.count("\n") == 1, second.stderr
    assert f"pid {proc.pid}" in second.stderr and "being written" in second.stderr
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    samples, events = plain_run(out)  # the live run is intact and closed cleanly
    assert samples.shape[0] >= before and ("stopped", samples.shape[0]) == events[-1][:2]
    assert not np.isnan(samples).any()


def assert_complete(samples: np.ndarray, events: list, protocol: str) -> None:
    """No sample missing, and the last row a sample (nothing padded); a Modbus poller starved of CPU
    misses polls, which are then reported gaps (tests/polled.py); streamed protocols miss nothing."""
    assert np.isfinite(samples[-1]).all()
    if protocol == "modbus":
        assert_missing_rows_are_reported_gaps(samples, [(e[1], e[2]) for e in events if e[0] == "gap"])
    else:
        assert not np.isnan(samples).any()


def _file_size_limit(n_bytes: int):
    """preexec_fn: the process (and its simulator) may not grow a file beyond ``n_bytes`` (EFBIG)."""
    import resource

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, n_bytes))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    return limit


def _emitted(rate: float):
    from flexmodal.fixtures.sim_source import sim_source

    src = sim_source(None, "impact", rate)
    return src, np.array([c.step for c in src.channels])


def _run_first_index(out: Path) -> int:
    with h5py.File(out, "r") as f:
        return next(iter(json.loads(next(iter(f["runs"].values())).attrs["first_index"]).values()))


def test_disk_nearly_full_at_start_is_refused_before_anything_is_written(tmp_path):
    out = tmp_path / "run.h5"
    proc = start_acquire(session_file(tmp_path, "serial"), out, 5, preexec_fn=_file_size_limit(4_000_000))
    _, stderr = proc.communicate(timeout=START_S)
    assert proc.returncode == 2 and stderr.count("\n") == 1
    assert re.search(r"only 4\.0 MB free for it; the run needs 0\.\d MB \+ 8 MB reserve", stderr)
    assert not out.exists() and not out.with_name("run.h5.lock").exists()


def test_disk_full_mid_run_stops_cleanly_with_the_run_intact(tmp_path):
    rate = 65536.0  # 1.8 MB/s: the 4 MB above the reserve fill in ~2 s
    out = tmp_path / "run.h5"
    config = session_file(tmp_path, "serial")
    config.write_text(config.read_text().replace("sample_rate_hz = 2048.0", f"sample_rate_hz = {rate}"))
    proc = subprocess.Popen([sys.executable, "-m", "flexmodal", "--quiet", "acquire", "--config", str(config),
                             "--out", str(out)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_file_size_limit(12_000_000))
    try:
        stdout, stderr = proc.communicate(timeout=START_S)
    finally:
        proc.kill()
    assert proc.returncode == 2 and stderr.count("\n") == 1 and "disk full" in stderr, stderr
    assert str(out) in stdout  # the summary of what was stored
    samples, events = plain_run(out)
    n = samples.shape[0]
    assert n > rate  # more than a second stored before the disk filled
    assert events[-1][0] == "stopped" and "disk full" in events[-1][3] and events[-1][1] == n
    src, steps = _emitted(rate)
    assert (np.abs(samples - src.physical(_run_first_index(out), n)) / steps).max() <= 1.0  # no zeros


def test_write_failure_at_the_final_flush_leaves_no_zeros(tmp_path):
    """The reserve check switched off: the last write itself fails (EFBIG); what is stored stays
    readable with plain h5py and rows that could not be written read NaN, never 0."""
    rate = 16384.0
    out = tmp_path / "run.h5"
    config = session_file(tmp_path, "serial")
    config.write_text(config.read_text().replace("sample_rate_hz = 2048.0", f"sample_rate_hz = {rate}"))
    chunk_rows = (1 << 20) // (4 * 7)  # one samples chunk of the 7-channel run (daq.store.CHUNK_BYTES)
    duration = (chunk_rows + 100) / rate  # chunk 1 fits under the limit, the tail written at close not
    code = ("import sys; import flexmodal.daq.acquire as a; a.DISK_RESERVE_BYTES = 0\n"
            "from flexmodal.app import main; sys.exit(main())\n")
    done = subprocess.run([sys.executable, "-c", code, "--quiet", "acquire", "--config", str(config), "--out",
                           str(out), "--duration", repr(duration)], cwd=REPO, capture_output=True, text=True,
                          timeout=START_S, preexec_fn=_file_size_limit(1_200_000))
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "writing failed" in done.stderr
    samples, _ = plain_run(out)
    good = ~np.isnan(samples).any(axis=1)
    assert good.sum() >= chunk_rows // 2  # what was flushed is there ...
    assert not (samples[~good] == 0).any()  # ... and nothing unwritten poses as a sample
    src, steps = _emitted(rate)
    ref = src.physical(_run_first_index(out), samples.shape[0])
    assert (np.abs(samples[good] - ref[good]) / steps).max() <= 1.0


# 5 s, not 2 s: a starved healthy simulator must not be declared lost too (the lost-device cases above
# use 5 s for the same reason); a left-behind device is no longer waited for after STALL_S (0.5 s).
TWO_DEVICES = """
sample_rate_hz = 2048.0
reconnect_timeout_s = 5.0
continue_on_device_loss = true
""" + "".join(f"""
[[device]]
name = "{d}"
protocol = "serial"
port = "{{{d}}}"
sources = ["ch0", "ch1", "ch2", "ch3", "ch4", "ch5", "ch6"]
[[channel]]
name = "F_{d}"
kind = "force"
unit = "N"
device = "{d}"
source = "ch0"
[[channel]]
name = "a1_{d}"
kind = "acceleration"
unit = "m/s^2"
device = "{d}"
source = "ch1"
""" for d in ("left", "right"))


def _serve_serial() -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "flexmodal", "sim", "serve", "--protocol", "serial",
                             "--quiet"], cwd=REPO, stdout=subprocess.PIPE, text=True)
    return proc, proc.stdout.readline().strip()


def test_one_lost_device_never_holds_back_the_other(tmp_path):
    (left, left_port), (right, right_port) = _serve_serial(), _serve_serial()
    config = tmp_path / "two.toml"
    config.write_text(TWO_DEVICES.replace("{left}", left_port).replace("{right}", right_port))
    out = tmp_path / "run.h5"
    fs, duration = 2048.0, 14.0  # the right device is killed 2 s in and declared lost about 5 s later
    proc = start_acquire(config, out, duration)
    polls: list[tuple[float, int]] = []
    held = 0
    try:
        with CpuWait(proc.pid, left.pid, right.pid) as waits:
            assert wait_for(lambda: stored(out) > 0, START_S)
            t_start = time.monotonic()
            while proc.poll() is None and time.monotonic() - t_start < 120:
                polls.append((time.monotonic(), stored(out)))
                if right.poll() is None and time.monotonic() - t_start > 2.0:
                    # the right device vanishes for good: its pty is held open here, so the kernel cannot
                    # give its number to a pty another process opens meanwhile (a simulator of a test run
                    # beside this one), which the acquire's reconnect would then read as this device
                    held = held or os.open(right_port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
                    right.kill()
                    t_kill = time.monotonic()
                time.sleep(0.05)
            stdout, stderr = proc.communicate(timeout=START_S)
    finally:
        for p in (proc, left, right):
            p.kill()
            p.wait()
        if held:
            os.close(held)
    assert proc.returncode == 0, stderr
    t = np.array([p[0] for p in polls])
    n = np.array([p[1] for p in polls], float)
    # seconds of real time not yet in the file, real time counted without the time the acquire, its
    # two simulators (or this test) were runnable but waiting for a CPU (tests/cpu_wait.py)
    waited = np.array([waits.waited(t[0], ti) for ti in t])
    behind = (t - t[0]) - waited - n / fs
    baseline = behind[t < t_kill].min()
    after = (t > t_kill) & (n < duration * fs)
    lag = behind[after] - baseline
    wall_lag = (behind + waited)[after] - (behind + waited)[t < t_kill].min()
    print(f"healthy device: file behind real time by at most {lag.max():.2f} s ({wall_lag.max():.2f} s "
          "wall) after the other was lost")
    assert after.sum() >= 10 and lag.max() <= 1.5, f"file lagged real time by up to {lag.max():.2f} s"
    samples, events = plain_run(out)
    assert samples.shape[0] == duration * fs
    # every sample of the healthy device: the run's row 0 is the first sample of whichever device
    # delivered first (docs/acquisition.md), so rows before the healthy device's own first sample are
    # NaN, and never reported as a gap (a later start is not a gap); after it, not one NaN
    lead = int(np.argmax(np.isfinite(samples[:, 0])))
    assert lead < duration * fs / 4 and np.isfinite(samples[lead:, :2]).all()
    assert np.isnan(samples[:lead, :2]).all()
    assert not [e for e in events if e[0] in ("gap", "corrupt") and e[3].startswith("left")]
    last = int(np.flatnonzero(np.isfinite(samples[:, 2]))[-1]) + 1  # the lost device's last sample
    in_flight_s = 1.5 + waits.waited(t[0], t_kill)  # what the file lagged at the kill, at most
    assert last <= n[t <= t_kill][-1] + in_flight_s * fs and np.isnan(samples[last:, 2:]).all()  # NaN ...
    right = [e[:3] for e in events if e[3].startswith("right")]
    assert ("gap", last, samples.shape[0] - last) in right  # ... reported as one gap, sample for sample
    assert [e[0] for e in right].count("device_lost") == 1


def test_closing_the_terminal_stops_cleanly(tmp_path):
    """acquire with its live view on a pseudo-terminal that is its controlling terminal; closing the
    terminal (master side) sends SIGHUP and leaves a display that can no longer be written."""
    out = tmp_path / "run.h5"
    master, slave = pty.openpty()

    def own_terminal() -> None:
        os.setsid()
        fcntl.ioctl(slave, termios.TIOCSCTTY, 0)

    proc = subprocess.Popen([sys.executable, "-m", "flexmodal", "acquire", "--config",
                             str(session_file(tmp_path, "serial")), "--out", str(out), "--duration", "60"],
                            cwd=REPO, stdin=slave, stdout=subprocess.PIPE, stderr=slave,
                            preexec_fn=own_terminal, pass_fds=(slave,), text=True)
    os.close(slave)
    try:
        end = time.monotonic() + START_S
        while stored(out) < 2048 and time.monotonic() < end:
            if select.select([master], [], [], 0.05)[0]:
                os.read(master, 65536)  # keep the terminal drained while it runs
        os.close(master)  # the terminal goes away
        stdout, _ = proc.communicate(timeout=START_S)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGHUP
    samples, events = plain_run(out)
    assert samples.shape[0] >= 2048 and events[-1][0] == "stopped" and "SIGHUP" in events[-1][3]
    assert not np.isnan(samples).any()
