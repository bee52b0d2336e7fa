"""Issue 13, point 7: Ctrl-C (SIGINT) stops every long command within 1 s with exit 130, one line on
stderr and no traceback, and leaves no output half-written (checked_io.output.atomic_path: the output is
absent, or whole from before; no temporary file stays behind).

Each command runs as the real console script on inputs big enough that it is still working when the
signal comes: SIGINT is sent once the process has used a given amount of CPU time (past its imports,
inside the computation), or once the child process it waits on exists.  Measured on the shared 2-core
machine under load (load average 5-10, several test runs at once): 0.01-0.2 s for every case but
acquire mid-recording (0.1-0.45 s: the readers, the simulator child and the file are closed first);
the limit below is the issue's 1 s, counted without the time the command's processes (and this test)
were runnable but waiting for a CPU (tests/cpu_wait.py; 26 Nov at load 20 with two busy loops beside
it: 1.2-2.8 s wall for 0.17-0.29 s of it).  Known exception (slow case): a CAN reader that is draining an
slcan backlog after a stall finishes that read first, 1.43 s once under load (daq/can_driver.py).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from interrupt_support import EXE, alive, children, cpu_s, descendants, interrupt, still_alive
from modal_cases import four_mode_random_record

from flexmodal.daq.store import Channel, RunWriter

REPO = Path(__file__).resolve().parents[1]
RIGS = REPO / "examples" / "rigs"
LIMIT_S = 1.0  # issue 13
def after_cpu(seconds: float) -> Callable[[int], bool]:
    return lambda pid: cpu_s(pid) >= seconds


def check(code: int, seconds: float, err: str, folder: Path, absent: tuple[str, ...] = ()) -> None:
    assert code == 130, err[-2000:]
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err[-2000:]
    assert seconds < LIMIT_S, f"exit took {seconds:.2f} s"
    print(f"exit 130 {seconds:.3f} s after SIGINT")  # shown with pytest -s
    assert [p.name for p in folder.rglob("*.part")] == []
    assert [name for name in absent if (folder / name).exists()] == []


@pytest.fixture(scope="module")
def runs_file(tmp_path_factory) -> Path:
    """Four random-test runs of 10 min at 1024 Hz (force + 3 accelerations, 4 known modes), no FRFs."""
    return _write_runs(tmp_path_factory.mktemp("runs") / "runs.h5", seed=3, duration_s=600.0, n_runs=4,
                       step_deg=10.0)


def _write_runs(path: Path, *, seed: int, duration_s: float, n_runs: int, step_deg: float) -> Path:
    """``n_runs`` random-test runs at 1024 Hz (force + 3 accelerations of the four-mode system), at
    theta_deg = k * step_deg, written to ``path``."""
    record = four_mode_random_record(np.random.default_rng(seed), 1024.0, duration_s)
    channels = [Channel("F", "force", "N")] + [Channel(f"a{k}", "acceleration", "m/s^2") for k in (1, 2, 3)]
    for k in range(n_runs):
        with RunWriter(path, f"r{k}", sample_rate_hz=1024.0, channels=channels, excitation="random",
                       pose={"theta_deg": step_deg * k}) as writer:
            writer.append(record)
    return path


@pytest.fixture(scope="module")
def many_runs(runs_file, tmp_path_factory) -> Path:
    """``runs_file`` with 124 more runs, each a second name (HDF5 hard link) of one of its four: 128 runs
    on the disk space of 4.  ``frf`` needs 3.2 s of CPU on them (measured; 0.56 s on the four runs,
    which left a few tenths of a second after the first run's FRFs, so under load the signal could
    land in the interpreter's tear-down), about 3 s after the trigger below."""
    path = tmp_path_factory.mktemp("many_runs") / "runs.h5"
    shutil.copyfile(runs_file, path)
    with h5py.File(path, "a") as f:
        for k in range(4, 128):
            f[f"runs/r{k}"] = f[f"runs/r{k % 4}"]
    return path


def test_frf_over_several_runs(many_runs, tmp_path):
    """Serial batch into --out, interrupted once the first run's FRFs are there: the runs written
    before the signal are whole, and the file closed cleanly."""
    out = tmp_path / "frf.h5"
    check(*interrupt(["frf", str(many_runs), "--workers", "0", "--nfft", "256", "--out", str(out)],
                     tmp_path, lambda _pid: out.exists()), tmp_path)
    from flexmodal.modal.runs_io import read_frf

    if out.exists():
        with h5py.File(out, "r") as f:  # plain h5py: the file was closed cleanly
            written = list(f["runs"]) if "runs" in f else []
        for rid in written:
            assert read_frf(out, rid).H.shape[:2] == (3, 1)


def test_frf_on_a_dask_local_cluster(runs_file, tmp_path):
    """--workers 2: SIGINT while the pool's processes start; the command and every process it started
    (fork server, workers; they hold its stderr) are gone within the limit."""
    seen: list[int] = []

    def cluster_starting(pid: int) -> bool:
        seen[:] = sorted(set(seen) | set(descendants(pid)))
        return len(seen) >= 3  # fork server, resource tracker, workers

    args = ["frf", str(runs_file), "--workers", "2", "--out", "frf.h5"]
    check(*interrupt(args, tmp_path, cluster_starting), tmp_path)
    assert still_alive(seen, LIMIT_S) == []


@pytest.fixture(scope="module")
def runs_with_frfs(runs_file, tmp_path_factory) -> Path:
    """``runs_file`` with every run's FRFs stored (``flexmodal frf`` in place): identify and report then
    identify each run from its stored FRFs, 11-18 s of CPU in all (measured: identify 11.3 s, report
    17.9 s; on ``runs_file`` without FRFs they need 2.8 s and 2.0 s, which left 0.8-1.6 s of work after
    the trigger, so under load the signal could land in the interpreter's tear-down)."""
    path = tmp_path_factory.mktemp("frf_runs") / "runs.h5"
    shutil.copyfile(runs_file, path)
    subprocess.run([EXE, "--quiet", "frf", str(path), "--workers", "0"], check=True, capture_output=True,
                   timeout=600)
    return path


@pytest.fixture(scope="module")
def many_runs_with_frfs(tmp_path_factory) -> Path:
    """64 random-test runs of 60 s (the four-mode system) with their FRFs stored.  Identify from stored
    FRFs needs about 0.07 s of CPU per run once the order search got faster (measured: 4 runs 1.6 s and
    32 runs 3.4 s in all, start-up included; on 4 runs the 1.2 s trigger landed in the interpreter's
    tear-down, exit -2 in a stress run), so 64 runs leave about 4 s of work after the trigger."""
    path = _write_runs(tmp_path_factory.mktemp("many_frf_runs") / "runs.h5", seed=5, duration_s=60.0,
                       n_runs=64, step_deg=2.5)
    subprocess.run([EXE, "--quiet", "frf", str(path), "--workers", "0"], check=True, capture_output=True,
                   timeout=600)
    return path


def test_identify(many_runs_with_frfs, tmp_path):
    check(*interrupt(["identify", str(many_runs_with_frfs), "--out", "modes.csv"], tmp_path, after_cpu(1.2)),
          tmp_path, ("modes.csv", "modes.synthesis.csv"))


def test_report(runs_with_frfs, tmp_path):
    check(*interrupt(["report", str(runs_with_frfs), "--out", "report.html"], tmp_path, after_cpu(1.2)),
          tmp_path, ("report.html",))


def _poses(path: Path, n: int, step_deg: float) -> Path:
    path.write_text("config,pose.theta_deg\n" + "".join(f"c{k},{k * step_deg:g}\n" for k in range(n)))
    return path


def _soft_elbow_rig(tmp_path: Path) -> Path:
    text = (RIGS / "demo_arm.toml").read_text()
    assert text.count('kind = "rigid"') == 1
    rig = tmp_path / "soft.toml"
    rig.write_text(text.replace('kind = "rigid"', 'kind = "spring"\nk_Nm_per_rad = 8000.0'))
    return rig


def test_predict_with_a_large_frame(tmp_path):
    """2400-DOF frames: the eigen-solve runs in a worker process, which is killed with the command."""
    _poses(tmp_path / "poses.csv", 2, 30.0)
    seen: list[int] = []

    def solving(pid: int) -> bool:
        seen[:] = children(pid) or seen
        return bool(seen) and cpu_s(seen[0]) >= 0.5  # the worker is inside its first eigen-solve

    check(*interrupt(["predict", str(RIGS / "demo_arm.toml"), "--model", "fe", "--poses", "poses.csv",
                      "--out", "pred.csv", "--elements", "400"], tmp_path, solving), tmp_path, ("pred.csv",))
    assert still_alive(seen, LIMIT_S) == [], "the eigen worker outlived the command"


@pytest.mark.slow  # ~10 s; pure-Python work is interrupted as in identify and report
def test_diagnose(tmp_path):
    rig = RIGS / "demo_arm.toml"
    measured = tmp_path / "measured.csv"
    subprocess.run([EXE, "--quiet", "predict", str(_soft_elbow_rig(tmp_path)), "--model", "fe", "--poses",
                    str(_poses(tmp_path / "poses.csv", 32, 3.5)), "--out", str(measured)], check=True,
                   capture_output=True)
    # 32 poses: diagnose needs 4.6 s of CPU (measured; 2.9 s for 8 poses), 3.4 s after the
    # trigger, so the signal cannot land in the interpreter's tear-down however loaded the machine is
    check(*interrupt(["diagnose", "--rig", str(rig), "--measured", str(measured), "--out", "dg"],
                     tmp_path, after_cpu(1.2)), tmp_path, ("dg/diagnosis.json", "dg/diagnosis.html"))


@pytest.mark.slow  # ~10 s; pure-Python work is interrupted as in identify and report
def test_compare_of_large_tables(tmp_path):
    poses = str(_poses(tmp_path / "poses.csv", 400, 0.3))
    for rig, out in ((RIGS / "demo_arm.toml", "pred.csv"), (_soft_elbow_rig(tmp_path), "meas.csv")):
        subprocess.run([EXE, "--quiet", "predict", str(rig), "--model", "fe", "--poses", poses, "--modes",
                        "8", "--out", str(tmp_path / out)], check=True, capture_output=True)
    for name in ("pred.csv", "meas.csv"):  # 30 copies of each configuration (96 000 rows): compare needs
        # ~5 s of CPU (measured: 0.9 s on the 3 200 predicted rows, less than the trigger; 2.4 s on 10
        # copies), >= 3 s after the trigger
        header, *rows = (tmp_path / name).read_text().splitlines()
        copies = [f"{c}r{j},{rest}" for j in range(30) for c, rest in (r.split(",", 1) for r in rows)]
        (tmp_path / name).write_text("\n".join([header, *copies]) + "\n")
    check(*interrupt(["compare", "meas.csv", "pred.csv", "--out", "table.md"], tmp_path, after_cpu(1.0)),
          tmp_path, ("table.md",))


def test_acquire_while_its_simulator_starts(tmp_path):
    """SIGINT while the session's simulator child is still starting: the launcher stops waiting for
    its endpoint at once, the child is ended, nothing was stored, exit 130.  The child is frozen
    (SIGSTOP) as soon as it runs `sim serve` (its imports take a second before it announces its
    endpoint) and thawed only once the launcher's SIGTERM is pending on it, so it cannot have started
    by the time SIGINT arrives however loaded the machine is: one outcome, one message."""
    text = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text()
    (tmp_path / "s.toml").write_text(text.replace('rig = "../rigs/', f'rig = "{RIGS}/'))
    seen: list[int] = []
    measured = threading.Event()

    def thaw_when_ended(kid: int) -> None:
        with contextlib.suppress(OSError):  # on time under any load (a tiny job every 5 ms): the
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))  # launcher's grace is wall time
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and alive(kid) and not _pending(kid, signal.SIGTERM):
            time.sleep(0.005)
        with contextlib.suppress(ProcessLookupError):
            os.kill(kid, signal.SIGCONT)
        measured.wait(300)  # on the exit's critical path: its CPU waiting is counted only while it lives

    def starting(pid: int) -> bool:   # the child once it runs `sim serve` (frozen before its exec,
        kids = [k for k in children(pid) if b"serve" in _cmdline(k)]   # it would hold Popen up)
        if not seen and kids:
            seen[:] = kids
            for kid in kids:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(kid, signal.SIGSTOP)
                threading.Thread(target=thaw_when_ended, args=(kid,), daemon=True).start()
        return bool(seen)

    try:
        code, seconds, err = interrupt(["acquire", "--config", "s.toml", "--out", "run.h5", "--duration",
                                        "5"], tmp_path, starting)
    finally:
        measured.set()
    check(code, seconds, err, tmp_path, ("run.h5",))
    assert "stopped by SIGINT before any sample was stored (the simulator was starting)" in err
    assert still_alive(seen, LIMIT_S) == [], "the simulator child outlived the command"


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except (FileNotFoundError, ProcessLookupError):
        return b""


