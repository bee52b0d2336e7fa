"""CLI commands of the `models` package (registered by app.py): ``flexmodal predict``."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable

from flexmodal.api import MAX_ELEMENTS, MODELS
from flexmodal.checked_io import options as opt
from flexmodal.checked_io.errors import FlexmodalError
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
    p.add_argument("--masses-per-link", type=opt.integer(1, 1000), default=None, metavar="N",
                   help="lumped-mass: lumped masses per link (default 4, as in seed 003)")
    p.add_argument("--coordinates", choices=("planar", "transverse"), default=None,
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
    n_poses = 0 if getattr(args, "quiet", False) else _count_poses(args.poses, read_poses)
    if n_poses < 2:
        predict(args.rig, args.poses, args.model, args.modes, **options)
    elif sys.stderr.isatty():
        # a bar on a terminal, for any table of two or more poses: ten poses of a 400-element frame
        # take 36 s (it was shown from 50 poses on)
        from rich.progress import Progress

        with Progress(transient=True, console=_stderr_console()) as bar:
            task = bar.add_task(f"predict ({args.model})", total=n_poses)
            predict(args.rig, args.poses, args.model, args.modes, progress=lambda _c: bar.advance(task),
                    **options)
    else:  # on a log or a pipe (rich would leave an empty line there): a line every few seconds
        lines = ProgressLines(n_poses, "poses solved", _stderr_line)
        predict(args.rig, args.poses, args.model, args.modes, progress=lambda _c: lines.advance(), **options)
        lines.finish()
    print(args.out)
    return 0


class ProgressLines:
    """Progress of ``total`` items as text lines for a log or a pipe: a line when an item is done and
    at least ``every_s`` seconds, or a sixth of the time spent if longer, have passed since the start or
    the last line, and a last line (the total time) when any line was printed; quick work prints
    nothing.

    Parameters
    ----------
    total : int
        Items to do [count].
    what : str
        What an item done is called, plural (``"poses solved"``).
    write : callable
        Called with each line (no newline).
    every_s : float, optional
        Least time between two lines [s] (default 5).
    clock : callable, optional
        Seconds of a monotonic clock (default ``time.monotonic``).

    Examples
    --------
    Ten items of 3 s each on a clock that is told, not read:

    >>> t = [0.0]
    >>> lines = ProgressLines(10, "poses solved", print, every_s=10.0, clock=lambda: t[0])
    >>> for _ in range(10):
    ...     t[0] += 3.0
    ...     lines.advance()
    4/10 poses solved (12 s, about 18 s left)
    8/10 poses solved (24 s, about 6 s left)
    >>> lines.finish()
    10/10 poses solved in 30 s

    A thousand items of 0.6 s (10 min): 21 lines, every 5 s at first, then a sixth of the time spent.

    >>> t, said = [0.0], []
    >>> lines = ProgressLines(1000, "poses solved", said.append, clock=lambda: t[0])
    >>> for _ in range(1000):
    ...     t[0] += 0.6
    ...     lines.advance()
    >>> len(said), said[0], said[-1]
    (21, '9/1000 poses solved (5 s, about 595 s left)', '856/1000 poses solved (514 s, about 86 s left)')
    """

    def __init__(self, total: int, what: str, write: Callable[[str], None], *, every_s: float = 5.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.total, self.what, self.write, self.every_s, self.clock = total, what, write, every_s, clock
        self.done, self.printed = 0, False
        self.start_s = self.last_s = clock()

    def advance(self) -> None:
        """Count one item done; print a line when enough time has passed since the last one."""
        self.done += 1
        now_s = self.clock()
        # the gap grows with the time spent (a sixth of it), so a ten-minute job logs ~25 lines, not 120
        gap_s = max(self.every_s, (now_s - self.start_s) / 6.0)
        if now_s - self.last_s >= gap_s and self.done < self.total:
            elapsed_s = now_s - self.start_s
            left_s = elapsed_s / self.done * (self.total - self.done)
            self.write(f"{self.done}/{self.total} {self.what} ({elapsed_s:.0f} s, about {left_s:.0f} s left)")
            self.last_s, self.printed = now_s, True

    def finish(self) -> None:
        """The closing line (items and total time), only when a line was printed before."""
        if self.printed:
            self.write(f"{self.done}/{self.total} {self.what} in {self.clock() - self.start_s:.0f} s")


def _count_poses(path: str, read_poses: Callable[[str], dict]) -> int:
    """The number of configurations in POSES.csv, 0 when it cannot be read: predict then reports the
    first bad input (--out, the rig, the poses) in its own order, naming the file."""
    try:
        return len(read_poses(path))
    except FlexmodalError:
        return 0


def _stderr_line(line: str) -> None:
    print(f"predict: {line}", file=sys.stderr, flush=True)


def _stderr_console():
    from rich.console import Console

    return Console(file=sys.stderr)
