"""Issue 24: a terminal's Ctrl-C (SIGINT to the whole process group) at any moment of a worker pool's
start ends the command with its one line "flexmodal: interrupted", exit 130, no traceback from it or
from any child, no process left, and no output half-written.

The point of the signal is chosen by what is seen, not by timing: the command runs in its own process
group, which the test runs in steps of about a millisecond (SIGCONT, sleep, SIGSTOP, wait until every
member is stopped) and inspects while it is stopped (/proc: members, what each has mapped, whether it
ignores or blocks SIGINT).  Once the wanted stage is seen, SIGINT goes to the stopped group and is
delivered exactly there when it continues.  Load only makes the steps finer (each gives the group less
CPU); a step that skipped over a short stage is retried with a new command and a finer step.

Before the fix (issue 24: one ``frf --workers 2`` in three printed a child's traceback) the fork
server's imports (stage "fork server importing") and its interpreter start printed KeyboardInterrupt
tracebacks: it is now started with SIGINT blocked, and so is every worker it forks until the worker
ignores it (checked_io/children.py).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import pytest
from interrupt_support import EXE

from flexmodal.daq.store import Channel, RunWriter

SIGINT_BIT = 1 << (signal.SIGINT - 1)
RIGS = Path(__file__).resolve().parents[1] / "examples" / "rigs"


@dataclass(frozen=True)
class Member:
    """One process of the command's process group, seen while it is stopped."""

    pid: int
    ppid: int
    state: str
    cmdline: str
    cpu_s: float
    blocks_sigint: bool
    ignores_sigint: bool

    def maps(self, name: str) -> bool:
        """Whether the process has a file whose path holds ``name`` mapped (a library it imported)."""
        try:
            return name in Path(f"/proc/{self.pid}/maps").read_text()
        except OSError:
            return False


