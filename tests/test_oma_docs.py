"""The accuracy figures of docs/oma.md are what benchmarks/oma_accuracy.py prints now."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow   # ~10 s quiet, ~30 s on the loaded machine; the capabilities have their own tests
def test_every_figure_of_docs_oma_is_reproduced(capsys):
    spec = importlib.util.spec_from_file_location("oma_accuracy", REPO / "benchmarks" / "oma_accuracy.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main() == 0
    rows = capsys.readouterr().out.strip().splitlines()
    docs = (REPO / "docs" / "oma.md").read_text()
    assert len(rows) == 11
    missing = [r for r in rows if r not in docs]
    assert not missing, missing
