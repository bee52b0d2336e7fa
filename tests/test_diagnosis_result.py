"""The typed diagnosis result (compare/result.py): diagnosis.json unchanged, strict, documented, frozen.

``tests/data/diagnosis/*.json`` are diagnosis.json files written at commit 2432c3a, while the result
was still a dict serialised by ``compare.diagnosis.to_json``: the demo's identified modes, seed 003's
Table 3 with ``--holdout theta30,theta90,theta150`` (nulls where nothing was held out), and two blind
cases of ``fixtures/blind.py`` (seed 0: case 1, ``none``; case 3, a pair with an alternative).
At that commit the typed ``diagnose`` wrote the same bytes for these and for the other blind cases
0-15 (compared once; the numbers belong to the method, which changes, so they are not re-run here).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import pickle
import re
import typing

import numpy as np
import pytest
from conftest import REPO

from flexmodal.app import main
from flexmodal.compare.diagnosis import diagnose
from flexmodal.compare.errors import CompareError
from flexmodal.compare.result import (
    Alternative,
    CandidateScore,
    Diagnosis,
    Predictions,
    Verdict,
    Where,
    _Record,
)
from flexmodal.contract.table import ModalTable
from flexmodal.fixtures.blind import CATEGORIES, KINDS, make_case
from flexmodal.models.effects import apply_effect
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig

GOLDEN = sorted((REPO / "tests" / "data" / "diagnosis").glob("*.json"))


def _strict(text: str) -> dict:
    def refuse(constant: str):
        raise AssertionError(f"non-standard JSON constant {constant}")
    return json.loads(text, parse_constant=refuse)


def _record_of(tp) -> type | None:
    """The record class a field holds (itself, in a tuple, or optional), else None."""
    for t in (tp, *typing.get_args(tp)):
        for u in (t, *typing.get_args(t)):
            if isinstance(u, type) and issubclass(u, _Record):
                return u
    return None


def schema_paths(cls: type = Diagnosis, prefix: str = "", required: bool = True) -> dict[str, bool]:
    """Every JSON key path of the records ({path: in the minimal contract}), e.g. ``ranking[].score``."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        suffix = f.metadata.get("suffix")
        path = prefix + (f"<name>{suffix}" if suffix else f.name)
        needed = required and f.default is not None and not suffix
        out[path] = needed
        sub = _record_of(hints[f.name])
        if sub is not None:
            many = typing.get_origin(hints[f.name]) is tuple or any(
                typing.get_origin(a) is tuple for a in typing.get_args(hints[f.name]))
            out.update(schema_paths(sub, path + ("[]." if many else "."), needed))
    return out


def json_paths(doc: dict, cls: type = Diagnosis, prefix: str = "") -> set[str]:
    """The key paths of a parsed diagnosis.json, walking into the objects the records describe; a key
    no record has is returned as it is (so that it fails the comparison)."""
    hints = typing.get_type_hints(cls)
    suffixes = {f.metadata["suffix"] for f in dataclasses.fields(cls) if "suffix" in f.metadata}
    out = set()
    for key, value in doc.items():
        suffix = next((s for s in suffixes if key.endswith(s)), None)
        path = prefix + (f"<name>{suffix}" if suffix else key)
        out.add(path)
        sub = _record_of(hints[key]) if key in hints else None
        if sub is not None and isinstance(value, dict):
            out |= json_paths(value, sub, path + ".")
        elif sub is not None and isinstance(value, list):
            for item in value:
                out |= json_paths(item, sub, path + "[].")
    return out


def formats_section() -> tuple[str, dict]:
    """docs/formats.md's "Diagnosis JSON" section and its parsed diagnosis.json example."""
    text = (REPO / "docs" / "formats.md").read_text()
    section = text[text.index("## Diagnosis JSON"):]
    section = section[:section.index("\n## ", 5)]
    start = section.index("```json") + len("```json")
    return section, json.loads(section[start:section.index("```", start)])


