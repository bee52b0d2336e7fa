"""The public Python API (flexmodal.api, re-exported lazily by flexmodal): the worked example of
docs/python-api.md runs as written and gets the simulated truth back; the CLI prints what the API
returns; ``import flexmodal`` stays cheap."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO
from matplotlib.figure import Figure

import flexmodal
from flexmodal import api
from flexmodal.app import main
from flexmodal.fixtures.rig_sim import DEMO_RIG, HiddenEffect, simulate
from flexmodal.models.rig import load_rig

DOC = REPO / "docs" / "python-api.md"


def _doc_code() -> str:
    return "\n".join(re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S))


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The namespace left by the doc's example, run in a fresh directory."""
    import os

    where = tmp_path_factory.mktemp("python-api")
    cwd = os.getcwd()
    os.chdir(where)
    try:
        namespace: dict = {"__name__": "__doc_example__"}
        exec(compile(_doc_code(), str(DOC), "exec"), namespace)
    finally:
        os.chdir(cwd)
    namespace["dir"] = where
    return namespace


def test_the_first_cell_runs_again_on_the_file_it_made(example, monkeypatch):
    """A notebook is run more than once: the cell that stores the simulated runs raised "runs.h5: run
    'theta0' already exists" on the second run; now it keeps the stored runs (and simulates nothing)."""
    first = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)[0]
    monkeypatch.chdir(example["dir"])
    before = api.list_runs("runs.h5")
    exec(compile(first, str(DOC), "exec"), {"__name__": "__doc_example__"})
    assert api.list_runs("runs.h5") == before == ["theta0", "theta30", "theta60", "theta90", "theta120"]


def test_the_worked_example_finds_the_simulated_modes(example):
    """Known answer: the simulated arm's natural frequencies (with the hidden elbow spring)."""
    rig, measured = example["rig"], example["measured"]
    ids = ["theta0", "theta30", "theta60", "theta90", "theta120"]   # as the doc's comment says
    assert api.list_runs(example["dir"] / "runs.h5") == ids
    elbow = example["elbow"]
    for config, pose in example["poses"].items():
        truth = simulate(rig, pose, excitation="random", duration_s=1.0, effects=elbow).natural_freq_hz
        found = measured.freq_hz(config)
        assert found.size == 3, config
        np.testing.assert_allclose(found, truth[:3], rtol=0.01, err_msg=config)
        zeta = measured.rows(config)["damping_ratio"].to_numpy(float)
        np.testing.assert_allclose(zeta, 0.01, rtol=0.3, err_msg=config)   # the simulator's 1 %


def test_the_worked_example_compares_and_diagnoses_the_hidden_elbow(example):
    comparison, predicted = example["comparison"], example["predicted"]
    assert sorted(predicted.configs) == sorted(example["poses"])
    pairing = comparison.pairings[0]
    assert len(pairing.pairs) == 15 and {p.method for p in pairing.pairs} == {"mac"}
    assert min(p.mac for p in pairing.pairs) > 0.9
    verdict = example["diagnosis"].verdict
    assert "joint_stiffness" in verdict.effect and verdict.location.startswith("elbow")
    assert verdict.heldout_rms_rel_error_after < 0.1 * verdict.heldout_rms_rel_error_before
    for name, png in (("fig_frf", "frf"), ("fig_stab", "stabilisation"), ("fig_cmp", "comparison"),
                      ("fig_shapes", "shapes"), ("fig_gap", "gap")):
        assert isinstance(example[name], Figure) and (example["dir"] / f"{png}.png").stat().st_size > 10_000
    assert (example["dir"] / "diagnosis" / "diagnosis.json").is_file()
    html = (example["dir"] / example["out"]).read_text(encoding="utf-8")
    assert "runs.h5::theta120" in html and "joint_stiffness" in html


