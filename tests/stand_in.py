"""Helpers of the acquisition tests: run a stand-in device in a thread while `acquire` records it, and
stream a stand-in serial device's records over a pty from the moment the reader is there."""

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


def stream_when_read(link: PtyLink, records: Callable[[int, int], bytes], rate_hz: float,
                     stop: threading.Event, n: int | None = None) -> None:
    """A stand-in serial device on ``link``: ``records(k0, k1)`` are the bytes of its records k0 .. k1-1,
    sent paced at ``rate_hz`` (``n`` records, or until ``stop``).

    The stream starts once the reader has opened the port (record 0 is written first and the stream goes
    on when it left the read buffer: pyserial flushes the input when it opens a port;
    ``PtyLink.await_reader``), so the run holds the same stream however long the acquisition's start
    took on a loaded machine; a device that streamed from its own start filled the pty and gave up
    ("nobody is reading") when the acquisition opened the port 2 s late.  A reader that falls behind
    (starved of CPU together with this process) is waited for, never dropped; runs end with ``stop``.
    """
    if not link.await_reader(records(0, 1), stop, lambda: None):
        return
    t0, sent = time.monotonic() - 1.0 / rate_hz, 1
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
