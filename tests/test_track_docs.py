"""The tracking figures of docs/oma.md are what benchmarks/track.py prints now (accuracy, the two-joint
path, the veering case, the crossing case and the diagnosis; the 10-minute speed figure is a benchmark,
not re-run here), and a small version of the benchmark's accuracy measurement runs in the default
suite."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path

import pytest
from docs_kernel import run_under_docs_kernel

REPO = Path(__file__).resolve().parents[1]


def _benchmark():
    spec = importlib.util.spec_from_file_location("track_bench", REPO / "benchmarks" / "track.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _in_docs(rows):
    docs = (REPO / "docs" / "oma.md").read_text()
    return [r for r in rows if r not in docs]


_PART = """
import importlib.util, json, sys
spec = importlib.util.spec_from_file_location("track_bench", sys.argv[1])
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
print(json.dumps(getattr(module, sys.argv[2])()))
"""


# One slow test per table of docs/oma.md: each re-runs one part of the benchmark, 30-70 s of CPU
# (a sweep simulated, tracked in ~300 windows with two refinement passes, the truth model solved along
# it; the diagnosis part also a frozen-pose campaign and two diagnoses), so a few minutes each at a
# load of 10 on two cores; all of them together were one test of about an hour at such loads.
@pytest.mark.slow
@pytest.mark.timeout(3600)
@pytest.mark.parametrize("part", ["accuracy_rows", "two_joint_rows", "veering_rows", "crossing_rows",
                                  "diagnosis_rows"])
def test_every_tracking_figure_of_docs_oma_is_reproduced(part):
    out = run_under_docs_kernel([sys.executable, "-c", _PART, str(REPO / "benchmarks" / "track.py"), part],
                                timeout_s=3000)
    missing = _in_docs(json.loads(out.splitlines()[-1]))
    assert not missing, missing


@pytest.mark.timeout(1800)
def test_benchmark_accuracy_rows_on_a_short_sweep():
    """The benchmark's accuracy measurement on a 40 s sweep 0 -> 60 -> 0 deg with the three harmonic
    orders, modes below 200 Hz: its rows name every tracked mode against the truth model, no harmonic
    reported as a mode, and the two modes tracked within 1 % over most of the record."""
    from flexmodal.fixtures.moving_arm import Trajectory

    module = _benchmark()
    path = Trajectory({"theta_deg": 0.0}, {"theta_deg": 60.0}, 40.0)
    rows, res = module._accuracy(module.DEMO_RIG, path, 200.0, 3, "short sweep", module.MOTOR_ORDERS)
    assert rows[0].startswith("| short sweep | ") and len(res.tracks) == 2
    for row in rows[1:3]:
        share = int(re.match(r"\| mode \d \([0-9-]+ Hz\) \| (\d+)%", row).group(1))
        assert share >= 70, row
    assert rows[-1].endswith("| 0 reported as modes | | | |")
