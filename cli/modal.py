"""CLI commands of the `modal` package (registered by app.py): ``flexmodal frf`` and ``identify``."""

from __future__ import annotations

import argparse
import sys

from flexmodal.api import ESTIMATORS, METHODS
from flexmodal.checked_io import options as opt
from flexmodal.cli.commands import Subcommands, command


def register(sub: Subcommands) -> None:
    """Add this package's sub-commands to the flexmodal parser."""
    p = command(sub, "frf", _frf)
    p.add_argument("runs", nargs="+", metavar="RUN.h5", help="HDF5 run files (docs/hdf5-format.md)")
    p.add_argument("--estimator", default="H1", choices=ESTIMATORS, metavar="NAME",
                   help="FRF estimator: %(choices)s (default H1)")
    p.add_argument("--nfft", type=opt.segment_length, default=None, metavar="N",
                   help="segment length in samples for random runs (default: power of two <= 8192 "
                        "giving >= 8 segments); impact runs use one record per hit, sweep runs one "
                        "segment per sweep unless --nfft or --window is given")
    p.add_argument("--window", type=opt.nonempty, default=None, metavar="WINDOW[,...]",
                   help="window: rect|hann|flattop for random runs (default hann); impact runs "
                        "'force:W,exponential:E' (fractions; default force:0.05 and no "
                        "window on the responses; 'exponential' alone is exponential:0.01)")
    p.add_argument("--overlap", type=opt.overlap, default=0.5, metavar="FRACTION",
                   help="segment overlap, 0..1 (default 0.5)")
    p.add_argument("--averaging", default="linear", choices=["linear", "exponential"],
                   help="averaging of impact hits (default linear)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=opt.workers, default=None, metavar="N",
                   help="local worker processes (0 = serial here; default: chosen by cost)")
    g.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="dask.distributed scheduler address (needs the extra flexmodal[cluster])")
    p.add_argument("--out", default=None, metavar="OUT.h5", help="write the FRFs into this file instead")

    q = command(sub, "identify", _identify)
    q.add_argument("input", metavar="INPUT", help="RUN.h5 or FILE.uff/.unv")
    q.add_argument("--out", required=True, metavar="MODES.csv", help="modal table to write")
    q.add_argument("--fmin", type=opt.hertz, default=None, metavar="HZ",
                   help="lower band edge, Hz (default first line > 0)")
    q.add_argument("--fmax", type=opt.positive_hz, default=None, metavar="HZ",
                   help="upper band edge, Hz (default Nyquist, or below a top stretch where the FRFs' "
                        "coherence stays under 0.9; the band fitted is printed)")
    q.add_argument("--method", default=None, choices=METHODS,
                   help="; ".join(f"{name}: {METHODS[name].caption}" for name in METHODS)
                   + ". Output-only shapes are unscaled (unit largest entry)")
    q.add_argument("--max-order", type=opt.model_order, default=None, metavar="N",
                   help="cap of the pLSCF model order (default: the order grows until the modes found "
                        "stop growing and explain every clear CMIF peak, at most 200 / number of "
                        "references, more while clear peaks are unexplained); ssi: highest model order "
                        "(default 100)")
    q.add_argument("--poles", default=None, metavar="F1,F2,...",
                   help="pick the stable poles nearest these frequencies, Hz (exactly these modes, no "
                        "automatic selection)")
    q.add_argument("--from-diagram", action="store_true",
                   help="with --poles: pick only from the stabilisation diagram an earlier identify stored "
                        "beside --out (MODES.diagram.npz; an error when it was computed from another input "
                        "or options). Without it a matching stored diagram is used too, else the "
                        "stabilisation runs again")
    q.add_argument("--need-min", type=opt.nonnegative, default=None, metavar="F",
                   help="drop a mode whose F statistic in the FRF synthesis is below F (the FRFs do not "
                        "need it; default 10)")
    q.add_argument("--mpc-min", type=opt.fraction, default=None, metavar="MPC",
                   help="with 3+ outputs, drop a mode whose modal phase collinearity is below MPC "
                        "(0..1, default 0.5)")
    q.add_argument("--exp-window-decay", type=opt.nonnegative, default=None, metavar="RATE",
                   help="decay rate, 1/s, of an exponential window the FRFs were measured with "
                        "(w(t) = exp(-RATE t)); its added damping is removed (default: the rate the "
                        "FRFs record, 0 for UFF files)")
    q.add_argument("--references", type=opt.names, default=None, metavar="NAME,...",
                   help="ssi/fdd: reference output channels (default all outputs)")
    q.add_argument("--run", default=None, metavar="RUN_ID", help="only this run of an HDF5 file")
    q.add_argument("--uff", default=None, metavar="MODES.uff", help="also write the modes as UFF dataset 55")
    q.add_argument("--verbose", action="store_true",
                   help="also print the per-mode lines behind each summary warning (--quiet: no warnings)")
    t = q.add_argument_group("tracking a moving arm (--track; docs/oma.md)")
    t.add_argument("--track", action="store_true",
                   help="follow the modes in sliding windows tagged by the encoders' pose; write the modal "
                        "map (one configuration per pose bin) and MODES.harmonics.csv")
    t.add_argument("--pose-from", default=None, metavar="VAR=CHANNEL,...",
                   help="encoder channel of each pose variable, degrees (default: the record's one encoder)")
    t.add_argument("--window", type=opt.seconds, default=None, metavar="S",
                   help="window length, s (default: 80 periods of the slowest mode)")
    t.add_argument("--hop", type=opt.seconds, default=None, metavar="S",
                   help="window step, s (default: a quarter pose bin at the 90th percentile pose rate)")
    t.add_argument("--bin", type=opt.positive, default=None, metavar="DEG",
                   help="pose bin width (default 5)")
    t.add_argument("--max-spread", type=opt.nonnegative, default=None, metavar="DEG",
                   help="skip windows whose pose standard deviation exceeds DEG (default 5)")
    t.add_argument("--orders", default=None, metavar="O1,O2,...",
                   help="harmonic orders per joint revolution (default: found from the data)")


