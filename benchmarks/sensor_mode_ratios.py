"""The moved-sensor test's ratios mode by mode on blind draws (compare/sensor_flag.py ``SENSOR_MODE_FACTOR``).

    python benchmarks/sensor_mode_ratios.py                # print the block: draws 1156-1160, ~2 min each
    python benchmarks/sensor_mode_ratios.py --write        # and put it into docs/diagnosis.md
    python benchmarks/sensor_mode_ratios.py --fresh --write  # the block of draws 1681-1685
    python benchmarks/sensor_mode_ratios.py --seeds 1261   # other draws, printed only

Each case of a blind draw (fixtures/blind.py, 36 per draw) whose diagnosis checks its measured shapes
(three sensors or more: ``sensor_flag`` is called once, with the verdict's fitted model, or the nominal
model for ``none``) gives its largest ratio in one mode -- a sensor's misfit mean square in that mode
over that mode's shape noise at the other sensors, ``sensor_check`` of that mode alone -- and whether
the test flags the verdict, pooled over modes or in one mode.  One line per draw: the moved sensors
(category ``sensor``), and the ``none`` and in-library cases (``single``, ``weak``, ``pair``) flagged
and the largest ratio among them; cases outside the library are left out (a flag there is right).
docs/diagnosis.md quotes the blocks ``sensor_modes`` (the draws the test was developed on) and
``sensor_modes_fresh`` (draws 1681-1685, none of which chose it); tests/test_diagnosis_sensor_flag.py
re-runs every draw under ``-m slow`` and compares its line.
"""

from __future__ import annotations

import argparse
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
from flexmodal.compare.diagnosis import diagnose  # noqa: E402
from flexmodal.compare.sensor_flag import sensor_check, sensor_flag  # noqa: E402
from flexmodal.fixtures.blind import draw_cases  # noqa: E402

SEEDS = (1156, 1157, 1158, 1159, 1160)
"""The draws the mode-by-mode test was developed on (blind 1159 #10), run with the current method."""
FRESH = (1681, 1682, 1683, 1684, 1685)
"""Draws no part of the sensor test was chosen on (block ``sensor_modes_fresh``)."""
BLOCKS = {SEEDS: "sensor_modes", FRESH: "sensor_modes_fresh"}
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
    """The shape check of every case of draw ``seed`` whose diagnosis makes one (the cases of
    ``run_blind``; those with shapes at fewer than three sensors, which no check reaches, are not
    diagnosed)."""
    checks: list = []
    rows: list[CaseRatio] = []

    def recording(measured, model, names):
        checks.append(mode_ratio(measured, model))
        return sensor_flag(measured, model, names)

    for i, case in enumerate(draw_cases(cases, seed)):
        if sum(c.startswith("shape.") for c in case.table.frame.columns) < 3:
            continue
        with mock.patch.object(diagnosis, "sensor_flag", recording):
            diagnose(case.rig, case.table)
        found = [c for c in checks if c is not None]
        checks.clear()
        if found:
            rows.append(CaseRatio(i, case.category, *found[-1]))
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
    ap.add_argument("--fresh", action="store_const", const=FRESH, dest="seeds",
                    help="the draws 1681-1685 (block sensor_modes_fresh)")
    ap.add_argument("--write", action="store_true", help="replace its block in docs/diagnosis.md")
    args = ap.parse_args()
    if args.write and args.seeds not in BLOCKS:
        ap.error("--write puts the draws 1156-1160 or 1681-1685 (--fresh) into docs/diagnosis.md: "
                 "leave --seeds out")
    text = block(args.seeds)
    if args.write:
        write_block(BLOCKS[args.seeds], text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
