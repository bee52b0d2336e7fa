"""Blind accuracy of the gap diagnosis against the independent truth model (fixtures/blind.py).

The default run diagnoses the first eight cases (every rig kind; single, weak and paired effects, one
``none``, one effect outside the library; two mass look-alikes that only the measured shapes separate
and a pair whose second part is poor on its own).  The full 36-case run is ``slow``: it asserts the
acceptance targets and that docs/diagnosis.md quotes exactly its table.
"""

from __future__ import annotations

import importlib.util
import json
import sys

import numpy as np
import pytest
from scipy.stats import chi2

from flexmodal.checked_io.percent import percent
from flexmodal.compare.diagnosis import diagnose
from flexmodal.contract.table import ModalTable
from flexmodal.fixtures.blind import (
    CATEGORIES,
    KINDS,
    advice_trials,
    format_advice,
    format_draws,
    format_summary,
    format_table,
    make_case,
    moved_fraction,
    run_blind,
    run_sparse,
    summarise,
)


def _strict(text: str) -> dict:
    return json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))


def _check(results) -> dict:
    s = summarise(results)
    print(format_table(results))
    print(format_summary(s))
    for r in results:
        _strict(r.verdict.to_json())
        if r.verdict.effect == "none":          # alternatives only on a verdict flagged ambiguous
            assert bool(r.verdict.alternatives) == bool(r.verdict.ambiguous)
    return s


def test_a_figure_with_no_case_of_its_kind_reads_no_cases():
    """No ``nan %`` in the summary: a category without cases (here: none at all) says so."""
    text = format_summary(summarise([])) + "\n" + format_draws([summarise([])])
    assert "nan" not in text
    assert "moved sensor flagged by its shapes: no cases\n" in text
    assert "held-out frequencies inside their 95 % prediction interval: no cases" in text
    assert "  'none' right: no cases" in text


@pytest.fixture(scope="module")
def first_eight():
    return run_blind(8, seed=0)


@pytest.mark.timeout(1800)          # ~60 s on a quiet machine (case generation included), more under load
def test_first_eight_blind_cases_are_all_right(first_eight):
    s = _check(first_eight)
    assert s["n_library"] == 6 and s["n_none"] == 1 and s["n_outside"] == 1
    assert s["top1_effect_accuracy"] == 1.0 and s["location_accuracy"] == 1.0
    assert s["none_accuracy"] == 1.0
    assert s["outside_flagged"] == 1.0
    assert s["heldout_after_within_2x_scatter"] == 1.0


@pytest.mark.parametrize("index", [3, 4])
def test_shapes_separate_look_alikes_that_frequencies_leave_ambiguous(first_eight, index):
    """Cases 3 (sensor + tip mass vs link + tip mass) and 4 (weak base stiffness vs sensor mass): right
    and unambiguous with their measured shapes; without the shape columns the frequencies alone leave
    the right answer only among the alternatives of an ambiguous verdict."""
    r = first_eight[index]
    assert r.case.shapes and r.location_ok and not r.verdict.ambiguous
    frame = r.case.table.frame
    bare = ModalTable.from_frame(frame[[c for c in frame.columns if not c.startswith("shape.")]], "<bare>")
    v = diagnose(r.case.rig, bare).verdict
    assert v.ambiguous
    assert (r.case.effect, r.case.location) in {(v.effect, v.location)} | {
        (a.effect, a.location) for a in v.alternatives}


def test_a_moved_sensor_sits_half_a_link_away_wherever_the_rig_puts_it():
    """Sensor fractions are drawn on a 0.01 grid; at 0.5 the sensor was once "moved" to 0.5 (draw 631
    case 30: a moved-sensor case with no moved sensor)."""
    for f in [k / 100 for k in range(101)]:
        to = moved_fraction(f)
        assert 0.0 < to <= 1.0 and abs(to - f) == pytest.approx(0.5)


