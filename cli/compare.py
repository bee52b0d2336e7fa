"""CLI commands of the `compare` package (registered by app.py): ``flexmodal compare``."""

from __future__ import annotations

import argparse
import sys

from flexmodal.checked_io import options as opt
from flexmodal.cli.commands import Subcommands, command


def register(sub: Subcommands) -> None:
    """Add this package's sub-commands to the flexmodal parser."""
    p = command(sub, "compare", _run)
    p.add_argument("measured", metavar="MEASURED.csv", help="measured modal table (docs/formats.md)")
    p.add_argument("predicted", metavar="PRED.csv", nargs="+",
                   help="predicted modal tables; each names its source by its 'source' column, "
                        "else by its file name")
    p.add_argument("--format", choices=("md", "csv", "tex", "html", "json"), default="md",
                   help="output format: Markdown, CSV (full precision), LaTeX booktabs table, HTML page or "
                        "JSON rows (full precision) (default md)")
    p.add_argument("--layout", choices=("modes", "sources"), default="modes",
                   help="modes: a row per mode, a column per source (seed 001 Table 3.1); "
                        "sources: a row per source, a column per mode (seed 000 Table 2); default modes")
    p.add_argument("--min-mac", type=opt.fraction, default=0.5, metavar="MAC",
                   help="reject MAC pairs below this value, 0..1 (default 0.5)")
    p.add_argument("--caption", type=opt.text_line, default="Measured and predicted natural frequencies",
                   metavar="TEXT",
                   help="table caption (tex and html; default '%(default)s')")
    p.add_argument("--out", metavar="FILE",
                   help="write the table to FILE (prints the path) instead of stdout ('-': stdout)")


def _run(args: argparse.Namespace) -> int:
    """table of measured vs predicted modes (paired by MAC or frequency order)

    Pair every predicted modal table with the measured one (by MAC where both have shapes at two or
    more common sensors, else by ascending frequency) and print a table: frequencies [Hz], measured
    damping ratio [%], error (pred - meas)/meas [%] and MAC [-]. Unpaired modes are listed, never
    dropped.
    """
    from flexmodal.api import compare_modes, format_comparison, write_comparison

    comp = compare_modes(args.measured, *args.predicted, min_mac=args.min_mac)
    for warning in comp.warnings():
        print(f"flexmodal: warning: {warning}", file=sys.stderr)
    if args.out not in (None, "-"):   # "" (an unset variable) is refused by the path check, not stdout
        print(write_comparison(comp, args.out, args.format, args.layout, args.caption))
    else:
        sys.stdout.write(format_comparison(comp, args.format, args.layout, args.caption))
    return 0
