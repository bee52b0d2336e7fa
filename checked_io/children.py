"""Child processes that leave Ctrl-C to the command that started them.

A terminal's Ctrl-C sends SIGINT to every process of its foreground process group: the command and
every Python child it started (a worker pool's fork server and its workers, the eigen worker).  A child
that gets it while its interpreter starts or imports prints a KeyboardInterrupt traceback below the
command's one line (issue 24: 1 ``frf --workers 2`` in 3).  Ignoring SIGINT in the child's own code
leaves the window before that code runs; a child started from a thread that blocks SIGINT has none:
the signal mask is inherited through fork and exec, so a Ctrl-C stays pending in the child until it
ignores SIGINT (``signal.SIG_IGN`` discards a pending signal), and the command alone answers it.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def ctrl_c_blocked() -> Iterator[None]:
    """Block SIGINT in the calling thread while the block runs (the block starts processes; keep it to
    the milliseconds of their fork and exec): a Ctrl-C that comes meanwhile reaches this process when
    the block ends, and the processes started inside begin with SIGINT blocked.

    Examples
    --------
    >>> import signal
    >>> with ctrl_c_blocked():
    ...     signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    True
    >>> signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    False
    """
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def leave_ctrl_c_to_parent() -> None:
    """In a child process: ignore SIGINT from now on (a pending one is discarded); the parent that
    started it answers a Ctrl-C and ends it.  Call it first thing in the child."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