def _member(pid: int, pgid: int) -> Member | None:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        if int(stat[2]) != pgid:
            return None
        status = dict(line.split(":\t", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
                      if ":\t" in line)
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except (OSError, ValueError, IndexError):   # gone meanwhile
        return None
    tick = os.sysconf("SC_CLK_TCK")
    return Member(pid, int(stat[1]), stat[0], cmdline, (int(stat[11]) + int(stat[12])) / tick,
                  bool(int(status["SigBlk"], 16) & SIGINT_BIT), bool(int(status["SigIgn"], 16) & SIGINT_BIT))


class Group:
    """The process group ``pgid``, run in steps and inspected while stopped."""

    def __init__(self, pgid: int) -> None:
        self.pgid = pgid

    def members(self) -> list[Member]:
        found = (_member(int(p), self.pgid) for p in os.listdir("/proc") if p.isdigit())
        return sorted((m for m in found if m is not None), key=lambda m: m.pid)

    def stop(self) -> list[Member]:
        """SIGSTOP the group; return its members once none runs user code (stopped, exited, or in an
        uninterruptible wait such as the parent of a stopped vfork child)."""
        deadline = time.monotonic() + 120.0
        while True:
            os.killpg(self.pgid, signal.SIGSTOP)
            members = self.members()
            if all(m.state in "TtZXD" for m in members):
                return members
            assert time.monotonic() < deadline, f"group {self.pgid} does not stop: {members}"
            time.sleep(0.0005)

    def step(self, seconds: float) -> list[Member]:
        os.killpg(self.pgid, signal.SIGCONT)
        time.sleep(seconds)
        return self.stop()


Stage = Callable[[int, list[Member]], int]   # (command pid, members) -> how far the start has come


def _pool_stage(pid: int, members: list[Member]) -> int:
    """How far ``flexmodal frf --workers 2``'s pool start has come (0-7), from the stopped group."""
    parent = next(m for m in members if m.pid == pid)
    server = [m for m in members if "forkserver" in m.cmdline]
    workers = [m for m in members if server and m.ppid == server[0].pid]
    if not workers:
        if not server:
            others = [m for m in members if m.pid != pid]
            return 2 if others else 1 if parent.maps("libhdf5") else 0
        return 4 if server[0].maps("numpy") else 3
    if not workers[0].ignores_sigint:
        return 5
    busy = [w for w in workers if w.ignores_sigint and w.cpu_s >= 0.1]
    return 7 if len(busy) >= 2 else 6


POOL_STAGES = {1: "before the pool (runs listed)", 3: "fork server starting", 4: "fork server importing",
               7: "workers computing"}   # 5 (a worker before its initializer) lasts ~1 ms: see below


def _eigen_stage(pid: int, members: list[Member]) -> int:
    """How far ``flexmodal predict``'s eigen worker has come (0-4)."""
    worker = [m for m in members if "eigen_worker" in m.cmdline]
    if not worker:
        return 0
    if not worker[0].ignores_sigint:
        return 2 if worker[0].maps("numpy") else 1
    return 4 if worker[0].cpu_s >= 0.5 else 3


EIGEN_STAGES = {1: "eigen worker starting", 2: "eigen worker importing", 4: "eigen worker solving"}


@dataclass(frozen=True)
class Interrupted:
    code: int
    stderr: str
    seen: list[Member]      # the group when the signal was sent
    left: list[Member]      # its members still alive afterwards (not zombies)


def _interrupt_at(args: list[str], cwd: Path, stage: Stage, target: int, step_s: float,
                  whole_group: bool = True, command: tuple[str, ...] = (EXE,)) -> Interrupted | None:
    """Run ``flexmodal --quiet ARGS`` (or ``command --quiet ARGS``) in a process group of its own, in
    steps of ``step_s``, until ``stage`` reaches ``target``; then SIGINT (to the whole group, as a
    terminal's Ctrl-C, or to the command only) and let it go on.  None when a step went past
    ``target`` (try a finer step)."""
    proc = subprocess.Popen([*command, "--quiet", *args], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
                            start_new_session=True)
    group = Group(proc.pid)
    try:
        members = group.stop()
        deadline = time.monotonic() + 600.0
        while (reached := stage(proc.pid, members)) < target:
            assert proc.poll() is None, f"ended (exit {proc.returncode}) before stage {target}: {members}"
            assert time.monotonic() < deadline, f"stage {target} not reached; at {reached}: {members}"
            members = group.step(step_s)
        if reached > target:
            return None
        if whole_group:
            os.killpg(proc.pid, signal.SIGINT)
        else:
            os.kill(proc.pid, signal.SIGINT)
        os.killpg(proc.pid, signal.SIGCONT)
        _, err = proc.communicate(timeout=300)
        left = [m for m in group.members() if m.state not in "ZX"]
        deadline = time.monotonic() + 60.0   # a child may still be ending when stderr closes
        while left and time.monotonic() < deadline:
            time.sleep(0.05)
            left = [m for m in group.members() if m.state not in "ZX"]
        return Interrupted(proc.returncode, err, members, left)
    finally:   # a failed check leaves the group stopped: end it (its members hold our stderr pipe)
        if [m for m in group.members() if m.state not in "ZX"]:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stderr.close()


def _interrupt(args: list[str], cwd: Path, stage: Stage, target: int, whole_group: bool = True,
               command: tuple[str, ...] = (EXE,)) -> Interrupted:
    for step_s in (0.002, 0.001, 0.0005, 0.0002, 0.0001):
        done = _interrupt_at(args, cwd, stage, target, step_s, whole_group, command)
        if done is not None:
            return done
    raise AssertionError(f"every step went past stage {target}, the finest {step_s} s")


def _check(done: Interrupted) -> None:
    assert done.code == 130, done.stderr[-3000:]
    assert done.stderr == "flexmodal: interrupted\n", done.stderr[-3000:]
    assert done.left == [], f"processes left: {done.left}"


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Path:
    """32 random-test runs of 300 s at 1024 Hz (force + two responses): 4 records, each stored under 8
    run groups (whose datasets are HDF5 hard links).  A worker needs a few hundredths of a second of
    CPU per run, so the workers are still computing once each has used 0.1 s."""
    import numpy as np

    path = tmp_path_factory.mktemp("pool-runs") / "runs.h5"
    rng = np.random.default_rng(4)
    channels = [Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2"),
                Channel("a2", "acceleration", "m/s^2")]
    decay = np.exp(-np.arange(200) / 40.0)
    for k in range(4):
        force = rng.standard_normal(307200)
        response = [np.convolve(force, decay * np.sin(np.arange(200) / w))[:307200] for w in (3.0, 5.0)]
        with RunWriter(path, f"r{k}", sample_rate_hz=1024.0, channels=channels, excitation="random",
                       pose={"theta_deg": 10.0 * k}) as writer:
            writer.append(np.column_stack([force, *response]))
    with h5py.File(path, "a") as f:   # run groups of their own (a hard-linked group is one run, listed
        for k in range(4, 32):        # once), whose members are hard links to a record's: no copies
            record, run = f[f"runs/r{k % 4}"], f.create_group(f"runs/r{k}")
            for name in record:
                run[name] = record[name]
            run.attrs.update(record.attrs)
    return path


@pytest.mark.timeout(900)
@pytest.mark.parametrize("target", sorted(POOL_STAGES), ids=list(POOL_STAGES.values()))
def test_ctrl_c_during_the_pool_start(runs, tmp_path, target):
    out = tmp_path / "frf.h5"
    done = _interrupt(["frf", str(runs), "--workers", "2", "--out", str(out)], tmp_path, _pool_stage, target)
    _check(done)
    assert [p.name for p in tmp_path.iterdir() if p.name != "frf.h5"] == []
    if out.exists():   # the runs written before the signal are whole, the file closed
        from flexmodal.modal.runs_io import read_frf

        with h5py.File(out, "r") as f:
            written = list(f["runs"]) if "runs" in f else []
        for rid in written:
            assert read_frf(out, rid).H.shape[:2] == (2, 1)


def _a_worker_stopped(members: list[Member]) -> bool:
    server = [m.pid for m in members if "forkserver" in m.cmdline]
    return any(m.ppid in server and m.state == "T" for m in members)


@pytest.mark.timeout(900)
def test_ctrl_c_while_a_worker_starts(runs, tmp_path):
    """Stage 5, a worker forked but not yet ignoring SIGINT, lasts about a millisecond (steps went past
    it 1 time in 3): with FLEXMODAL_STOP_AT=worker-start each worker stops itself at the start of its
    initializer (modal/batch.py); the signal goes to the group once one has."""
    proc = subprocess.Popen([EXE, "--quiet", "frf", str(runs), "--workers", "2", "--out", "frf.h5"],
                            cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, text=True, start_new_session=True,
                            env={**os.environ, "FLEXMODAL_STOP_AT": "worker-start"})
    group = Group(proc.pid)
    try:
        deadline = time.monotonic() + 600.0
        while not _a_worker_stopped(group.members()):
            assert proc.poll() is None and time.monotonic() < deadline, "no worker stopped itself"
            time.sleep(0.01)
        members = group.stop()
        assert _pool_stage(proc.pid, members) == 5, members
        os.killpg(proc.pid, signal.SIGINT)
        deadline = time.monotonic() + 300.0
        while True:   # a worker forked after the signal stops itself too: continue it (it then ends)
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGCONT)
            try:
                _, err = proc.communicate(timeout=1.0)
                break
            except subprocess.TimeoutExpired:
                assert time.monotonic() < deadline, "the command's processes did not end"
        left = [m for m in group.members() if m.state not in "ZX"]
        deadline = time.monotonic() + 60.0
        while left and time.monotonic() < deadline:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGCONT)
            time.sleep(0.05)
            left = [m for m in group.members() if m.state not in "ZX"]
        _check(Interrupted(proc.returncode, err, members, left))
    finally:
        if [m for m in group.members() if m.state not in "ZX"]:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
    assert not (tmp_path / "frf.h5").exists()