def _pending(pid: int, signum: int) -> bool:
    """Whether signal ``signum`` is pending on process ``pid`` (Linux /proc/PID/status SigPnd, ShdPnd)."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except (FileNotFoundError, ProcessLookupError):
        return False
    masks = [int(line.split()[1], 16) for line in lines if line.startswith(("SigPnd:", "ShdPnd:"))]
    return any(m >> (signum - 1) & 1 for m in masks)


@pytest.mark.parametrize("protocol", ["serial", pytest.param("can", marks=pytest.mark.slow),
                                      pytest.param("modbus", marks=pytest.mark.slow)])
def test_acquire_mid_recording(tmp_path, protocol):
    """SIGINT while recording from a simulator child: the run is closed with what was recorded (that
    is the point of acquire, not a half-written file: plain h5py reads it), the simulator child ends
    with the command, exit 130 (a duration was asked for)."""
    text = (REPO / "examples" / "sessions" / f"{protocol}-sim.toml").read_text()
    text = text.replace('rig = "../rigs/', f'rig = "{RIGS}/').replace('dbc = "../../fixtures/',
                                                                     f'dbc = "{REPO}/fixtures/')
    (tmp_path / "s.toml").write_text(text)
    out, seen, since = tmp_path / "run.h5", [], []

    def recording(pid: int) -> bool:
        seen[:] = children(pid) or seen
        if not since and out.exists():
            since.append(time.monotonic())
        return bool(since) and time.monotonic() - since[0] >= 0.5

    code, seconds, err = interrupt(["acquire", "--config", "s.toml", "--out", "run.h5", "--duration", "30"],
                                   tmp_path, recording)
    assert (code, err) == (130, ""), err[-2000:]
    assert seconds < LIMIT_S, f"exit took {seconds:.2f} s"
    print(f"exit 130 {seconds:.3f} s after SIGINT")
    with h5py.File(out, "r") as f:
        run = next(iter(f["runs"].values()))
        assert run["samples"].shape[0] > 0
    assert still_alive(seen, LIMIT_S) == []
