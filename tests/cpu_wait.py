"""Wall-clock bounds that hold under load: the time a process tree spent ready to run but waiting for a CPU.

A product promise such as "exits within 1 s of SIGINT" is about what the program does (work, sleeps,
waits on its children), not about how much CPU other users of a shared machine leave it.  Linux counts,
for every thread, the time it was runnable but kept off a CPU (``run_delay``, the second field of
``/proc/PID/task/TID/schedstat``; 0 for every thread on an idle machine).  :class:`CpuWait` follows a
process, its threads and its descendants (and the threads of the test that observes it) from a
background thread and gives, for any window, how long at least one of them was kept waiting; a bound
is then checked on

    wall seconds of the window - seconds the tree waited for a CPU within it

which equals the wall time on a quiet machine and does not grow with the load.  Linux adds a wait to
``run_delay`` only when it ends (the thread gets a CPU), so a poll that finds a thread's count grown by
``d`` seconds dates that wait to the ``d`` seconds before the poll; the waits of all threads are merged
(several threads waiting at once count once).  (Capping each poll's share at the poll's step instead
dropped all but 20 ms of every longer wait: under two busy loops a SIGTERM stop of 13.7 s wall with 0.22 s
of CPU came out at 6.5 s.)  A thread that ends between two polls takes its last waiting time with it,
which only makes the check stricter (the polling thread runs with a real-time priority where allowed,
so that a step stays 20 ms under any load: a child that waited seconds for the CPU to handle its SIGTERM
and then exited would otherwise take those seconds with it).
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
        self.waits: list[tuple[float, float]] = []  # disjoint (start, end) of waiting, by time
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
            first = not self.last
            tasks = {str(t): t for t in [*_tasks(os.getpid()), *(t for pid in self.pids for t in _tree(pid))]}
            tasks.pop(self.poller, None)
            for key, task in tasks.items():
                ns = _run_delay_ns(task)
                if ns is None:
                    continue
                grown = ns - self.last.get(key, ns if first else 0)  # a new task: all since it began
                self.last[key] = ns
                if grown > 0:
                    self._add(now - grown / 1e9, now)

    def _add(self, start: float, end: float) -> None:
        """Merge the wait [start, end] (``end`` is the latest time yet) into the disjoint list."""
        while self.waits and self.waits[-1][1] >= start:
            start = min(start, self.waits.pop()[0])
        self.waits.append((start, end))

    def waited(self, t0: float, t1: float) -> float:
        """Seconds within [t0, t1] during which the tree (or the observer) waited for a CPU, as far as
        the polls so far know (a wait still going on is counted once it ended and a poll saw it)."""
        with self.lock:
            return sum(max(0.0, min(b, t1) - max(a, t0)) for a, b in self.waits if b > t0 and a < t1)

    def unloaded(self, t0: float, t1: float) -> float:
        """``t1 - t0`` less the time the tree waited for a CPU within it: the window's length on a quiet
        machine."""
        return (t1 - t0) - self.waited(t0, t1)