@pytest.mark.slow
@pytest.mark.timeout(14400)         # 5 draws x 36 cases + 60 sparse arms + the advice trials: ~30 min quiet
def test_the_draws_and_the_advice_the_docs_quote():
    """The acceptance measurement (benchmarks/diagnosis_doc.py ``DRAW_SETS``: 36 cases in each of five
    draws run once after the last change to the method), the next-measurement trials on 60 sparsely
    measured arms and on the ambiguous verdicts of those draws are exactly what docs/diagnosis.md
    quotes; the summary ("In short") states how many of the blind set's cases without an effect were
    ``none``, as measured (issue 26 asks for all: a shortfall is quoted, not hidden)."""
    from conftest import REPO

    spec = importlib.util.spec_from_file_location("diagnosis_doc", REPO / "benchmarks" / "diagnosis_doc.py")
    doc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(doc)
    draws = {}   # block name -> {seed: run_blind's results}
    for d in doc.DRAW_SETS:
        draws[d.name] = {seed: run_blind(doc.BLIND_CASES, seed=seed) for seed in d.seeds}
        assert doc.doc_block(d.name) == doc.blind_block(d.seeds, results=draws[d.name], note=d.note)
        assert doc.doc_block(d.ideal) == doc.ideal_block(draws[d.name], seeds=d.seeds)
    last = [r for res in draws[doc.DRAW_SETS[-1].name].values() for r in res if r.case.category == "none"]
    text = doc.DOC.read_text()
    short = " ".join(text[text.index("**In short**"):text.index("**What this version changed**")].split())
    assert f"`none` right {sum(r.verdict.effect == 'none' for r in last)} of {len(last)}" in short
    assert doc.doc_block("sparse") == doc.sparse_block()
    for name, seeds in doc.ADVICE_SETS.items():
        set_results = {s: r for d in draws.values() for s, r in d.items() if s in seeds}
        assert doc.doc_block(name) == doc.advice_block(set_results, seeds=seeds)


def test_the_summary_quotes_the_blind_figure_of_its_block():
    """docs/diagnosis.md's "In short" states the mean and worst draw of the last draw set's ideal-fit block
    (the acceptance's count), as that block prints them."""
    import re

    from conftest import REPO

    spec = importlib.util.spec_from_file_location("diagnosis_doc", REPO / "benchmarks" / "diagnosis_doc.py")
    doc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(doc)
    ideal = doc.doc_block(doc.DRAW_SETS[-1].ideal)
    mean, worst = re.search(r"mean ([\d.]+) %, worst ([\d.]+) %", ideal).groups()
    text = doc.DOC.read_text()
    short = text[text.index("**In short**"):text.index("**What this version changed**")]
    assert f"right {mean} % on average" in " ".join(short.split())
    assert f"{worst} % worst" in " ".join(short.split())


@pytest.mark.timeout(1800)          # ~15 s CPU: two truth arms, two diagnoses and three trial diagnoses
def test_no_pose_is_advised_where_the_alternatives_only_add_a_component():
    """Issue 26 (next measurement): the second sparse arm (fixtures/blind.py ``sparse_case``, seed 1: a
    sensor mass measured at three poses, two modes) is right but ambiguous with alternatives that only
    add a component to it (base stiffness, link mass) within the nested margin.  Whether one more pose
    confirms or excludes such a component is decided by its noise, not by where it is taken (on the
    used blind draws and the 60 sparse arms of docs/diagnosis.md's ``advice`` and ``sparse`` blocks,
    re-run by the slow test above, random poses resolve these as often as the old advice did), so no
    pose is advised and the summary says why; the advice trials still measure such a verdict at three
    random untested poses (reported apart from the advised ones).  That the advised pose resolves
    where poses inside the measured range do not: tests/test_next_measurement.py."""
    results = run_sparse(2, seed=1)
    v = results[1].verdict
    assert (v.effect, v.location) == (results[1].case.effect, results[1].case.location) and v.ambiguous
    assert all(set(v.effect.split("+")) < set(a.effect.split("+")) for a in v.alternatives)
    assert not v.next_measurements and "no pose is advised" in v.summary
    (trial,) = advice_trials(results, seed=1)
    assert trial.case is results[1].case and trial.advised is None and trial.advised_outcome is None
    assert len(set(trial.random_poses)) == 3 and len(trial.random_outcomes) == 3
    assert "no pose advised" in format_advice([trial])


