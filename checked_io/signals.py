"""Signal handlers installed for the length of a block and put back after it (main thread only)."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager


@contextmanager
def signal_handlers(handler: Callable, signals: Iterable[int]) -> Iterator[dict]:
    """Inside the block, each of ``signals`` calls ``handler(signum, frame)``; leaving it (however) puts
    back the handlers found, so the process's signal handling stays the caller's (the API may run
    inside a Python session).  Outside the main thread, where Python sets no handlers, nothing changes.
    Yields the handlers found, {signal: handler} (empty outside the main thread).

    Examples
    --------
    >>> import signal
    >>> got = []
    >>> with signal_handlers(lambda signum, _frame: got.append(signum), [signal.SIGUSR1]) as found:
    ...     signal.raise_signal(signal.SIGUSR1)
    >>> got == [signal.SIGUSR1], signal.getsignal(signal.SIGUSR1) is found[signal.SIGUSR1]
    (True, True)
    """
    if threading.current_thread() is not threading.main_thread():
        yield {}
        return
    previous: dict = {}
    try:
        for s in signals:
            previous[s] = signal.signal(s, handler)
        yield previous
    finally:
        for s, old in previous.items():
            signal.signal(s, old)