def documented_paths() -> tuple[set[str], set[str]]:
    """(the key paths of docs/formats.md's diagnosis.json example, every key path of its key table)."""
    section, example = formats_section()
    rows = section[section.index("| key | value |"):].split("\n\n")[0].splitlines()[2:]
    table = {key for row in rows for key in re.findall(r"`([^`]+)`", row.split(" | ")[0])}
    return json_paths(example), table


@pytest.mark.parametrize("path", GOLDEN, ids=[p.stem for p in GOLDEN])
def test_diagnosis_json_of_the_dict_era_round_trips_byte_for_byte(path):
    text = path.read_text()
    d = Diagnosis.from_json(text)
    assert d.to_json() == text
    assert Diagnosis.from_json(d.to_json()) == d
    assert d.to_dict() == _strict(text)


def test_the_records_and_the_documented_keys_are_the_same():
    """docs/formats.md's example holds exactly the contract keys (the required fields); its key table
    lists exactly the keys of the records; the files of the dict era use only those keys."""
    example, table = documented_paths()
    schema = schema_paths()
    assert example == {p for p, needed in schema.items() if needed}
    leaves = {p for p in schema if not any(q.startswith((p + ".", p + "[].")) for q in schema)}
    assert table == leaves
    for path in GOLDEN:
        assert json_paths(_strict(path.read_text())) <= set(schema), path.name


@functools.cache
def blind_diagnosis(i: int) -> Diagnosis:
    """Case ``i`` of the blind check's default subset (``fixtures/blind.py``, seed 0), diagnosed now."""
    rng = np.random.default_rng(0)
    cases = [make_case(rng, CATEGORIES[k % len(CATEGORIES)], KINDS[k % len(KINDS)]) for k in range(i + 1)]
    return diagnose(cases[i].rig, cases[i].table)


@pytest.fixture(scope="module")
def live() -> list[Diagnosis]:
    """Blind cases 0 (a single effect) and 1 (none) of the default subset."""
    return [blind_diagnosis(0), blind_diagnosis(1)]


def check_tree(d: Diagnosis) -> None:
    """``d`` is the typed tree: strict JSON with only documented keys, no working entries, round trip."""
    assert isinstance(d, Diagnosis) and isinstance(d.verdict, Verdict)
    assert all(isinstance(e, CandidateScore) for e in d.ranking)
    text = d.to_json()
    assert json_paths(_strict(text)) <= set(schema_paths())
    assert not any(k.startswith("_") for k in re.findall(r'"(\w+)":', text))
    assert Diagnosis.from_json(text) == d


def test_diagnose_returns_the_tree_written_as_strict_documented_json(live):
    for d in live:
        check_tree(d)
    assert [d.verdict.effect == "none" for d in live] == [False, True]
    assert live[1].verdict.alternatives == () and live[1].where.region == ""
    assert live[1].per_mode_after() is None
    for d in live:   # the per-mode RMS of the nominal model's frequencies is the baseline's, computed apart
        per_mode = d.predictions.rms_rel_error_per_mode(d.predictions.baseline_hz)
        assert per_mode == pytest.approx(d.baseline.per_mode, rel=1e-12, abs=1e-15)


@pytest.mark.slow
@pytest.mark.parametrize("i", range(2, 8))
def test_every_case_of_the_default_blind_subset_gives_the_strict_documented_tree(i):
    check_tree(blind_diagnosis(i))


