"""`flexmodal diagnose`: contract output files and one-line errors (exit 2) on bad inputs."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from flexmodal.app import main

RIG = "examples/rigs/seed003_two_link.toml"


@pytest.fixture()
def measured(tmp_path, data_dir):
    t3 = pd.read_csv(data_dir / "seeds" / "seed003_table3_experimental.csv")
    rows = [{"config": f"theta{int(r.theta_deg)}", "mode": m, "freq_hz": r[f"f{m}_hz"],
             "pose.theta_deg": r.theta_deg} for _, r in t3.iterrows() for m in (1, 2)]
    return tmp_path, pd.DataFrame(rows)


def _run(tmp_path, df, *extra):
    path = tmp_path / "modes.csv"
    df.to_csv(path, index=False)
    from conftest import REPO
    return main(["--quiet", "diagnose", "--rig", str(REPO / RIG), "--measured", str(path),
                 "--out", str(tmp_path / "out"), *extra])


def test_writes_contract_json_and_html(measured, capsys):
    tmp_path, df = measured
    assert _run(tmp_path, df, "--effects", "joint_stiffness,joint_mass,tip_mass") == 0
    res = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert set(res) >= {"baseline", "where", "ranking", "verdict"}
    assert set(res["baseline"]) >= {"rms_rel_error", "max_rel_error", "per_mode", "per_config"}
    assert set(res["where"]) >= {"modes", "configs", "region"}
    assert set(res["verdict"]) >= {"effect", "location", "heldout_rms_rel_error_before",
                                   "heldout_rms_rel_error_after", "explained"}
    for entry in res["ranking"]:
        assert set(entry) >= {"effect", "location", "params", "fit_rms_rel_error", "heldout_rms_rel_error",
                              "n_params", "score"}
    assert [e["score"] for e in res["ranking"]] == sorted(e["score"] for e in res["ranking"])
    assert "joint_mass+joint_stiffness" in {e["effect"] for e in res["ranking"]}   # alphabetical
    page = (tmp_path / "out" / "diagnosis.html").read_text()
    assert page.startswith("<!DOCTYPE html>")       # the report's diagnosis section alone (one renderer)
    v, pred = res["verdict"], res["predictions"]
    assert f"{v['effect']} at {v['location']}" in page and '<h2 id="diagnosis">' in page
    assert v["params"] and v["param_intervals"]
    for name, value in v["params"].items():   # the verdict's parameters with their 95 % intervals
        lo, hi = v["param_intervals"][name]
        unit = " N m/rad" if name.endswith("_Nm_per_rad") else " kg" if name.endswith("_kg") else ""
        assert f"{name} = {value:.4g}{unit} (95 % interval {lo:.4g} .. {hi:.4g})" in page
    first = next(iter(pred["measured_hz"]))
    assert "Natural frequencies [Hz]" in page and page.count("data:image/png;base64,") == 1   # the gap plot
    for key in ("measured_hz", "baseline_hz", "best_heldout_hz"):
        assert f'<td class="num">{pred[key][first][0]:.2f}</td>' in page
    assert "diagnosis.json" in capsys.readouterr().out


@pytest.mark.parametrize("mutate, message", [
    (lambda df: df.rename(columns={"pose.theta_deg": "pose.phi_deg"}), "pose columns do not match"),
    (lambda df: df[df.config.isin(["theta0", "theta30"])], "at least 3"),
    (lambda df: df.drop(index=3), "missing mode 2"),
])
def test_bad_inputs_exit_2_with_one_line(measured, capsys, mutate, message):
    tmp_path, df = measured
    assert _run(tmp_path, mutate(df)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def test_bad_options_exit_2(measured, capsys):
    tmp_path, df = measured
    assert _run(tmp_path, df, "--effects", "gearbox") == 2
    assert "gearbox" in capsys.readouterr().err
    assert _run(tmp_path, df, "--holdout", "theta999") == 2
    assert "theta999" in capsys.readouterr().err


def test_no_applicable_effect_leaves_the_gap_unexplained(measured):
    tmp_path, df = measured
    assert _run(tmp_path, df, "--effects", "end_restraint") == 0          # seed 003's arm has no member
    v = json.loads((tmp_path / "out" / "diagnosis.json").read_text())["verdict"]
    assert v["effect"] == "none" and v["explained"] is False
    assert v["heldout_rms_rel_error_after"] == v["heldout_rms_rel_error_before"] > 0.4


def test_selftest_runs_blind_cases_of_the_independent_truth(capsys):
    assert main(["--quiet", "diagnose", "--selftest", "1"]) == 0
    out = capsys.readouterr().out
    assert "cases: 1 (1 library effect," in out and "top-1 effect accuracy:" in out
    assert "nan" not in out and "'none' for no-effect cases: no cases" in out     # was "nan %"
    assert main(["--quiet", "diagnose", "--selftest", "0"]) == 2
    assert "--selftest" in capsys.readouterr().err