def test_cli_prints_exactly_what_the_api_returns(example, tmp_path, capsys):
    where = example["dir"]
    example["measured"].to_csv(tmp_path / "modes.csv")
    example["predicted"].to_csv(tmp_path / "fe.csv")
    assert main(["compare", str(tmp_path / "modes.csv"), str(tmp_path / "fe.csv"), "--format", "csv"]) == 0
    direct = api.format_comparison(api.compare_modes(tmp_path / "modes.csv", tmp_path / "fe.csv"), "csv")
    assert capsys.readouterr().out == direct
    out = tmp_path / "cli.csv"
    assert main(["--quiet", "identify", str(where / "runs.h5"), "--fmin", "5", "--fmax", "450",
                 "--max-order", "20", "--out", str(out)]) == 0
    capsys.readouterr()
    cli = api.read_table(out).frame
    mine = api.read_table(tmp_path / "modes.csv").frame   # the same CSV round trip
    np.testing.assert_array_equal(cli["freq_hz"].to_numpy(), mine["freq_hz"].to_numpy())


def test_inputs_may_be_paths_or_objects(tmp_path):
    rig = load_rig(DEMO_RIG)
    poses = tmp_path / "poses.csv"
    poses.write_text("config,pose.theta_deg\na,0\nb,90\n")
    by_path = api.predict(DEMO_RIG, poses, "fe", 2)
    by_object = api.predict(rig, {"a": {"theta_deg": 0.0}, "b": {"theta_deg": 90.0}}, "fe", 2)
    assert by_path.frame.equals(by_object.frame)
    by_table = api.predict(rig, by_path, "fe", 2)   # configurations and poses of a modal table
    np.testing.assert_array_equal(by_table.frame["freq_hz"], by_path.frame["freq_hz"])


def test_one_run_files_need_no_run_id_and_errors_are_the_packages(tmp_path):
    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.store import RunWriter
    from flexmodal.models.errors import ModelError

    test = simulate(load_rig(DEMO_RIG), {"theta_deg": 30.0}, excitation="random", duration_s=8.0,
                    effects=[HiddenEffect("joint_stiffness", "elbow", {"k_Nm_per_rad": 8000.0})])
    for run_id in ("r1", "r2"):
        with RunWriter(tmp_path / f"{run_id}.h5", run_id, sample_rate_hz=test.sample_rate_hz,
                       channels=test.channels, excitation="random", pose={"theta_deg": 30.0}) as w:
            w.append(test.samples)
    assert api.read_run(tmp_path / "r1.h5").run_id == "r1"
    with RunWriter(tmp_path / "r1.h5", "r2", sample_rate_hz=test.sample_rate_hz, channels=test.channels,
                   excitation="random", pose={}) as w:
        w.append(test.samples)
    with pytest.raises(DaqError, match="holds 2 runs"):
        api.read_run(tmp_path / "r1.h5")
    with pytest.raises(ModelError, match="no configurations"):
        api.predict(DEMO_RIG, {}, "fe")
    with pytest.raises(DaqError, match="--duration -1.0: must be a number of seconds > 0"):
        api.acquire(REPO / "examples" / "sessions" / "serial-sim.toml", tmp_path / "a.h5", duration_s=-1.0)
    assert not (tmp_path / "a.h5").exists()   # refused before any device or file is opened
    frf = api.compute_frf(tmp_path / "r2.h5", nfft=4096)
    ident = api.identify(frf, fmin=5.0, fmax=450.0, max_order=20, config="c30", pose={"theta_deg": 30.0})
    assert ident.table.configs == ["c30"] and ident.table.pose("c30") == {"theta_deg": 30.0}
    np.testing.assert_allclose(ident.table.freq_hz("c30"), test.natural_freq_hz[:3], rtol=0.01)


def test_import_flexmodal_is_cheap_and_names_resolve_lazily():
    code = ("import sys, flexmodal; heavy = [m for m in ('numpy', 'h5py', 'matplotlib', 'pandas') "
            "if m in sys.modules]; print(heavy); flexmodal.read_table; "
            "print('flexmodal.api' in sys.modules, 'numpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                         check=True).stdout.split("\n")
    assert out[0] == "[]" and out[1] == "True False"   # the API module itself imports nothing heavy
    assert set(flexmodal.__all__) == set(api.__all__)
    subpackages = {p.name for p in REPO.iterdir() if (p / "__init__.py").is_file()} | {"app", "api"}
    assert subpackages >= {"daq", "modal", "compare"} and not subpackages & set(api.__all__)
    assert all(getattr(flexmodal, name) is getattr(api, name) for name in api.__all__)
    assert set(api.__all__) <= set(dir(flexmodal))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        flexmodal.nope  # noqa: B018
