"""The moved-sensor test on a real structure where nothing was moved (compare/sensor_flag.py).

    python benchmarks/sensor_flag_beam.py            # print the block (~5 s)
    python benchmarks/sensor_flag_beam.py --write    # and put it into docs/diagnosis.md

Measured: the first four modes flexmodal identifies in tests/data/realdata/modelab_free_beam (65-1000
Hz; ModeLAB's free beam, roving hammer at the nine points ``Z_M``, accelerometer at 0.5 m, both from
ModeLAB's Example/SignalCalc/setup.csv).  Model: the textbook free-free Euler-Bernoulli beam
(``cos(bL) cosh(bL) = 1``) at the same points, ``L`` = 1.3 m (the points' span and their 0.1 m end
margins).  Nothing was moved, so a flag is false, or a finding of a local effect the textbook beam lacks:
the accelerometer's own mass at 0.5 m.  As a review (28 Nov) made it: every set of 3, 4 and 5 of the
nine points with modes 1-2, 1-3 and 1-4, each mode scaled to a largest component of 1, repeated over 6
configurations with independent noise of 0.5 % of that (seed 2, drawn in that order).  One line per
sensor count: the sets, those the pooled test flags, and those the mode-by-mode test adds -- with one
mode alone (``SENSOR_MODES`` = 1, the rule before 28 Nov) and as now -- with how many of the added ones
name the sensor at the accelerometer.  docs/diagnosis.md quotes the block ``sensor_beam``;
tests/test_diagnosis_sensor_flag.py re-runs it.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path
from unittest import mock

import numpy as np
from scipy.optimize import brentq

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from diagnosis_doc import write_block  # noqa: E402

import flexmodal.compare.sensor_flag as sensor_flag_module  # noqa: E402
from flexmodal.api import identify  # noqa: E402
from flexmodal.compare.sensor_flag import sensor_check  # noqa: E402

BEAM = REPO / "tests" / "data" / "realdata" / "modelab_free_beam" / "free_beam.uff"
Z_M = np.array([0.1, 0.25, 0.375, 0.5, 0.65, 0.8, 0.925, 1.05, 1.2])
"""The hammer points [m] along the beam (ModeLAB setup.csv ``zHammer``): the shapes' sensors."""
ACCELEROMETER_M = 0.5
"""Where the accelerometer sits [m] (setup.csv ``zAccel``)."""
LENGTH_M = 1.3
SIZES = (3, 4, 5)
"""Sensor counts of the project's rigs (seed003: 3, seed001: 4, demo: 5)."""
MODE_SETS = ((0, 1), (0, 1, 2), (0, 1, 2, 3))
CONFIGS, NOISE, SEED = 6, 0.005, 2


def free_free_shapes(z_m: np.ndarray, n: int = 4, length_m: float = LENGTH_M) -> np.ndarray:
    """The first ``n`` flexible mode shapes [len(z), n] of a uniform free-free Euler-Bernoulli beam of
    length ``length_m`` at the points ``z_m`` [m] (the roots of ``cos(bL) cosh(bL) = 1``)."""
    roots = [brentq(lambda x: np.cos(x) * np.cosh(x) - 1.0, (k + 0.5) * np.pi - 0.5, (k + 0.5) * np.pi + 0.5)
             for k in range(1, n + 1)]                                # one root near (k + 1/2) pi
    out = []
    for bl in roots:
        b, sigma = bl / length_m, (np.cosh(bl) - np.cos(bl)) / (np.sinh(bl) - np.sin(bl))
        out.append(np.cosh(b * z_m) + np.cos(b * z_m) - sigma * (np.sinh(b * z_m) + np.sin(b * z_m)))
    return np.array(out).T


def beam_shapes() -> np.ndarray:
    """The identified shapes [9, 4] of the beam's first four modes, each scaled to a largest |component|
    of 1."""
    frame = identify(str(BEAM), fmin=65, fmax=1000).table.frame
    shapes = frame[[c for c in frame.columns if c.startswith("shape.")]].to_numpy(float).T[:, :4]
    return shapes / np.abs(shapes).max(axis=0)


def checks(measured: np.ndarray, model: np.ndarray) -> list[tuple[int, tuple, dict]]:
    """(sensor count, the points' indices, {rule: SensorCheck}) of every set, rules ``pooled`` (the
    pooled test alone), ``one mode`` (``SENSOR_MODES`` = 1) and ``now``."""
    rng = np.random.default_rng(SEED)
    out = []
    for s in SIZES:
        for points in itertools.combinations(range(len(Z_M)), s):
            for modes in MODE_SETS:
                m = measured[np.ix_(points, modes)][None].repeat(CONFIGS, axis=0)
                m = m + NOISE * rng.standard_normal(m.shape)
                a = model[np.ix_(points, modes)][None].repeat(CONFIGS, axis=0)
                found = {"now": sensor_check(m, a)}
                with mock.patch.object(sensor_flag_module, "SENSOR_MODES", 1):
                    found["one mode"] = sensor_check(m, a)
                with mock.patch.object(sensor_flag_module, "SENSOR_MODE_FACTOR", np.inf):
                    found["pooled"] = sensor_check(m, a)
                out.append((s, points, found))
    return out


def block(rows: list[tuple[int, tuple, dict]]) -> str:
    """The fenced block: one line per sensor count."""
    at = int(np.flatnonzero(Z_M == ACCELEROMETER_M)[0])
    lines = []
    for s in SIZES:
        mine = [(p, f) for n, p, f in rows if n == s]
        pooled = sum(f["pooled"].flagged for _, f in mine)
        added = {k: [(p, f[k]) for p, f in mine if f[k].flagged and not f["pooled"].flagged]
                 for k in ("one mode", "now")}
        near = {k: sum(p[c.sensor] == at for p, c in v) for k, v in added.items()}
        lines.append(f"{s} sensors: {len(mine)} sets; the pooled test flags {pooled}; the mode-by-mode test "
                     f"adds {len(added['one mode'])} with one mode alone ({near['one mode']} at the "
                     f"accelerometer), {len(added['now'])} now ({near['now']} at the accelerometer)")
    return "```\n" + "\n".join(lines) + "\n```"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="replace its block in docs/diagnosis.md")
    args = ap.parse_args()
    text = block(checks(beam_shapes(), free_free_shapes(Z_M)))
    if args.write:
        write_block("sensor_beam", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
