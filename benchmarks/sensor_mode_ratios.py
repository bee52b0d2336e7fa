"""The moved-sensor test's ratios mode by mode on blind draws (compare/sensor_flag.py ``SENSOR_MODE_FACTOR``).

    python benchmarks/sensor_mode_ratios.py                # print the block: draws 1156-1160, ~4 min each
    python benchmarks/sensor_mode_ratios.py --write        # and put it into docs/diagnosis.md
    python benchmarks/sensor_mode_ratios.py --seeds 1261   # other draws, printed only

Each case of ``run_blind`` (fixtures/blind.py, 36 per draw) whose diagnosis checks its measured shapes
(three sensors or more: ``sensor_flag`` is called once, with the verdict's fitted model, or the nominal
model for ``none``) gives its largest ratio in one mode -- a sensor's misfit mean square in that mode
over that mode's shape noise at the other sensors, ``sensor_check`` of that mode alone -- and whether
the test flags the verdict, pooled over modes or in one mode.  One line per draw: the moved sensors
(category ``sensor``), and the ``none`` and in-library cases (``single``, ``weak``, ``pair``) flagged
and the largest ratio among them; cases outside the library are left out (a flag there is right).
docs/diagnosis.md quotes the block ``sensor_modes``; tests/test_diagnosis_sensor_flag.py re-runs every
draw under ``-m slow`` and compares its line.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path
from typing import NamedTuple
from unittest import mock

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from diagnosis_doc import BLIND_CASES, write_block  # noqa: E402

import flexmodal.compare.diagnosis as diagnosis  # noqa: E402
import flexmodal.compare.sensor_flag as sensor_flag_module  # noqa: E402
from flexmodal.compare.sensor_flag import sensor_check, sensor_flag  # noqa: E402
from flexmodal.fixtures.blind import run_blind  # noqa: E402

SEEDS = (1156, 1157, 1158, 1159, 1160)
"""The draws the mode-by-mode test was developed on (blind 1159 #10), run with the current method."""
CLEAN = ("none", "single", "weak", "pair")
"""Categories whose verdict a sensor flag would wrongly mark: nothing moved, every effect in the library."""


class CaseRatio(NamedTuple):
    """One case's shape check: its index in the draw, category, largest ratio in one mode [-] and that
    mode (1-based), how the test flags the verdict (``""`` not, ``"pooled"``, or ``"in mode k"``), and
    the largest ratio pooled over modes [-]."""

    index: int
    category: str
    ratio: float
    mode: int
    flag: str
    pooled: float


def mode_ratio(measured: np.ndarray, model: np.ndarray) -> tuple[float, int, str, float] | None:
    """(largest ratio of one mode, that mode 1-based, the test's flag, largest pooled ratio) of
    ``sensor_check`` on ``measured`` against ``model`` [C, s, n]; None when the check does not apply."""
    check = sensor_check(measured, model)
    if check is None:
        return None
    full = ~(np.isnan(measured).any(axis=(1, 2)) | np.isnan(model).any(axis=(1, 2)))
    m, a = measured[full], model[full]
    ratios = [sensor_check(m[..., [k]], a[..., [k]]).ratio for k in range(m.shape[2])]
    k = int(np.argmax(ratios))
    flag = "" if not check.flagged else "pooled" if check.mode is None else f"in mode {check.mode + 1}"
    with mock.patch.object(sensor_flag_module, "SENSOR_MODE_FACTOR", np.inf):   # the pooled test alone
        pooled = sensor_check(measured, model).ratio
    return ratios[k], k + 1, flag, pooled


def draw_ratios(seed: int, cases: int = BLIND_CASES) -> list[CaseRatio]:
    """The shape check of every case of draw ``seed`` whose diagnosis makes one."""
    checks: list = []
    rows: list[CaseRatio] = []
    index = itertools.count()

    def recording(measured, model, names):
        checks.append(mode_ratio(measured, model))
        return sensor_flag(measured, model, names)

    def done(result) -> None:
        i, found = next(index), [c for c in checks if c is not None]
        checks.clear()
        if found:
            rows.append(CaseRatio(i, result.case.category, *found[-1]))

    with mock.patch.object(diagnosis, "sensor_flag", recording):
        run_blind(cases, seed=seed, progress=done)
    return rows


def _ratio(x: float) -> str:
    return f"{x:.1f}" if x < 100 else f"{x:.0f}"


def draw_line(seed: int, rows: list[CaseRatio]) -> str:
    """One draw's line of the block."""
    moved = ", ".join(f"#{r.index} {_ratio(r.ratio)} in mode {r.mode} (pooled {_ratio(r.pooled)}), "
                      + (f"flagged {r.flag}" if r.flag else "not flagged")
                      for r in rows if r.category == "sensor") or "none checked"
    clean = [r for r in rows if r.category in CLEAN]
    flagged = [f"#{r.index} ({r.category}, {r.flag})" for r in clean if r.flag]
    top = max(clean, key=lambda r: r.ratio, default=None)
    largest = "" if top is None else (f"; largest ratio {_ratio(top.ratio)}, #{top.index} {top.category} "
                                      f"mode {top.mode}")
    return (f"draw {seed}: {len(rows)} cases checked; moved sensor {moved}; none or in-library: "
            f"{len(flagged)} of {len(clean)} flagged{': ' + ', '.join(flagged) if flagged else ''}{largest}")


def block(seeds: tuple[int, ...] = SEEDS, cases: int = BLIND_CASES) -> str:
    """The fenced block of ``cases`` cases of each draw of ``seeds``."""
    return "```\n" + "\n".join(draw_line(s, draw_ratios(s, cases)) for s in seeds) + "\n```"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=lambda t: tuple(int(x) for x in t.split(",")), default=SEEDS,
                    help="comma-separated draws (default 1156-1160)")
    ap.add_argument("--write", action="store_true", help="replace its block in docs/diagnosis.md")
    args = ap.parse_args()
    if args.write and args.seeds != SEEDS:
        ap.error("--write puts the draws 1156-1160 into docs/diagnosis.md: leave --seeds out")
    text = block(args.seeds)
    if args.write:
        write_block("sensor_modes", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