def test_records_are_frozen(live):
    d = live[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.verdict.effect = "tip_mass"                                   # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.ranking[0].score = 0.0                                        # type: ignore[misc]
    with pytest.raises((AttributeError, TypeError)):
        d.verdict.note = "x"                                            # type: ignore[attr-defined]
    with pytest.raises(TypeError):
        d.ranking[0].params["k_Nm_per_rad"] = 1.0                       # type: ignore[index]
    with pytest.raises(TypeError):
        d.predictions.measured_hz[d.configs[0]][0] = 1.0               # type: ignore[index]
    assert isinstance(d.ranking, tuple) and isinstance(d.where.modes, tuple)
    copy = pickle.loads(pickle.dumps(d))                                # immutable all the way: hashable
    assert copy == d and hash(copy) == hash(d) and copy is not d


def test_numbers_are_python_and_finite_or_null_and_per_config_keys_round_trip():
    nan = float("nan")
    v = Verdict(effect="joint_stiffness_pose", location="elbow", heldout_rms_rel_error_before=np.float64(0.2),
                heldout_rms_rel_error_after=0.004, explained=np.bool_(True),
                params={"k_Nm_per_rad": np.float64(7500.0), "log_slope_per_rad": np.inf},
                alternatives=[Alternative(effect="joint_stiffness", location="elbow",
                                          params={"k_Nm_per_rad": 7400.0}, heldout_rms_rel_error=0.005)],
                per_config={"k_Nm_per_rad": {"theta0": 7500.0, "theta90": nan}})
    assert type(v.heldout_rms_rel_error_before) is float and v.explained is True
    assert v.params == {"k_Nm_per_rad": 7500.0, "log_slope_per_rad": None}
    p = Predictions(measured_hz={"theta0": np.array([10.0, 20.0])}, baseline_hz={"theta0": [11.0, nan]})
    assert p.measured_hz["theta0"] == (10.0, 20.0) and p.baseline_hz["theta0"] == (11.0, None)
    assert Where(modes=[2], configs=["a"], region="") == Where(modes=(2,), configs=("a",), region="")
    doc = _strict(v.to_json())
    assert doc["k_Nm_per_rad_per_config"] == {"theta0": 7500.0, "theta90": None}
    assert doc["params"]["log_slope_per_rad"] is None and "remaining" not in doc
    assert list(doc["alternatives"][0]) == ["effect", "location", "params", "heldout_rms_rel_error"]
    assert Verdict.from_json(v.to_json()) == v
    assert Predictions.from_json(p.to_json()) == p


def test_a_document_that_is_not_a_diagnosis_is_named_in_one_line(tmp_path, capsys):
    good = _strict((REPO / "tests" / "data" / "diagnosis" / "demo.json").read_text())
    with pytest.raises(CompareError, match=r"^no 'verdict\.explained'$"):
        Diagnosis.from_dict({**good, "verdict": {k: v for k, v in good["verdict"].items()
                                                 if k != "explained"}})
    with pytest.raises(CompareError, match=r"^baseline\.rms_rel_error: expected a number \(got str '12 %'\)"):
        Diagnosis.from_dict({**good, "baseline": {**good["baseline"], "rms_rel_error": "12 %"}})
    with pytest.raises(CompareError,
                       match=r"^ranking\[0\]\.n_params: expected an integer from 0 to 1000000 \(got bool"):
        Diagnosis.from_dict({**good, "ranking": [{**good["ranking"][0], "n_params": True}]})
    with pytest.raises(CompareError, match=r"^where\.modes: expected a list \(got int\)$"):
        Diagnosis.from_dict({**good, "where": {**good["where"], "modes": 2}})
    minimal = Diagnosis.from_dict(formats_section()[1])              # the contract keys alone
    assert minimal.predictions is None and minimal.verdict.summary is None
    assert minimal.to_dict() == formats_section()[1]
    bad = tmp_path / "d.json"
    bad.write_text(json.dumps({"baseline": good["baseline"], "where": good["where"], "ranking": []}))
    assert main(["report", "--diagnosis", str(bad), "--out", str(tmp_path / "r.html")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(f"{bad}: no 'verdict'")
    bad.write_text("[1, 2]")
    assert main(["report", "--diagnosis", str(bad), "--out", str(tmp_path / "r.html")]) == 2
    assert capsys.readouterr().err.strip().endswith(f"{bad}: expected a JSON object (got list)")


def test_the_typed_tree_reaches_every_consumer(live, tmp_path):
    """api.write_diagnosis writes the tree's JSON and renders its page from the typed fields; the file
    (parsed, or by path) reads back equal; the gap plot's bars are the typed per-mode errors."""
    from flexmodal import api
    from flexmodal.reports import plots

    d = live[0]
    pj, ph = api.write_diagnosis(d, tmp_path)
    assert pj.read_text() == d.to_json()
    html = ph.read_text()
    assert f"{d.verdict.effect} at {d.verdict.location}" in html and d.verdict.summary.split(";")[0] in html
    assert api._diagnosis(json.loads(pj.read_text())) == d and api.read_diagnosis(pj) == d
    modes, before, after = plots.gap_per_mode(d)
    assert before.tolist() == [d.per_mode_before()[m] for m in modes]   # the nominal model, like for like
    # every configuration is held out once: the nominal model's per-mode RMS over them is the baseline's
    np.testing.assert_allclose(before, [d.baseline.per_mode[m] for m in modes], rtol=1e-9)
    assert after.tolist() == [d.per_mode_after()[m] for m in modes]


def test_a_pose_law_verdict_lists_its_stiffness_per_configuration(rigs_dir):
    """A joint stiffness k(q) = k0 exp(a1 q + a2 q^2) hidden at seed 003's elbow: the verdict's
    ``per_config`` (JSON ``k_Nm_per_rad_per_config``) is that law at each pose, from the fitted
    parameters, and close to the hidden one (the fit's in-sample RMS on these noise-free data is 0.2 %:
    the diagnosis' reduced model is not the full frame model that made them)."""
    rig = load_rig(rigs_dir / "seed003_two_link.toml")
    law = {"k_Nm_per_rad": 3000.0, "log_slope_per_rad": 0.5, "log_curv_per_rad2": 0.0}
    recs = []
    for th in (0, 30, 60, 90, 120, 150):
        pose = {"theta_deg": float(th)}
        f = frame_modes(apply_effect(rig, "joint_stiffness_pose", "elbow", law, pose=pose), pose, 3).freq_hz
        recs += [{"config": f"theta{th}", "mode": m + 1, "freq_hz": f[m], "pose.theta_deg": float(th)}
                 for m in range(3)]
    d = diagnose(rig, ModalTable.from_records(recs, "<pose law>"), effects="joint_stiffness_pose")
    v = d.verdict
    assert (v.effect, v.location) == ("joint_stiffness_pose", "elbow")
    fitted = next(e for e in d.ranking if (e.effect, e.location) == (v.effect, v.location)).params
    k0, a1, a2 = (fitted[n] for n in law)
    per_config = v.per_config["k_Nm_per_rad"]
    assert list(per_config) == list(d.configs) and set(d.configs) == {r["config"] for r in recs}
    for config, k in per_config.items():
        q = math.radians(float(config[len("theta"):]))
        assert k == pytest.approx(k0 * math.exp(a1 * q + a2 * q * q), rel=1e-12)
        assert k == pytest.approx(3000.0 * math.exp(0.5 * q), rel=0.03)   # measured: within 2.4 %
    assert _strict(d.to_json())["verdict"]["k_Nm_per_rad_per_config"] == per_config


def test_the_verdicts_entry_is_the_ranking_entry_at_its_place(live):
    """``verdict_score``: the ranking entry at ``verdict.ranked`` (1 = first), found by place, not by
    equal parameters (two entries of one effect and place, a point mass and a distributed one, may share
    them); None for a ``none`` verdict and for a place below the entries kept."""
    d, none = live
    assert none.verdict.effect == "none" and none.verdict.ranked is None and none.verdict_score() is None
    v = d.verdict
    entry = d.verdict_score()
    assert entry is d.ranking[v.ranked - 1] and (entry.effect, entry.location) == (v.effect, v.location)
    twin = dataclasses.replace(entry, n_params=entry.n_params + 1)   # same effect, place and parameters
    moved = dataclasses.replace(d, ranking=(twin, *d.ranking),
                                verdict=dataclasses.replace(v, ranked=v.ranked + 1))
    assert moved.verdict_score() is entry
    below = dataclasses.replace(d, verdict=dataclasses.replace(v, ranked=len(d.ranking) + 1))
    assert below.verdict_score() is None
