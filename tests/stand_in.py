"""Helper of the acquisition tests: run a stand-in device in a thread while `acquire` records it."""

from __future__ import annotations

import threading
from pathlib import Path

from flexmodal.daq.acquire import acquire
from flexmodal.daq.store import Run, read_run


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
