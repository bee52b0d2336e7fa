"""predict() and `flexmodal predict`: one modal table for every model; bad rigs exit 2 with one line."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from conftest import RIGS

from flexmodal.app import main
from flexmodal.contract.table import ModalTable
from flexmodal.models.errors import ModelError
from flexmodal.models.predict import load_external, predict
from flexmodal.models.registry import registered_models
from flexmodal.models.rig import load_rig

SEED003 = (RIGS / "seed003_two_link.toml").read_text()  # a copy is edited into bad rigs below


def write(tmp_path, text: str, name: str = "rig.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.fixture
def poses_csv(tmp_path):
    return write(tmp_path, "config,pose.theta_deg\ntheta0,0\ntheta90,90\n", "poses.csv")


def test_every_model_agrees_on_the_straight_arm(rigs_dir):
    rig = load_rig(rigs_dir / "seed003_two_link.toml")
    tables = {m: predict(rig, {"theta0": {"theta_deg": 0.0}}, m, 4) for m in registered_models()}
    blevins = tables["blevins"].freq_hz("theta0")
    assert tables["assumed-modes"].freq_hz("theta0") == pytest.approx(blevins, rel=1e-6)
    assert tables["fe"].freq_hz("theta0") == pytest.approx(blevins, rel=1e-2)  # FE adds rotary inertia
    assert tables["lumped-mass"].freq_hz("theta0")[0] == pytest.approx(blevins[0], rel=1e-2)
    fe, am = tables["fe"].shapes("theta0"), tables["assumed-modes"].shapes("theta0")
    assert fe[:, :2] == pytest.approx(am[:, :2], rel=5e-3)  # same normalisation and sign convention
    assert tables["blevins"].sensors == [] and tables["fe"].sensors == ["a1", "a2", "a3"]
    assert set(tables["fe"].frame["source"]) == {"fe"}


def test_cli_writes_a_modal_table(tmp_path, poses_csv, capsys):
    out = tmp_path / "pred.csv"
    rig = write(tmp_path, SEED003)
    assert main(["predict", str(rig), "--model", "fe", "--poses", str(poses_csv), "--out", str(out),
                 "--modes", "3", "--source", "fe-rigid"]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    table = ModalTable.read_csv(out)
    assert table.configs == ["theta0", "theta90"]
    assert len(table.frame) == 6 and table.pose("theta90") == {"theta_deg": 90.0}
    assert set(table.frame["source"]) == {"fe-rigid"}
    assert table.freq_hz("theta90")[0] == pytest.approx(33.43, rel=1e-3)  # seed 003 Table 6: 33.43 Hz


def test_external_predictions_load_as_a_source(tmp_path):
    path = write(tmp_path, "config,mode,freq_hz\ntheta0,1,25.33\ntheta0,2,158.45\n", "ansys.csv")
    table = load_external(path)
    assert set(table.frame["source"]) == {"ansys"} and np.allclose(table.freq_hz("theta0"), [25.33, 158.45])


BAD_RIGS = {
    "missing link": (SEED003.replace('child = "link2"', 'child = "link3"'), "link3"),
    "member off its link": (SEED003 + '[[member]]\nname = "pusher"\nfrom = "link1@0.3"\nto = "link2@1.2"\n'
                            'section = { shape = "custom", EA_N = 1e6, EI_Nm2 = 10.0, '
                            'mass_per_m_kg = 0.1 }\n', "link2@1.2"),
    "zero wall": (SEED003.replace("wall_m = 0.0011 }", "wall_m = 0.0 }", 1), "wall_m"),
}


@pytest.mark.parametrize("case", sorted(BAD_RIGS))
def test_bad_rig_gives_one_line_and_exit_2(tmp_path, poses_csv, capsys, case):
    text, named = BAD_RIGS[case]
    rig = write(tmp_path, text)
    code = main(["predict", str(rig), "--model", "fe", "--poses", str(poses_csv),
                 "--out", str(tmp_path / "p.csv")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and named in err and "Traceback" not in err
    assert not (tmp_path / "p.csv").exists()


def test_model_that_cannot_handle_the_rig_says_so(tmp_path, poses_csv, capsys):
    rig = write(tmp_path, SEED003)
    code = main(["predict", str(rig), "--model", "blevins", "--poses", str(poses_csv), "--out",
                 str(tmp_path / "p.csv")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "straight arms only" in err and "elbow" in err and len(err.splitlines()) == 1


def test_missing_pose_variable_is_named(tmp_path, capsys):
    rig = write(tmp_path, SEED003)
    poses = write(tmp_path, "config,pose.payload_kg\nc1,0\n", "poses.csv")
    code = main(["predict", str(rig), "--model", "fe", "--poses", str(poses),
                 "--out", str(tmp_path / "p.csv")])
    assert code == 2 and "theta_deg" in capsys.readouterr().err


def test_predict_validates_its_arguments(rigs_dir):
    rig = load_rig(rigs_dir / "seed003_two_link.toml")
    with pytest.raises(ModelError, match="unknown model"):
        predict(rig, {"a": {"theta_deg": 0}}, "ritz")
    with pytest.raises(ModelError, match=">= 1"):
        predict(rig, {"a": {"theta_deg": 0}}, "fe", 0)
    frame = predict(rig, {"a": {"theta_deg": 10}}, "lumped-mass", 2, source="lmm-planar").frame
    assert isinstance(frame, pd.DataFrame) and set(frame["source"]) == {"lmm-planar"}


def test_fe_drops_every_rigid_body_mode_of_a_floating_chain():
    from flexmodal.models.rig import parse_rig

    section = {"shape": "custom", "EA_N": 1e7, "EI_Nm2": 100.0, "mass_per_m_kg": 1.0}
    doc = {"base": {"support": "free"},
           "link": [{"name": f"l{i}", "length_m": 1.0, "section": section} for i in range(3)],
           "joint": [{"name": f"j{i}", "parent": f"l{i}", "child": f"l{i + 1}", "kind": "pin"}
                     for i in range(2)]}
    freq = predict(parse_rig(doc), {"a": {}}, "fe", 4).freq_hz("a")
    assert len(freq) == 4 and freq.min() > 1.0  # 3 planar rigid-body modes + 2 free pins are left out


def test_fe_eigensolves_run_under_the_single_thread_blas_limit(rigs_dir, monkeypatch):
    """The solvers are generators: every eigen-solve must run inside predict's BLAS thread limit."""
    import threadpoolctl

    from flexmodal.models import frame

    seen = []
    solve = frame.solve_modes

    def spy(system, n):
        seen.append(max((p["num_threads"] for p in threadpoolctl.threadpool_info()
                         if p["user_api"] == "blas"), default=1))
        return solve(system, n)

    monkeypatch.setattr(frame, "solve_modes", spy)
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        predict(load_rig(rigs_dir / "seed003_two_link.toml"),
                {"a": {"theta_deg": 0.0}, "b": {"theta_deg": 60.0}})
    assert seen == [1, 1]


