"""CLI commands of the `daq` package: `flexmodal acquire` and `flexmodal sim serve` (registered by app.py)."""

from __future__ import annotations

import argparse
import os
import sys


def register(sub: argparse._SubParsersAction) -> None:
    """Add this package's sub-commands to the flexmodal parser."""
    p = sub.add_parser("acquire", help="record an acquisition session into an HDF5 run",
                       description="Record the devices of a session config (TOML, docs/acquisition.md) into "
                                   "a run of an HDF5 file (CONTRACT §6). Stops at --duration (or the "
                                   "session's duration_s) or on Ctrl-C, with everything flushed.")
    p.add_argument("--config", required=True, metavar="SESSION.toml", help="session config file")
    p.add_argument("--out", required=True, metavar="RUN.h5", help="HDF5 file (created, or a run is appended)")
    p.add_argument("--duration", type=float, metavar="S", help="run length in seconds")
    p.add_argument("--run-id", metavar="ID", help="run id (default: the session's, else name + UTC time)")
    p.add_argument("--recover", action="store_true",
                   help="RUN.h5 was left by a killed writer: clear its open-for-writing flags first")
    p.set_defaults(func=_acquire)

    sim = sub.add_parser("sim", help="simulated devices").add_subparsers(dest="sim_command", metavar="CMD")
    sim.required = True
    s = sim.add_parser("serve", help="serve a simulated device streaming a simulated rig's signals",
                       description="Start a simulated device on loopback only: serial over a pty (prints its "
                                   "path), CAN as an slcan adapter on a pty (prints its path), Modbus TCP on "
                                   "127.0.0.1 (prints host:port). Runs until Ctrl-C/SIGTERM or --duration.")
    s.add_argument("--protocol", required=True, choices=("serial", "can", "modbus"))
    s.add_argument("--rig", metavar="RIG.toml", help="rig description (default: the demo arm)")
    s.add_argument("--test", choices=("impact", "random", "sweep", "operational"), default="impact",
                   help="excitation (operational: the arm driven by joint torque and tip force noise, "
                        "no force channel streamed)")
    s.add_argument("--rate", type=float, default=2048.0, metavar="HZ", help="sample rate, Hz")
    s.add_argument("--pose", default="", metavar="VAR=VALUE,...",
                   help="pose of the rig, e.g. theta_deg=60 (angles in degrees; default 30 deg, others 0)")
    s.add_argument("--seed", type=int, default=0, help="seed of the simulated test and the faults")
    s.add_argument("--effect", action="append", default=[], metavar="EFFECT@LOCATION:PARAM=VALUE,...",
                   help="hide an effect in the simulated arm (CONTRACT §5 names, SI units), e.g. "
                        "joint_stiffness@elbow:k_Nm_per_rad=8000; repeatable")
    s.add_argument("--duration", type=float, metavar="S", help="stop after S seconds of samples")
    s.add_argument("--link", metavar="PATH", help="serial/slcan: symlink path of the pty")
    s.add_argument("--port", type=int, default=0, help="modbus: TCP port on 127.0.0.1 (0 = a free one)")
    s.add_argument("--transport", choices=("tcp", "rtu"), default="tcp",
                   help="modbus: TCP on 127.0.0.1, or RTU over a pty pair (prints the client's port)")
    s.add_argument("--framing", choices=("binary", "csv"), default="binary", help="serial framing")
    s.add_argument("--format", choices=("int16", "int32", "float32"), default="int16",
                   help="serial binary sample format")
    s.add_argument("--scans-per-frame", type=int, default=32, metavar="N", help="serial: scans per frame")
    s.add_argument("--corrupt-rate", type=float, default=0.0, metavar="P",
                   help="fraction of frames corrupted (0.01 = 1 %%)")
    s.add_argument("--drop-at", type=float, metavar="S", help="drop a burst of frames starting at S seconds")
    s.add_argument("--drop", type=float, default=0.2, metavar="S", help="length of the dropped burst, s")
    s.add_argument("--disconnect-after", type=float, metavar="S", help="disconnect after S seconds")
    s.add_argument("--disconnect", type=float, default=0.5, metavar="S", help="length of the disconnect, s")
    s.add_argument("--fault-log", metavar="FILE", help="append one JSON line per injected fault")
    s.add_argument("--exit-with-parent", action="store_true", help="stop when the parent process exits")
    s.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS, help="no logs on stderr")
    s.set_defaults(func=_serve)


def _acquire(args: argparse.Namespace) -> int:
    from flexmodal.daq.acquire import WriteFailed, acquire
    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.session import load_session

    session = load_session(args.config)
    if args.recover and os.path.exists(args.out):
        from flexmodal.daq.store import recover

        recover(args.out)
    if args.duration is not None and args.duration <= 0:
        raise DaqError(f"--duration {args.duration}: must be > 0 seconds")
    try:
        summary = acquire(session, args.out, duration_s=args.duration, quiet=args.quiet, run_id=args.run_id)
    except WriteFailed as exc:  # leave without closing the HDF5 file: it keeps its last flushed state
        print(f"flexmodal: error: {exc}", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(2)
    print(summary.line())
    return 0


def _serve(args: argparse.Namespace) -> int:
    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.sim_serve import serve

    if not 0 <= args.corrupt_rate < 1:
        raise DaqError(f"--corrupt-rate {args.corrupt_rate}: must be in [0, 1)")
    if args.rate <= 0:
        raise DaqError(f"--rate {args.rate}: must be > 0 Hz")
    try:
        pairs = (item.split("=") for item in args.pose.split(",") if item)
        args.pose = {k.strip(): float(v) for k, v in pairs}
    except ValueError as exc:
        raise DaqError(f"--pose {args.pose!r}: expected VAR=NUMBER[,VAR=NUMBER...]") from exc
    args.effect = [_hidden_effect(text) for text in args.effect]
    serve(args, sys.stdout)
    return 0


def _hidden_effect(text: str):
    """Parse ``EFFECT@LOCATION:PARAM=VALUE,...`` into a fixtures.rig_sim.HiddenEffect."""
    from flexmodal.daq.errors import DaqError
    from flexmodal.fixtures.rig_sim import HiddenEffect

    head, _, params = text.partition(":")
    effect, _, location = head.partition("@")
    try:
        values = {k.strip(): float(v) for k, v in (item.split("=") for item in params.split(",") if item)}
    except ValueError:
        values = {}
    if not effect or not location or not values:
        raise DaqError(f"--effect {text!r}: expected EFFECT@LOCATION:PARAM=VALUE[,PARAM=VALUE...]")
    return HiddenEffect(effect, location, values)
