"""The tracking figures of docs/oma.md are what benchmarks/track.py prints now (accuracy and diagnosis;
the 10-minute speed figure is a benchmark, not re-run here)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow   # a 90 s sweep tracked twice, a frozen-pose campaign and two diagnoses: minutes
@pytest.mark.timeout(3600)
def test_every_tracking_figure_of_docs_oma_is_reproduced():
    spec = importlib.util.spec_from_file_location("track_bench", REPO / "benchmarks" / "track.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    rows = module.accuracy_rows() + module.diagnosis_rows()
    docs = (REPO / "docs" / "oma.md").read_text()
    assert len(rows) == 8
    missing = [r for r in rows if r not in docs]
    assert not missing, missing
