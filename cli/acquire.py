"""CLI command of the `daq` package: `flexmodal acquire` (registered by app.py)."""

from __future__ import annotations

import argparse
import os
import sys

from flexmodal.checked_io import options as opt
from flexmodal.cli.commands import Subcommands, command


def register(sub: Subcommands) -> None:
    """Add this package's sub-commands to the flexmodal parser."""
    p = command(sub, "acquire", _acquire)
    p.add_argument("--config", required=True, metavar="SESSION.toml", help="session config file")
    p.add_argument("--out", required=True, metavar="RUN.h5", help="HDF5 file (created, or a run is appended)")
    p.add_argument("--duration", type=opt.seconds, metavar="S", help="run length in seconds")
    p.add_argument("--run-id", metavar="ID", help="run id (default: the session's, else name + UTC time)")
    p.add_argument("--recover", action="store_true",
                   help="RUN.h5 was left by a killed writer: clear its open-for-writing flags first "
                        "(refused while another acquire is writing it)")


def _acquire(args: argparse.Namespace) -> int:
    """record an acquisition session into an HDF5 run

    Record the devices of a session config (TOML, docs/acquisition.md) into a run of an HDF5 file
    (docs/hdf5-format.md). Stops at --duration (or the session's duration_s) or on Ctrl-C, SIGTERM or
    SIGHUP, with everything flushed and closed. Exit 0: done; 128+N: stopped early by signal N; 2: bad
    input, a lost device, a full disk or a write error (one line).
    """
    from flexmodal.api import DaqError, WriteFailed, acquire

    try:
        summary = acquire(args.config, args.out, duration_s=args.duration, run_id=args.run_id,
                          recover=args.recover, quiet=args.quiet)
    except WriteFailed as exc:  # leave without closing the HDF5 file: it keeps its last flushed state
        print(f"flexmodal: error: {exc}", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(2)
    print(summary.line(), flush=True)
    if summary.polls_line():
        print(summary.polls_line(), file=sys.stderr, flush=True)
    if summary.error:
        raise DaqError(summary.error)
    return summary.exit_code
