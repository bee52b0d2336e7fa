"""Wall-clock bounds that hold under load: the time a process tree spent ready to run but waiting for a CPU.

A product promise such as "exits within 1 s of SIGINT" is about what the program does (work, sleeps,
waits on its children), not about how much CPU other users of a shared machine leave it.  Linux counts,
for every thread, the time it was runnable but kept off a CPU (``run_delay``, the second field of
``/proc/PID/task/TID/schedstat``; 0 for every thread on an idle machine).  :class:`CpuWait` follows a
process, its threads and its descendants (and the threads of the test that observes it) from a
background thread and gives, for any window, how long at least one of them was kept waiting; a bound
is then checked on

    wall seconds of the window - seconds the tree waited for a CPU within it

which equals the wall time on a quiet machine and does not grow with the load.  The subtraction is capped
per polling step at the step's length (several threads waiting at once count once); a thread that ends
between two polls takes its last waiting time with it, which only makes the check stricter (the polling
thread runs with a real-time priority where allowed, so that a step stays 20 ms under any load: a
child that waited seconds for the CPU to handle its SIGTERM and then exited would otherwise take those
seconds with it).
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path


def _tasks(pid: int) -> list[Path]:
    try:
        return list(Path(f"/proc/{pid}/task").iterdir())
    except (FileNotFoundError, ProcessLookupError, NotADirectoryError):
        return []


def _tree(pid: int) -> list[Path]:
    """Task folders of ``pid`` and of all its descendants (Linux /proc/PID/task/TID/children)."""
    found, todo = [], [pid]
    while todo:
        for task in _tasks(todo.pop()):
            found.append(task)
            try:
                todo += [int(c) for c in (task / "children").read_text().split()]
            except (FileNotFoundError, ProcessLookupError):
                pass
    return found


def _run_delay_ns(task: Path) -> int | None:
    try:
        return int((task / "schedstat").read_text().split()[1])
    except (FileNotFoundError, ProcessLookupError, IndexError, ValueError):
        return None


class CpuWait:
    """Follow the process trees of ``pids`` and the threads of this process; ``waited(t0, t1)`` is the
    number of seconds between two ``time.monotonic()`` instants during which one of them was runnable
    but not running.

    Use as a context manager (polling every ``step_s`` seconds from a daemon thread), or call
    :meth:`sample` in a loop of one's own; call :meth:`sample` once more right after the event that
    ends a window (a process that exited but is not reaped yet: ``os.waitid(..., WNOWAIT)`` keeps its
    counters readable)."""

    def __init__(self, *pids: int, step_s: float = 0.02) -> None:
        self.pids = pids
        self.step_s = step_s
        self.last: dict[str, int] = {}
        self.times = [time.monotonic()]
        self.total = [0.0]  # cumulative seconds waited at self.times
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.poller = ""
        self.sample()
        self.thread = threading.Thread(target=self._poll, daemon=True)

    def __enter__(self) -> CpuWait:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join(timeout=5)

    def _poll(self) -> None:
        self.poller = f"/proc/{os.getpid()}/task/{threading.get_native_id()}"  # not itself a waiter
        try:  # sample on time however loaded the machine is (a tiny job every step); else best effort
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        except (PermissionError, OSError):
            pass
        while not self.stop.wait(self.step_s):
            self.sample()

    def sample(self) -> None:
        with self.lock:
            now = time.monotonic()
            grown, first = 0, not self.last
            tasks = {str(t): t for t in [*_tasks(os.getpid()), *(t for pid in self.pids for t in _tree(pid))]}
            tasks.pop(self.poller, None)
            for key, task in tasks.items():
                ns = _run_delay_ns(task)
                if ns is None:
                    continue
                grown += ns - self.last.get(key, ns if first else 0)  # a new task: all since it began
                self.last[key] = ns
            step = now - self.times[-1]
            self.times.append(now)
            self.total.append(self.total[-1] + min(step, max(grown, 0) / 1e9))

    def _at(self, t: float, later: bool) -> float:
        """Cumulative waiting at the first sample at or after ``t`` (``later``) or the last one before."""
        with self.lock:
            if later:
                i = next((k for k, s in enumerate(self.times) if s >= t), len(self.times) - 1)
            else:
                i = max((k for k, s in enumerate(self.times) if s <= t), default=0)
            return self.total[i]

    def waited(self, t0: float, t1: float) -> float:
        """Seconds within [t0, t1] during which the tree (or the observer) waited for a CPU; counted
        between the first poll after ``t0`` and the last one before ``t1`` (never more than is known)."""
        return max(0.0, self._at(t1, later=False) - self._at(t0, later=True))

    def unloaded(self, t0: float, t1: float) -> float:
        """``t1 - t0`` less the time the tree waited for a CPU within it: the window's length on a quiet
        machine."""
        return (t1 - t0) - self.waited(t0, t1)