def test_benchmark_script_times_the_six_pose_case_and_finds_its_effect(capsys, monkeypatch):
    """benchmarks/diagnose_blind.py (the source of docs/diagnosis.md's timing line) runs as written."""
    from conftest import REPO

    spec = importlib.util.spec_from_file_location("diagnose_blind", REPO / "benchmarks" / "diagnose_blind.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    monkeypatch.setattr(sys, "argv", ["diagnose_blind.py", "--cases", "0", "--timing-runs", "1"])
    assert bench.main() == 0
    out = capsys.readouterr().out
    assert "time, 6 poses x 4 modes" in out and "verdict joint_mass+joint_stiffness@elbow" in out


@pytest.mark.timeout(1800)          # ~5 s CPU: three candidates fitted and cross-validated over six poses
def test_an_ideal_fit_tells_the_truth_from_a_look_alike_only_beyond_noise():
    """``heldout_errors`` (the blind count's ideal-fit rule, fixtures/blind.py ``ideal_fit_undecidable``)
    on exact data of the diagnosis' own FE model with an elbow spring (so the true candidate fits them
    exactly): the truth's held-out error is ~0, the same spring at the same place again equals it, and
    a tip mass, which cannot bend the pose trend of an elbow spring, is worse by far more than the noise
    margin at 0.5 % scatter; ``none`` is the nominal model's error, unfitted."""
    import numpy as np
    from conftest import REPO

    from flexmodal.compare.diagnosis import heldout_errors
    from flexmodal.models.effects import apply_effect
    from flexmodal.models.frame import frame_modes
    from flexmodal.models.rig import load_rig

    rig = load_rig(REPO / "examples" / "rigs" / "seed003_two_link.toml")
    real = apply_effect(rig, "joint_stiffness", "elbow", {"k_Nm_per_rad": 3000.0})
    records = [{"config": f"theta{th}", "mode": k + 1, "freq_hz": f, "pose.theta_deg": th}
               for th in (0, 30, 60, 90, 120, 150)
               for k, f in enumerate(frame_modes(real, {"theta_deg": th}, 2).freq_hz)]
    table = ModalTable.from_records(records, "<exact>")
    names = [("joint_stiffness", "elbow"), ("joint_stiffness", "elbow"), ("tip_mass", "tip"), ("none", "")]
    (truth, again, tip, nominal), margin = heldout_errors(rig, table, names, 0.005)
    assert truth < 2e-3 and abs(again - truth) < 1e-9
    assert 0.001 < margin < 0.01 and tip - truth > 3 * margin
    poses = (0, 30, 60, 90, 120, 150)
    base = np.concatenate([frame_modes(rig, {"theta_deg": th}, 2).freq_hz for th in poses])
    exact = np.concatenate([table.freq_hz(f"theta{th}") for th in poses])
    assert nominal == pytest.approx(np.sqrt(np.mean((base / exact - 1) ** 2)), rel=1e-3)   # no fit


def test_a_gap_within_the_upper_limit_of_the_held_out_noise_is_none():
    """Blind draw 736 case 14 (no effect; axial rig, 3 poses x 2 modes, no repeats: fallback scatter
    0.5 %), replayed from the generator's state before it: the best single predicted the 6 held-out
    frequencies to 0.144 % and, taken as the noise, made the 0.384 % gap a link stiffness.  An RMS of
    6 values bounds the noise only up to its 95 % chi-square limit, 0.275 %: the verdict is ``none``."""
    rng = np.random.default_rng()
    rng.bit_generator.state = {"bit_generator": "PCG64", "has_uint32": 1, "uinteger": 310024668, "state": {
        "state": 66786972595587313164633063584206518220, "inc": 77213257748787901358264856692433969155}}
    case = make_case(rng, CATEGORIES[14 % len(CATEGORIES)], KINDS[14 % len(KINDS)])
    assert (case.category, case.kind, case.n_configs, case.n_modes) == ("none", "axial", 3, 2)
    d = diagnose(case.rig, case.table)
    v = d.verdict
    assert v.effect == "none" and v.grade == "explained"
    n_held = case.n_configs * case.n_modes                   # each configuration held out once: N = 6
    best_h = min(e.heldout_rms_rel_error for e in d.ranking)
    assert 0.0013 < best_h < 0.0016                          # the best single's ~0.144 % of the miss
    upper = best_h * np.sqrt(n_held / chi2.ppf(0.05, n_held))  # one-sided 95 % limit, closed form
    assert chi2.ppf(0.05, n_held) == pytest.approx(1.635, abs=1e-3)   # tabulated chi2_0.05(6)
    assert f"measurement scatter ({percent(upper)})" in v.summary
