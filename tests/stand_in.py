"""Helpers of the acquisition tests: run a stand-in device in a thread while `acquire` records it, and
stream a stand-in serial device's records over a pty to a reader however late it comes."""

from __future__ import annotations

import os
import select
import threading
import time
from collections.abc import Callable
from pathlib import Path

from flexmodal.daq.acquire import acquire
from flexmodal.daq.store import Run, read_run
from flexmodal.fixtures.sim_common import PtyLink


def record_with(device, session, out: Path, seconds: float) -> Run:
    """Run ``device(stop)`` in a thread (the stand-in device, stopping when ``stop`` is set) while
    acquiring ``seconds`` of ``session`` into ``out``; the stored run."""
    stop = threading.Event()
    thread = threading.Thread(target=device, args=(stop,), daemon=True)
    thread.start()
    try:
        summary = acquire(session, out, duration_s=seconds, quiet=True)
    finally:
        stop.set()
        thread.join(5)
    return read_run(out, summary.run_id)


def stream_paced(link: PtyLink, records: Callable[[int, int], bytes], rate_hz: float,
                 stop: threading.Event, n: int | None = None) -> None:
    """A stand-in serial device on ``link``: ``records(k0, k1)`` are the bytes of its records k0 .. k1-1,
    sent paced at ``rate_hz`` (``n`` records, or until ``stop``).

    A reader that is not there yet, or falls behind (starved of CPU with this process on a loaded
    machine), is waited for as long as it takes, never given up on: the records that do not fit in the
    pty wait, and the opening reader flushes what the pty holds (pyserial) and takes the rest.  (A device
    that gave up after 1 s, ``PtyLink.write``, died "nobody is reading" when the acquisition opened the
    port 2 s late, and the run failed "no samples within 15 s".)
    """
    t0, sent = time.monotonic(), 0
    while (n is None or sent < n) and not stop.is_set():
        due = int((time.monotonic() - t0) * rate_hz)
        due = due if n is None else min(n, due)
        if due > sent:
            _write_until_stopped(link, records(sent, due), stop)
            sent = due
        time.sleep(0.005)


def _write_until_stopped(link: PtyLink, data: bytes, stop: threading.Event) -> None:
    view = memoryview(data)
    while view and not stop.is_set():
        if select.select([], [link.master], [], 0.1)[1]:
            try:
                view = view[os.write(link.master, view):]
            except BlockingIOError:
                continue
