"""CLI commands of the `reports` package (registered by app.py): ``flexmodal report``."""

from __future__ import annotations

import argparse
import sys

from flexmodal.checked_io import options as opt
from flexmodal.cli.commands import Subcommands, command


def register(sub: Subcommands) -> None:
    """Add this package's sub-commands to the flexmodal parser."""
    p = command(sub, "report", _run)
    p.add_argument("runs", metavar="RUN.h5", nargs="*",
                   help="stored runs (docs/hdf5-format.md): a file means all its runs, FILE::RUN_ID one run")
    p.add_argument("--measured", metavar="MODES.csv", help="identified modes (modal table, docs/formats.md)")
    p.add_argument("--repeat", metavar="MODES.csv", action="append", default=[],
                   help="modes of a repeated test of the same configurations (error bars; repeatable)")
    p.add_argument("--pred", metavar="PRED.csv", action="append", default=[],
                   help="predicted modes of one model (repeatable)")
    p.add_argument("--diagnosis", metavar="diagnosis.json",
                   help="output of flexmodal diagnose (docs/formats.md)")
    p.add_argument("--rig", metavar="RIG.toml", help="rig description, to draw mode shapes on the arm")
    p.add_argument("--geometry", metavar="GEOMETRY.uff",
                   help="test geometry (UFF datasets 15/2411, 82, 18/2420) to animate the measured modes on")
    p.add_argument("--shapes-at", metavar="CONFIG", action="append", default=None,
                   help="a measured configuration whose mode shapes to draw on the rig (repeatable; "
                        "default: the first and the last)")
    p.add_argument("--title", type=opt.text_line, default="flexmodal validation report", metavar="TEXT",
                   help="report title (default '%(default)s')")
    p.add_argument("--fmin", metavar="HZ", type=opt.positive_hz,
                   help="runs with FRFs: identify above this frequency (as identify --fmin)")
    p.add_argument("--fmax", metavar="HZ", type=opt.positive_hz,
                   help="runs with FRFs: identify below this frequency (as identify --fmax)")
    p.add_argument("--oma-fmin", metavar="HZ", type=opt.positive_hz,
                   help="output-only runs: identify (SSI, FDD) above this frequency (as identify --fmin)")
    p.add_argument("--oma-fmax", metavar="HZ", type=opt.positive_hz,
                   help="output-only runs: identify (SSI, FDD) below this frequency (as identify --fmax)")
    p.add_argument("--out", metavar="REPORT.html", required=True, help="the HTML file to write")
    p.add_argument("--pdf", action="store_true",
                   help="also print it to REPORT.pdf beside it with headless Chromium (A4, tables whole)")


def _run(args: argparse.Namespace) -> int:
    """self-contained HTML validation report from runs, modes, predictions and a diagnosis

    Write one HTML file (images embedded, one inline script for the shape animation and printing,
    nothing fetched from a network): run metadata, channels, data quality (events, rejected hits,
    coherence), FRF plots, measured vs predicted modes (table and plots) and the gap diagnosis; with
    --pdf also REPORT.pdf, printed by headless Chromium.
    """
    from flexmodal.api import report

    quiet = getattr(args, "quiet", False)
    progress = None if quiet else (lambda msg: print(f"report: {msg}", file=sys.stderr))
    out = report(args.out, runs=args.runs, measured=args.measured, repeats=args.repeat, predictions=args.pred,
                 diagnosis=args.diagnosis, rig=args.rig, title=args.title, oma_fmin=args.oma_fmin,
                 oma_fmax=args.oma_fmax, fmin=args.fmin, fmax=args.fmax, geometry=args.geometry,
                 progress=progress, pdf=args.pdf, shapes_at=args.shapes_at)
    print(out)
    if args.pdf:
        print(out.with_suffix(".pdf"))
    return 0