def _frf(args: argparse.Namespace) -> int:
    """batch FRFs + coherence of stored runs, written back under /runs/<id>/frf

    Compute FRFs and coherence of every run in the HDF5 files and write them back under /runs/<id>/frf
    (or into --out). Random runs are streamed block by block (memory does not grow with the
    record) and segments holding NaN rows or touching gap/corrupt events are skipped; sweep runs are
    read whole and cut into one rectangular segment per sweep (Welch, as random runs, when they hold
    lost data or --nfft/--window is given). Runs are computed
    here, one after the other, and shared with a helper process forked from this one once the measured
    cost of the runs done predicts that it pays and a CPU is idle; --workers N forces a pool of N
    processes (0: always here), --scheduler uses an existing dask cluster. Prints one 'FILE:RUN_ID'
    line per run written. A bad run (or file) does not stop the others: every good run is written,
    then each bad one is named on stderr with why, followed by one summary line, and the exit code is 2.
    """
    from flexmodal.api import RunsFailed, compute_frfs

    try:
        written = compute_frfs(args.runs, estimator=args.estimator, nfft=args.nfft, window=args.window,
                               overlap=args.overlap, averaging=args.averaging, workers=args.workers,
                               scheduler=args.scheduler, out=args.out, quiet=getattr(args, "quiet", False))
    except RunsFailed as exc:
        _print_runs(exc.written)
        _tell_failed(exc)
        return 2
    _print_runs(written)
    return 0


def _print_runs(written) -> None:
    for path, rid in written:
        print(f"{path}:{rid}")


def _tell_failed(exc) -> None:
    """Each bad run of a RunsFailed and why, then one summary line, on stderr."""
    for line in exc.lines():
        print(f"flexmodal: error: {line}", file=sys.stderr)


def _pairs(text: str, what: str) -> dict[str, str]:
    """``VAR=CHANNEL,...`` -> {VAR: CHANNEL} (ModalError naming the option)."""
    from flexmodal.api import ModalError

    try:
        pairs = [item.split("=") for item in opt.names(text)]
    except argparse.ArgumentTypeError:
        pairs = []
    if not pairs or any(len(p) != 2 or not p[0].strip() or not p[1].strip() for p in pairs):
        raise ModalError(f"{what} {text!r}: expected VAR=CHANNEL[,VAR=CHANNEL...]")
    found = {k.strip(): v.strip() for k, v in pairs}
    if len(found) < len(pairs):   # theta_deg=enc,theta_deg=a1: the last one won in silence
        raise ModalError(f"{what} {text!r}: a variable is given twice")
    return found


#: options only identify --track reads, and options only identify without it reads: each was ignored in
#: silence by the other (identify --window 2 without --track ran the whole record; --track --uff M.uff
#: wrote no UFF file), exit 0
TRACK_ONLY = ("pose_from", "window", "hop", "bin", "max_spread", "orders")
IDENTIFY_ONLY = ("poles", "from_diagram", "need_min", "mpc_min", "exp_window_decay", "references", "uff")


def _check_mode_options(args: argparse.Namespace) -> None:
    """ModalError naming the first option given that the chosen mode (``--track`` or not) does not read;
    --method is read by --track only as ssi (SSI-cov in every window)."""
    from flexmodal.api import ModalError

    names = IDENTIFY_ONLY if args.track else TRACK_ONLY
    unused = [n for n in names if getattr(args, n) is not None and getattr(args, n) is not False]  # 0 given
    if args.track and args.method not in (None, "ssi"):
        unused.insert(0, "method")
    if not unused:
        return
    flag = "--" + unused[0].replace("_", "-")
    if args.track:
        raise ModalError(f"identify --track does not read {flag} (SSI-cov in sliding windows; leave it out)")
    raise ModalError(f"identify: {flag} is an option of identify --track (add --track, or leave it out)")


