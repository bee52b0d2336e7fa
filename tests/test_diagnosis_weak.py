"""A gap within the noise is not ``none`` when a single predicts unseen poses better than no effect
beyond noise and beyond the beam theory's known error (compare/diagnosis.py ``_beating_nominal``):
blind draw 1052 case 9 (a weak effect found) and 316 case 14 (no effect, stays ``none``), stored; and
when a single does overrule the gap test on a case without an effect, the held-out test says ``none``."""

from __future__ import annotations

import inspect
import json
import re
from pathlib import Path

import pytest

import flexmodal.compare.diagnosis as diagnosis
from flexmodal.compare.diagnosis import diagnose
from flexmodal.contract.table import ModalTable
from flexmodal.models.rig import parse_rig

CASE = Path(__file__).parent / "data" / "blind_cases" / "draw1052_case09"


@pytest.mark.slow   # ~4 s CPU: above the ~3 s of a default test
def test_a_weak_effect_that_predicts_held_out_poses_is_not_none():
    """Blind draw 1052 #9 (axial-sensor arm, a weak elbow stiffness, 10 configurations x 3 modes with
    shapes, the independent truth model's frequencies with 0.87 % scatter): the baseline gap, 1.57 %,
    is within twice the repeat scatter (0.85 %), so the gap test alone declared ``none`` -- while the
    elbow stiffness predicted the held-out poses to 0.87 %, beyond the noise margin of the nominal
    model's 1.57 %, and an ideal fit on the noise-free data decides it (0.107 % against 0.979 %).
    Asserted: the verdict is the hidden effect at its joint (top-1), not ``none``."""
    doc = json.loads(CASE.with_suffix(".json").read_text())
    truth = (doc["truth"]["effect"], doc["truth"]["location"])
    assert truth == ("joint_stiffness", "elbow")
    d = diagnose(parse_rig(doc["rig"], "<draw 1052 case 9>"), ModalTable.read_csv(CASE.with_suffix(".csv")))
    assert (d.verdict.effect, d.verdict.location) == truth, d.verdict.summary


NONE_CASE = Path(__file__).parent / "data" / "blind_cases" / "draw316_case14"


def test_a_single_that_only_absorbs_the_beam_theory_error_leaves_none():
    """Blind draw 316 #14 (axial-sensor arm, no effect hidden, 9 configurations x 4 modes, 0.25 % scatter
    of repeated configurations): the baseline gap, 0.68 %, is mostly the model's known Euler-Bernoulli
    error (0.54 %), and a link-1 mass (scale ~1.03) absorbs it, held out at 0.34 %: beyond the noise
    margin of the nominal model, not beyond the beam theory's error.  Such a single is no evidence of
    an effect, so the gap test stands.  Asserted: ``none`` (with the rule above counting noise only,
    the full search gave ``link_mass at link1``)."""
    doc = json.loads(NONE_CASE.with_suffix(".json").read_text())
    assert doc["truth"]["effect"] == "none"
    rig = parse_rig(doc["rig"], "<draw 316 case 14>")
    d = diagnose(rig, ModalTable.read_csv(NONE_CASE.with_suffix(".csv")))
    assert d.verdict.effect == "none", d.verdict.summary


FIRED_CASE = Path(__file__).parent / "data" / "blind_cases" / "axialnone515151_case48"


@pytest.mark.slow   # 4.9 s alone, 10.7 s under xdist at load 4.5 (REVIEW41): above a default test's ~3 s
def test_a_gate_that_fires_on_no_effect_still_leaves_none(monkeypatch):
    """The false-positive side of the rule: when a single does overrule the gap test on data without an
    effect, the full search and the held-out ``none`` test must still say ``none``.  The rule as it
    stands fired on none of 420 fresh true-``none`` cases (benchmarks/none_gate.py: ``make_case(rng,
    "none", kind)``, the five rigs in turn, 120 of seed 880001 and 300 of seed 880002; re-run by
    ``test_the_gate_fires_on_no_fresh_case_without_an_effect``), so the
    case is one where its first form, the noise margin alone (main 62751cc; ``form`` left 0), fires:
    review 40's axial ``none`` case 48 of seed 515151 (8 configurations x 4 modes with shapes, 0.25 %
    repeat scatter; a link-1 mass held out at 0.27 % against the nominal model's 0.335 %, beyond the
    noise margin but within the beam theory's 0.368 %).  Asserted: the gate fired, the full search ran
    (pairs fitted), and the verdict is ``none`` by the held-out test."""
    doc = json.loads(FIRED_CASE.with_suffix(".json").read_text())
    assert doc["truth"]["effect"] == "none"
    beating, fired = diagnosis._beating_nominal, []

    def noise_only(*args, **kwargs):
        call = inspect.signature(beating).bind(*args, **kwargs)
        if not call.arguments.get("form"):                   # the alternatives of a ``none`` verdict
            return beating(*args, **kwargs)
        call.arguments["form"] = 0.0                         # the gate, without the beam term
        fired.append(beating(*call.args, **call.kwargs))
        return fired[-1]

    monkeypatch.setattr(diagnosis, "_beating_nominal", noise_only)
    rig = parse_rig(doc["rig"], "<seed 515151 axial none case 48>")
    d = diagnosis.diagnose(rig, ModalTable.read_csv(FIRED_CASE.with_suffix(".csv")))
    assert [(e["effect"], e["location"]) for e in fired[0]][:1] == [("link_mass", "link1")]
    assert any("+" in r.effect for r in d.ranking)                    # the full search: pairs ranked
    assert d.verdict.effect == "none", d.verdict.summary
    assert d.verdict.summary.startswith("no candidate beats the nominal model on held-out configurations")


@pytest.mark.slow
@pytest.mark.parametrize("k", range(2))   # 120 and 300 cases: ~5 and ~12 min at load 5 (~2.4 s a case)
def test_the_gate_fires_on_no_fresh_case_without_an_effect(k):
    """The count ``test_a_gate_that_fires_on_no_effect_still_leaves_none`` quotes, re-run
    (benchmarks/none_gate.py ``RUNS``): on fresh cases without an effect the gate never overrules the
    gap test; and the ``none`` verdicts on those cases are those docs/diagnosis.md's Limits quote."""
    import importlib.util

    from conftest import REPO

    spec = importlib.util.spec_from_file_location("none_gate", REPO / "benchmarks" / "none_gate.py")
    gate = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gate)
    quoted = " ".join(test_a_gate_that_fires_on_no_effect_still_leaves_none.__doc__.split())
    assert f"fired on none of {sum(n for _, n in gate.RUNS)} fresh" in quoted
    assert " and ".join(f"{n} of seed {seed}" for seed, n in gate.RUNS) in quoted
    seed, cases = gate.RUNS[k]
    count = gate.gate_count(seed, cases)
    assert (count.cases, count.fired) == (cases, ()), gate.line(seed, count)
    limits = " ".join((REPO / "docs" / "diagnosis.md").read_text().split())
    quoted = re.search(r"the verdict is `none` on (\d+) and (\d+) of them", limits).groups()
    assert count.none == int(quoted[k]), gate.line(seed, count)