@pytest.mark.timeout(900)
def test_ctrl_c_to_the_command_only_while_the_fork_server_imports(runs, tmp_path):
    """``kill -INT`` of the command alone: it ends the fork server (and so its workers) itself."""
    done = _interrupt(["frf", str(runs), "--workers", "2", "--out", "frf.h5"], tmp_path, _pool_stage, 4,
                      whole_group=False)
    _check(done)
    assert not (tmp_path / "frf.h5").exists()


def _helper_stage(pid: int, members: list[Member]) -> int:
    """How far the automatic choice's helper has come (0-2): none yet, forked, computing (0.05 s of CPU:
    it ignores SIGINT long before)."""
    helpers = [m for m in members if m.ppid == pid]
    return 0 if not helpers else 2 if helpers[0].cpu_s >= 0.05 else 1


# `flexmodal` whose automatic choice sees an idle CPU whatever the machine's load (so it forks a helper),
# run as the command is (main() with no argv: its Ctrl-C handling, e.g. the unraisable hook, in place)
IDLE_CPU = (sys.executable, "-c", "import sys; from flexmodal.modal import batch; "
            "batch._idle_cpus_between = lambda before, after: 1.0; "
            "from flexmodal.app import main; sys.exit(main())")


@pytest.mark.timeout(900)
def test_ctrl_c_while_the_automatic_choices_helper_computes(runs, tmp_path):
    """The default `frf` with a helper forked from it (started with SIGINT blocked, then ignoring it):
    a terminal's Ctrl-C is answered by the command alone, the helper is ended and waited for, and the
    runs written before are whole."""
    out = tmp_path / "frf.h5"
    done = _interrupt(["frf", str(runs), "--out", str(out)], tmp_path, _helper_stage, 2, command=IDLE_CPU)
    _check(done)
    pids = {m.pid for m in done.seen}
    assert [m.ignores_sigint for m in done.seen if m.ppid in pids] == [True]   # the one helper
    if out.exists():
        from flexmodal.modal.runs_io import read_frf

        with h5py.File(out, "r") as f:
            written = list(f["runs"]) if "runs" in f else []
        for rid in written:
            assert read_frf(out, rid).H.shape[:2] == (2, 1)


@pytest.mark.timeout(900)
@pytest.mark.parametrize("target", sorted(EIGEN_STAGES), ids=list(EIGEN_STAGES.values()))
def test_ctrl_c_while_the_eigen_worker_starts(tmp_path, target):
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\nc0,0\nc1,30\n")
    done = _interrupt(["predict", str(RIGS / "demo_arm.toml"), "--model", "fe", "--poses", "poses.csv",
                       "--out", "pred.csv", "--elements", "400"], tmp_path, _eigen_stage, target)
    _check(done)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["poses.csv"]
