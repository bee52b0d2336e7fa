"""`flexmodal sim serve`: build the simulated rig's signal and run one protocol's device simulator.

The first line on stdout is the endpoint (pty path, or host:port for Modbus TCP); the simulator runs
until SIGTERM/SIGINT or ``--duration`` and then exits 0.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time

from flexmodal.daq.sim_common import FaultLog, FaultPlan
from flexmodal.daq.sim_source import sim_source


def _watch_parent(ppid: int, stop: threading.Event) -> None:
    """Stop when the parent process is gone (e.g. `flexmodal acquire` killed with SIGKILL)."""
    while not stop.is_set():
        if os.getppid() != ppid:
            stop.set()
        time.sleep(0.2)


def serve(args, stdout) -> None:
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    if args.exit_with_parent:
        threading.Thread(target=_watch_parent, args=(os.getppid(), stop), daemon=True).start()
    if args.quiet:
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    source = sim_source(args.rig, args.test, args.rate, seed=args.seed, pose=args.pose, effects=args.effect)
    faults = FaultPlan(args.corrupt_rate, args.drop_at, args.drop, args.disconnect_after, args.disconnect,
                       args.seed)
    log = FaultLog(args.fault_log)

    def announce(endpoint: str) -> None:
        print(endpoint, file=stdout, flush=True)

    try:
        if args.protocol == "serial":
            from flexmodal.daq.sim_common import PtyLink
            from flexmodal.fixtures.sim_serial import serve as serve_serial

            link = PtyLink(args.link)
            announce(str(link.path))
            serve_serial(link, source, scans_per_frame=args.scans_per_frame, framing=args.framing,
                         fmt=args.format, faults=faults, log=log, duration_s=args.duration, stop=stop)
            link.remove()
        elif args.protocol == "can":
            from flexmodal.fixtures.sim_can import serve_slcan

            serve_slcan(source, link_path=args.link, faults=faults, log=log, duration_s=args.duration,
                        stop=stop, announce=announce)
        else:
            from flexmodal.fixtures.sim_modbus import serve as serve_modbus

            serve_modbus(source, transport=args.transport, port=args.port, link_path=args.link, faults=faults,
                         log=log, duration_s=args.duration, stop=stop, announce=announce)
    finally:
        log.close()
