"""Sending Ctrl-C to the real console script at a chosen moment (tests/test_interrupt*.py,
tests/test_cli_interrupt.py): process CPU time, child processes and CPU waiting read from Linux /proc."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from cpu_wait import CpuWait

EXE = str(Path(sys.executable).with_name("flexmodal"))
TICK = os.sysconf("SC_CLK_TCK")


def cpu_s(pid: int) -> float:
    """User + system CPU seconds used so far by process ``pid`` (0 once it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return 0.0
    return (int(fields[11]) + int(fields[12])) / TICK


def children(pid: int) -> list[int]:
    """Live child processes of ``pid`` (from /proc, no psutil)."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (FileNotFoundError, ProcessLookupError):
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            kids.append(int(stat.parent.name))
    return kids


def alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def interrupt(args: list[str], cwd: Path, ready: Callable[[int], bool], ready_within_s: float = 120.0
              ) -> tuple[int, float, str]:
    """Run ``flexmodal --quiet ARGS``; once ``ready(pid)`` holds, send SIGINT.  Returns (exit code,
    seconds from the signal to the exit not counting the time the command's process tree (or this
    test) was runnable but waiting for a CPU (tests/cpu_wait.py: the wall time on a quiet machine),
    stderr)."""
    proc = subprocess.Popen([EXE, "--quiet", *args], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        with CpuWait(proc.pid) as waits:
            t0 = time.monotonic()
            while not ready(proc.pid):
                assert proc.poll() is None, f"ended before the signal: {proc.stderr.read()[-2000:]}"
                assert time.monotonic() - t0 < ready_within_s, f"not ready within {ready_within_s} s"
                time.sleep(0.01)
            assert proc.poll() is None, "ended before the signal"
            cpu_before = cpu_s(proc.pid)
            sent = time.monotonic()
            proc.send_signal(signal.SIGINT)
            exited = exit_seen(proc.pid, 120.0)
            waits.sample()  # the zombie's counters, still readable (not reaped yet)
            cpu_after = cpu_s(proc.pid)
        _, err = proc.communicate(timeout=30)
        seconds = waits.unloaded(sent, exited)
        print(f"exit {exited - sent:.3f} s wall after SIGINT, {seconds:.3f} s of it not waiting for a CPU, "
              f"{cpu_after - cpu_before:.2f} s CPU")
        return proc.returncode, seconds, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def exit_seen(pid: int, within_s: float) -> float:
    """``time.monotonic()`` when child ``pid`` was seen to have exited, leaving it unreaped (its /proc
    entry stays readable); fails if it is still running after ``within_s`` seconds (a hang guard)."""
    deadline = time.monotonic() + within_s
    while os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None:
        assert time.monotonic() < deadline, f"pid {pid} still running {within_s} s later"
        time.sleep(0.005)
    return time.monotonic()


def descendants(pid: int) -> list[int]:
    found, todo = [], [pid]
    while todo:
        kids = children(todo.pop())
        found += kids
        todo += kids
    return found


def still_alive(pids: list[int], within_s: float) -> list[int]:
    """Those of ``pids`` still alive ``within_s`` seconds from now, not counting time they (or this
    thread) waited for a CPU, at most 60 s wall (a process may still be exiting when the command's
    stderr closes; zombies count as gone)."""
    waits = CpuWait(*pids)
    start = time.monotonic()
    while [p for p in pids if alive(p)] and time.monotonic() < start + 60.0:
        time.sleep(0.02)
        waits.sample()
        if waits.unloaded(start, time.monotonic()) > within_s:
            break
    return [p for p in pids if alive(p)]