def test_progress_is_told_as_each_pose_is_solved(rigs_dir):
    """A model that solves pose by pose: predict tells progress after each pose, not after all of them
    (it listed every result first: a terminal's bar stood at 0 for 28 s, then jumped to 6/6), and a
    model whose table fails half-way is closed (its worker process ends)."""
    from flexmodal.models.registry import register_model, unregister_model

    events, closed = [], []

    def lazy(rig, poses, n_modes, options):
        try:
            for k, _pose in enumerate(poses):
                events.append(f"solve {k}")
                yield np.array([10.0 * (k + 1)]), None
        finally:
            closed.append(True)

    register_model("lazy-toy", lazy)
    try:
        rig = load_rig(rigs_dir / "seed003_two_link.toml")
        poses = {"a": {"theta_deg": 0.0}, "b": {"theta_deg": 60.0}, "c": {"theta_deg": 90.0}}
        table = predict(rig, poses, "lazy-toy", 1, progress=lambda c: events.append(f"told {c}"))
        assert events == ["solve 0", "told a", "solve 1", "told b", "solve 2", "told c"]
        assert table.freq_hz("c") == pytest.approx([30.0]) and closed == [True]
        events.clear()

        def stop(config):
            raise KeyboardInterrupt  # as Ctrl-C while the first pose is told

        with pytest.raises(KeyboardInterrupt):
            predict(rig, poses, "lazy-toy", 1, progress=stop)
        assert events == ["solve 0"] and closed == [True, True]
    finally:
        unregister_model("lazy-toy")