def _track(args: argparse.Namespace) -> int:
    """``identify --track``: the modal map of a moving arm and its harmonics (docs/oma.md)."""
    from flexmodal.api import ModalError, track

    pose_from = _pairs(args.pose_from, "--pose-from") if args.pose_from is not None else None
    try:
        orders = [float(v) for v in opt.names(args.orders)] if args.orders is not None else []
    except (ValueError, argparse.ArgumentTypeError):
        raise ModalError(f"--orders {args.orders!r}: give orders per revolution, comma-separated") from None
    if any(not 0 < o < float("inf") for o in orders):
        raise ModalError(f"--orders {args.orders!r}: orders must be positive and finite")
    binning = {k: v for k, v in (("bin_deg", args.bin), ("max_spread_deg", args.max_spread)) if v is not None}
    result = track(args.input, pose_from=pose_from, run_id=args.run, fmin=args.fmin, fmax=args.fmax,
                   window_s=args.window, hop_s=args.hop, orders=orders, max_order=args.max_order or 40,
                   out=args.out, **binning)
    if not getattr(args, "quiet", False):
        found = "; ".join(f"{v}: {', '.join(f'{o:.6g}' for o in ords) or 'none'}"
                          for v, ords in result.orders.items())
        print(f"flexmodal: {len(result.windows)} windows of {result.window_s:.3g} s every "
              f"{result.hop_s:.3g} s, {len(result.tracks)} modes tracked, {len(result.harmonics)} harmonic "
              f"poles (orders per revolution {found})", file=sys.stderr)
    for warning in result.warnings:
        print(f"flexmodal: warning: {warning}", file=sys.stderr)
    print(args.out)
    return 0


def _identify(args: argparse.Namespace) -> int:
    """natural frequencies, damping and mode shapes -> modal table CSV

    Identify modes from an HDF5 run (stored FRFs, or computed if absent) or a UFF file (dataset 58 FRFs,
    function type 4, or time histories, type 1, with a force reference) and write the modal table CSV
    (docs/formats.md) with the validation columns mpc, mpd_deg and synthesis_corr, and the FRAC of each
    measured and synthesised FRF to MODES.synthesis.csv. Each run of an HDF5 file is one configuration
    (config = run id). Runs with excitation=operational or without a force channel, and UFF time
    histories without a force, are identified output-only (SSI-cov by default; docs/oma.md). A bad run
    does not stop the others: the good runs' modes are written, each bad run is named on stderr with
    why, then one summary line, and the exit code is 2. A progress bar shows on a terminal (--quiet:
    none).
    """
    from flexmodal.api import ModalError, RunsFailed, Thresholds, identify

    _check_mode_options(args)
    if args.track:
        return _track(args)
    poles = None
    if args.poles is not None:
        try:
            poles = [opt.positive_hz(v) for v in opt.names(args.poles)]  # "40,,130": refused
        except argparse.ArgumentTypeError:
            raise ModalError(f"--poles {args.poles!r}: give frequencies in Hz (finite, > 0) separated by "
                             "commas") from None
        if not poles:
            raise ModalError(f"--poles {args.poles!r}: give positive frequencies in Hz")
    limits = Thresholds(**{k: v for k, v in (("need_min", args.need_min), ("mpc_min", args.mpc_min))
                           if v is not None})
    refs = args.references
    quiet = getattr(args, "quiet", False)
    try:
        result, failed = identify(args.input, method=args.method, fmin=args.fmin, fmax=args.fmax,
                                  max_order=args.max_order, run_id=args.run, poles_hz=poles,
                                  thresholds=limits, decay_rate_per_s=args.exp_window_decay,
                                  references=refs, out=args.out, uff=args.uff,
                                  from_diagram=args.from_diagram, quiet=quiet), None
    except RunsFailed as exc:
        result, failed = exc.result, exc
    if not quiet:
        _tell_identified(result, args.verbose)
    print(args.out)
    if failed is not None:
        _tell_failed(failed)
        return 2
    return 0


def _tell_identified(result, verbose: bool) -> None:
    """On stderr: for one configuration (or with --verbose) its band, model order and warnings; for
    several, one line per kind of warning and a count, not the same advice once per run."""
    each = verbose or len(result.modes) == 1
    for config, modes in result.modes.items() if each else ():   # a loop over configurations
        for note in (modes.band_note, modes.order_note):
            if note:
                print(f"flexmodal: {config}: {note}", file=sys.stderr)
        for warning in modes.warnings:
            print(f"flexmodal: warning: {config}: {warning}", file=sys.stderr)
        for line in modes.details if verbose else ():
            print(f"flexmodal: {config}: {line}", file=sys.stderr)
    if each:
        return
    summary = result.warning_summary()
    for line in summary:
        print(f"flexmodal: warning: {line}", file=sys.stderr)
    n, kinds = len(result.warnings), len(summary)
    print(f"flexmodal: {len(result.table.frame)} modes in {len(result.modes)} configurations, "
          f"{n} warning{'s' * (n != 1)} of {kinds} kind{'s' * (kinds != 1)} "
          "(--verbose: each configuration's band, model order and warnings)", file=sys.stderr)
