"""`flexmodal diagnose`: sim-to-real gap diagnosis (docs/formats.md) and its blind self-check."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from flexmodal.checked_io import options as opt
from flexmodal.cli.commands import Subcommands


def register(sub: Subcommands) -> None:
    """Add ``diagnose`` to the flexmodal parser."""
    p = sub.add_parser(
        "diagnose", help="sim-to-real gap diagnosis: where, which unmodelled effect, held-out improvement",
        description="Compare a nominal rig's FE modes with measured modes over several poses, rank every "
                    "unmodelled effect (docs/formats.md) at every location and pairs of them by their error "
                    "on held-out configurations, and write DIR/diagnosis.json and DIR/diagnosis.html.")
    p.add_argument("--rig", metavar="RIG.toml", help="nominal rig description (TOML, docs/formats.md)")
    p.add_argument("--measured", metavar="MODES.csv",
                   help="measured modes (modal table CSV, docs/formats.md) with pose.<var> columns")
    p.add_argument("--out", metavar="DIR", help="output directory for diagnosis.json and diagnosis.html")
    p.add_argument("--effects", default="all", metavar="all|NAME,...",
                   help="'all' or comma-separated effect names (docs/formats.md; default all)")
    p.add_argument("--holdout", default="auto", metavar="auto|CONFIG,...",
                   help="'auto' (leave one pose out, the configurations measured at one pose held out "
                        "together; 5-fold over poses above 10 poses) or a comma-separated list of "
                        "configurations to hold out")
    p.add_argument("--scatter", type=opt.real(1e-6, 1.0, hi_open=True, name="fraction"),
                   default=None, metavar="FRACTION",
                   help="fallback relative measurement scatter of the frequencies (fraction; default 0.005 = "
                        "0.5 %%), used only when the table has no repeated configurations and no "
                        "freq_std_hz column")
    p.add_argument("--selftest", type=opt.integer(1, 100000), metavar="N",
                   help="blind self-check instead: N random rigs simulated by an independent truth model "
                        "(Timoshenko frame) with withheld effects; prints accuracy")
    p.add_argument("--seed", type=opt.seed, default=0, metavar="N",
                   help="random seed of --selftest (default 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from flexmodal.api import CompareError

    if args.selftest is not None:
        from flexmodal.api import selftest

        def show(r) -> None:
            c, v = r.case, r.verdict
            print(f"{c.kind}/{c.category}: hidden {c.effect}@{c.location or '-'} -> {v.effect}@"
                  f"{v.location or '-'} ({r.seconds:.1f} s)", file=sys.stderr)

        check = selftest(args.selftest, seed=args.seed, progress=None if getattr(args, "quiet", False)
                         else show)
        print(check.text)
        return 0
    missing = [o for o in ("rig", "measured", "out") if getattr(args, o) is None]
    if missing:
        raise CompareError(f"diagnose: missing --{missing[0]} "
                           "(needs --rig, --measured and --out, or --selftest N)")
    from flexmodal.api import DIAGNOSIS_FILES, diagnose, format_diagnosis

    quiet = getattr(args, "quiet", False)
    result = diagnose(args.rig, args.measured, effects=args.effects, holdout=args.holdout,
                      scatter=args.scatter, out_dir=args.out,
                      progress=None if quiet else lambda line: print(line, file=sys.stderr))
    for warning in result.warnings or ():
        print(f"flexmodal: warning: {warning}", file=sys.stderr)
    print(format_diagnosis(result))
    for name in DIAGNOSIS_FILES:
        print(Path(args.out) / name)
    return 0
