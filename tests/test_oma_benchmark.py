"""benchmarks/oma.py on a short record: it runs, times both sides and finds the same modes as pyOMA2
(the timing itself is not a unit test; see docs/oma.md for the measured ratio)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path


def test_benchmark_runs_and_flexmodal_agrees_with_pyoma2(capsys):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "oma.py"
    spec = importlib.util.spec_from_file_location("oma_benchmark", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    args = ["--samples", "30000", "--max-order", "40", "--block-rows", "10", "--repeat", "1"]
    assert module.main(args) == 0
    out = capsys.readouterr().out
    assert "ratio median" in out
    assert "flexmodal modes found 6/6" in out
    diff = float(re.search(r"max \|fn flexmodal/pyOMA2 - 1\| (\S+)", out).group(1))
    assert diff < 2e-3, out
    macs = re.search(r"min MAC vs truth: flexmodal (\S+), pyOMA2 (\S+)", out)
    assert float(macs.group(1)) > 0.99 and float(macs.group(2)) > 0.99, out
