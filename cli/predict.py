"""CLI commands of the `models` package (registered by app.py): ``flexmodal predict``."""

from __future__ import annotations

import argparse
import sys

from flexmodal.api import MAX_ELEMENTS, MODELS
from flexmodal.checked_io import options as opt
from flexmodal.cli.commands import Subcommands, command


def register(sub: Subcommands) -> None:
    """Add this package's sub-commands to the flexmodal parser."""
    p = command(sub, "predict", _predict)
    p.add_argument("rig", metavar="RIG.toml", help="rig description (docs/formats.md)")
    p.add_argument("--model", required=True, choices=MODELS,
                   help="fe: planar frame finite elements; assumed-modes: exact beam eigenfunctions "
                        "(straight uniform arm only); lumped-mass: flexibility-matrix lumped masses "
                        "(seed 003); blevins: closed-form beam table (straight uniform arm, plain ends)")
    p.add_argument("--poses", required=True, metavar="POSES.csv", help="one row per configuration")
    p.add_argument("--out", required=True, metavar="PRED.csv", help="output modal table")
    p.add_argument("--modes", type=opt.integer(1, 1000), default=4, metavar="N",
                   help="elastic modes per pose (default 4)")
    p.add_argument("--source", type=opt.nonempty, default=None, metavar="NAME",
                   help="value of the output's source column (default: the model name, e.g. fe)")
    p.add_argument("--elements", type=opt.integer(1, MAX_ELEMENTS), default=None, metavar="N",
                   help="fe: elements per link and member (default: the rig's `elements`, else 10)")
    p.add_argument("--lumped-mass-matrix", action="store_true",
                   help="fe: diagonal (HRZ-lumped) mass matrix instead of the consistent one")
    p.add_argument("--masses-per-link", type=opt.integer(1, 1000), default=4, metavar="N",
                   help="lumped-mass: lumped masses per link (default 4, as in seed 003)")
    p.add_argument("--coordinates", choices=("planar", "transverse"), default="planar",
                   help="lumped-mass: both in-plane translations per mass (default) or only the one "
                        "normal to its link (seed 003's choice)")


def _predict(args: argparse.Namespace) -> int:
    """predicted natural frequencies and mode shapes of a rig for each pose

    Predict the modes of the arm described by RIG.toml for every configuration in POSES.csv (columns
    config, pose.<name>; angles in degrees, masses in kg) and write a modal table CSV (config, mode,
    freq_hz [Hz], source, pose.*, shape.<sensor>). Rigid-body (0 Hz) modes are left out.
    """
    from flexmodal.api import predict, read_poses

    options = {"elements_per_link": args.elements, "lumped_mass": args.lumped_mass_matrix,
               "masses_per_link": args.masses_per_link, "coordinates": args.coordinates,
               "source": args.source, "out": args.out}
    # a bar on a terminal only (on a log or a pipe rich leaves an empty line), for any table of two or
    # more poses: ten poses of a 400-element frame take 36 s (it was shown from 50 poses on)
    n_poses = 0 if getattr(args, "quiet", False) or not sys.stderr.isatty() else len(read_poses(args.poses))
    if n_poses < 2:  # the poses by path: an error names the file
        predict(args.rig, args.poses, args.model, args.modes, **options)
    else:
        from rich.progress import Progress

        with Progress(transient=True, console=_stderr_console()) as bar:
            task = bar.add_task(f"predict ({args.model})", total=n_poses)
            predict(args.rig, args.poses, args.model, args.modes, progress=lambda _c: bar.advance(task),
                    **options)
    print(args.out)
    return 0


def _stderr_console():
    from rich.console import Console

    return Console(file=sys.stderr)
