"""The real-data scoreboard is locked: every corpus entry (tests/data/realdata/) is identified with
default options by ``flexmodal identify`` run as a subprocess (benchmarks/realdata.py), and its score
may not fall below the one recorded in benchmarks/realdata_scores.json; the scoreboard in
docs/modal.md must show the numbers a fresh run gives (wall time excepted).

Raising a recorded score means re-running ``python benchmarks/realdata.py --write-scores
--write-docs`` and committing both files with the change that earned it.  The fast entries run in the
default suite, the others under ``-m slow``; every entry runs in one of the two.
"""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("realdata_benchmark", ROOT / "benchmarks" / "realdata.py")
realdata = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("realdata_benchmark", realdata)   # its dataclass looks its module up by name
_spec.loader.exec_module(realdata)

RECORDED = json.loads(realdata.SCORES.read_text())
# entries of least CPU time (the two issue-23 regressions and the analyser 58b export): the default
# suite's share, ~15 s on an idle machine
FAST = ("modelab_free_beam", "pyuff_meas_point", "pyuff_mps_oma")
SLOW = tuple(e for e in realdata.entries() if e not in FAST)


def _docs_rows() -> dict[str, list[str]]:
    text = realdata.DOCS.read_text()
    assert realdata.START in text and realdata.END in text, "docs/modal.md has no real-data scoreboard"
    section = text.split(realdata.START, 1)[1].split(realdata.END, 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 10 and cells[0] in RECORDED:
            rows[cells[0]] = cells
    return rows


def _check(entry: str) -> None:
    score = realdata.run_entry(entry, timeout_s=600)
    floor = RECORDED[entry]
    assert score.n_ref == floor["n_ref"], f"{entry}: the reference changed; re-record its score"
    assert score.found >= floor["found"], f"{entry}: {score.found} modes found, recorded {floor['found']}"
    assert score.extras <= floor["extras"], f"{entry}: {score.extras} extra modes, recorded {floor['extras']}"
    assert score.damping_ok >= floor["damping_ok"], (
        f"{entry}: damping within the reference's spread for {score.damping_ok}, "
        f"recorded {floor['damping_ok']}")
    if floor["exit_code"] == 0:
        assert score.exit_code == 0, f"{entry}: exit {score.exit_code}: {score.message}"
    assert realdata.recorded(score) == floor, (
        f"{entry}: score improved to {realdata.recorded(score)}; record it (benchmarks/realdata.py "
        "--write-scores --write-docs) in the commit that improved it")
    assert _docs_rows()[entry][:-1] == realdata.cells(score)[:-1], (
        f"{entry}: docs/modal.md's scoreboard row differs from a fresh run; regenerate it with "
        "benchmarks/realdata.py --write-docs")


def test_every_entry_has_a_recorded_score_a_docs_row_and_runs_somewhere():
    names = realdata.entries()
    assert len(names) >= 6
    assert sorted(RECORDED) == names
    assert sorted(_docs_rows()) == names
    assert set(FAST) <= set(names) and sorted(FAST + SLOW) == names


def test_each_entry_carries_its_source_licence_and_a_readable_reference():
    total = 0
    for name in realdata.entries():
        path, source, reference = realdata.load_entry(name)
        assert path.is_file(), path
        total += sum(p.stat().st_size for p in path.parent.iterdir())
        for key in ("repository", "licence", "kind", "derived", "script"):
            assert source.get(key), f"{name}: source.json lacks {key}"
        lo, hi = reference["band_hz"]
        assert reference["tolerance_pct"] in (0.05, 0.1, 0.5)
        for m in reference["modes"]:
            assert lo <= m["freq_hz"] <= hi
            assert m["damping_range"][0] <= m["damping_ratio"] <= m["damping_range"][1]
    assert total <= 12_000_000, f"the corpus holds {total} bytes (at most 12 MB)"


def test_match_pairs_each_reference_mode_once_within_tolerance():
    ref = np.array([100.0, 101.0, 200.0])
    found = np.array([100.04, 100.2, 199.2, 300.0])
    # 100.04 is 0.04 % from 100 and goes there; 100.2 is 0.79 % from 101 (outside 0.5 %)
    assert realdata.match(found, ref, 0.5) == [(0, 0), (2, 2)]
    assert realdata.match(found, ref, 0.05) == [(0, 0)]
    assert realdata.match(np.array([]), ref, 0.5) == []


def test_tolerance_is_judged_mode_by_mode():
    """One scattered reference mode keeps the entry's 0.5 % for itself only: a mode whose own scatter
    is below a third of 0.1 % is judged at 0.1 % (issue 23's "0.1 % where the reference's scatter
    allows"), and an entry's tighter tolerance (the regressions' 0.05 %) is never loosened."""
    modes = [{"freq_hz": 100.0, "freq_scatter_hz": 0.01}, {"freq_hz": 200.0, "freq_scatter_hz": 0.2}]
    tols = realdata.mode_tolerances_pct({"tolerance_pct": 0.5, "modes": modes})
    assert tols.tolist() == [0.1, 0.5]
    assert realdata.mode_tolerances_pct({"tolerance_pct": 0.05, "modes": modes}).tolist() == [0.05, 0.05]
    # 100.2 Hz is 0.2 % off the tight mode (a miss); 200.8 Hz is 0.4 % off the scattered one (a hit)
    assert realdata.match(np.array([100.2, 200.8]), np.array([100.0, 200.0]), tols) == [(1, 1)]
    reference = {"band_hz": [50, 250], "tolerance_pct": 0.5, "modes": [
        {**m, "damping_range": [0.0, 1.0]} for m in modes]}
    s = realdata.score_table("x", "k", reference, pd.DataFrame({"freq_hz": [100.2, 200.8],
                                                                "damping_ratio": [0.01, 0.01]}), 0, 1.0)
    assert (s.found, s.extras, realdata.tolerance_text(s)) == (1, 1, "0.1/0.5 %")


def test_score_counts_extras_in_band_only_and_damping_within_the_spread():
    reference = {"band_hz": [50, 250], "tolerance_pct": 0.5, "uncertain_hz": [150.0],
                 "modes": [{"freq_hz": 100.0, "damping_range": [0.009, 0.011]},
                           {"freq_hz": 200.0, "damping_range": [0.004, 0.006]}]}
    table = pd.DataFrame({"freq_hz": [40.0, 100.1, 150.3, 170.0, 199.5, 300.0],
                          "damping_ratio": [0.01, 0.0100, 0.02, 0.02, 0.008, 0.01]})
    s = realdata.score_table("x", "k", reference, table, 0, 1.0)
    # 40 and 300 Hz lie outside the band, 150.3 Hz is within 0.5 % of an uncertain candidate: 170 Hz is
    # the only extra; 199.5 Hz is found but its damping 0.008 is outside [0.004, 0.006]
    assert (s.found, s.extras, s.damping_ok) == (2, 1, 1)
    failed = realdata.score_table("x", "k", reference, None, 2, 1.0, "bad")
    assert (failed.found, failed.extras, failed.damping_ok, failed.exit_code) == (0, 0, 0, 2)


def test_docs_section_is_regenerated_in_place(tmp_path):
    doc = tmp_path / "modal.md"
    doc.write_text(f"# Modal\n\nbefore\n\n{realdata.START}\nold\n{realdata.END}\n\nafter\n")
    s = realdata.Score("e1", "impact", 3, 0.5, 2, 1, 1, 0, 1.25)
    realdata.write_docs([s], doc)
    text = doc.read_text()
    assert text.startswith("# Modal\n\nbefore\n\n") and text.endswith("\n\nafter\n") and "old" not in text
    assert "| e1 | impact | 3 | 2/3 | 0.5 % | 1 | 1/2 | 0 | no | 1.2 s |" in text
    assert re.search(r"\| \*\*all 1\*\* \| \| 3 \| 2/3 \|", text)


def test_acceptance_is_issue_23s_three_thresholds():
    def score(found, extras, damping_ok, code=0):
        return realdata.Score("e", "k", 10, 0.5, found, extras, damping_ok, code, 1.0)

    assert realdata.accepted(score(9, 1, 8))          # 90 %, one extra, 8/9 = 89 % damping
    assert not realdata.accepted(score(8, 0, 8))      # 80 % found
    assert not realdata.accepted(score(10, 2, 10))    # two extras
    assert not realdata.accepted(score(10, 0, 7))     # 70 % damping
    assert not realdata.accepted(score(10, 0, 10, 2))


@pytest.mark.parametrize("entry", FAST)
def test_fast_entry_holds_its_recorded_score(entry):
    _check(entry)


@pytest.mark.slow
@pytest.mark.parametrize("entry", SLOW)
def test_slow_entry_holds_its_recorded_score(entry):
    _check(entry)
