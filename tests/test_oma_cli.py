"""Output-only runs through `flexmodal identify` (HDF5 runs and UFF 58 time histories without a force
record default to SSI-cov; --method fdd; --references), the simulated arm in operation at three poses
against impact tests of the same poses (frequencies and the diagnosed effect), and an operational run
acquired from `sim serve --test operational` through the real serial stack."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.app import main
from flexmodal.contract.table import ModalTable
from flexmodal.daq.store import Channel, RunWriter
from flexmodal.fixtures.shear_frame import shear_frame_record

MASS = [3000.0, 2800.0, 2600.0, 2400.0, 2000.0]
STIFF = [9.6e7, 8.8e7, 8.0e7, 7.2e7, 6.4e7]
ZETA = [0.002, 0.005, 0.01, 0.015, 0.02]


@pytest.fixture(scope="module")
def frame():
    return shear_frame_record(MASS, STIFF, ZETA, duration_s=300.0, seed=2)


def _store(path, rec, excitation="operational", with_force=False):
    channels = [Channel(f"s{k + 1}", "acceleration", "m/s^2", location=f"floor{k + 1}", direction="x")
                for k in range(rec.samples.shape[1])]
    samples = rec.samples
    if with_force:   # a force channel that is not the excitation (e.g. a load cell in the structure)
        channels = [Channel("F", "force", "N", location="floor1", direction="x"), *channels]
        samples = np.column_stack([np.random.default_rng(0).standard_normal(samples.shape[0]), samples])
    with RunWriter(path, "op", sample_rate_hz=rec.sample_rate_hz, channels=channels, excitation=excitation,
                   pose={"storeys": 5}) as w:
        w.append(samples)
    return path


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("with_force", [False, True])
def test_operational_run_defaults_to_ssi(tmp_path, frame, with_force):
    run = _store(tmp_path / "op.h5", frame, with_force=with_force)
    out = tmp_path / "modes.csv"
    assert main(["--quiet", "identify", str(run), "--out", str(out)]) == 0
    table = ModalTable.read_csv(out)
    assert np.max(np.abs(table.freq_hz("op") / frame.freq_hz - 1)) < 0.002
    assert table.sensors == [f"s{k + 1}" for k in range(5)]
    assert table.frame["pose.storeys"].eq(5).all()


def test_fdd_and_references_on_the_command_line(tmp_path, frame, capsys):
    run = _store(tmp_path / "op.h5", frame)
    out = tmp_path / "fdd.csv"
    assert main(["identify", str(run), "--out", str(out), "--method", "fdd", "--references", "s1,s5"]) == 0
    table = ModalTable.read_csv(out)
    assert np.max(np.abs(table.freq_hz("op") / frame.freq_hz - 1)) < 0.002
    assert np.all(table.frame["freq_std_hz"] > 0) and np.all(table.frame["damping_std"] > 0)   # FDD's sigma
    capsys.readouterr()
    assert main(["identify", str(run), "--out", str(out), "--method", "ssi", "--references", "s9"]) == 2
    assert "reference channel s9 is not among the outputs" in _error_line(capsys)
    assert main(["identify", str(run), "--out", str(out), "--method", "lscf"]) == 2
    assert "no force channel" in _error_line(capsys)


def test_uff_time_histories_without_force_default_to_ssi(tmp_path, frame):
    import pyuff

    n = 64 * 1024
    sets = [pyuff.prepare_58(func_type=1, rsp_node=k + 1, rsp_dir=1, ref_node=k + 1, ref_dir=1,
                             ordinate_spec_data_type=12, orddenom_spec_data_type=0,
                             abscissa_spec_data_type=17,
                             data=frame.samples[:n, k], x=np.arange(n) / 256.0, abscissa_spacing=1,
                             abscissa_min=0.0, abscissa_inc=1 / 256.0, num_pts=n, id1="t") for k in range(5)]
    uff = tmp_path / "op.uff"
    pyuff.UFF(str(uff)).write_sets(sets, mode="overwrite")
    out = tmp_path / "modes.csv"
    assert main(["--quiet", "identify", str(uff), "--out", str(out)]) == 0
    table = ModalTable.read_csv(out)
    assert np.max(np.abs(table.freq_hz("op") / frame.freq_hz - 1)) < 0.003
    assert table.sensors == [f"{k + 1}+x" for k in range(5)]


def test_arm_in_operation_matches_impact_tests_and_gives_the_same_diagnosis(tmp_path):
    """Three poses of the demo arm with its hidden compliant elbow: 60 s operational records (SSI) and
    8 s impact tests (pLSCF) through `identify`; frequencies within 0.5 %, `diagnose` on either table
    names the same effect and place."""
    from flexmodal.compare.diagnosis import diagnose
    from flexmodal.fixtures.demo import DEMO_EFFECTS, store_test
    from flexmodal.fixtures.rig_sim import DEMO_RIG, simulate
    from flexmodal.models.rig import load_rig

    rig = load_rig(DEMO_RIG)
    for k, theta in enumerate((0, 60, 120)):
        pose = {"theta_deg": float(theta)}
        op = simulate(rig, pose, excitation="operational", duration_s=60.0, sample_rate_hz=2048.0,
                      effects=DEMO_EFFECTS, seed=3 + k)
        assert "force" not in [c.kind for c in op.channels] and op.driving.shape[0] == 2   # elbow + tip
        store_test(tmp_path / "op.h5", f"theta{theta}", op)
        store_test(tmp_path / "impact.h5", f"theta{theta}", simulate(
            rig, pose, excitation="impact", sample_rate_hz=2048.0, effects=DEMO_EFFECTS, seed=13 + k))
    assert main(["--quiet", "identify", str(tmp_path / "op.h5"), "--out", str(tmp_path / "oma.csv"),
                 "--fmin", "20", "--fmax", "450"]) == 0
    assert main(["--quiet", "identify", str(tmp_path / "impact.h5"), "--out", str(tmp_path / "imp.csv"),
                 "--fmin", "5", "--fmax", "450"]) == 0
    oma, imp = ModalTable.read_csv(tmp_path / "oma.csv"), ModalTable.read_csv(tmp_path / "imp.csv")
    for config in ("theta0", "theta60", "theta120"):
        f_oma, f_imp = oma.freq_hz(config), imp.freq_hz(config)
        assert f_oma.size == f_imp.size == 3
        assert np.max(np.abs(f_oma / f_imp - 1)) < 0.005, (config, f_oma, f_imp)
    verdicts = [diagnose(rig, table).verdict for table in (oma, imp)]
    assert verdicts[0].effect == verdicts[1].effect == "joint_stiffness"
    assert verdicts[0].location == verdicts[1].location == "elbow"
    assert verdicts[0].explained and verdicts[1].explained


def test_operational_run_acquired_from_the_serial_simulator(tmp_path):
    """`sim serve --test operational` streams the arm's responses (no force channel) over a pty; the
    session records them as an operational run, and `identify` (SSI by default) finds the arm's modes."""
    from flexmodal.daq.acquire import acquire
    from flexmodal.daq.session import parse_session
    from flexmodal.daq.store import read_run
    from flexmodal.fixtures.rig_sim import DEMO_RIG, simulate
    from flexmodal.fixtures.sim_source import sim_source
    from flexmodal.fixtures.truth_arm import bench_arm
    from flexmodal.models.rig import load_rig

    pose = {"theta_deg": 60.0}
    source = sim_source(DEMO_RIG, "operational", 2048.0, pose=pose)
    assert "force" not in [c.kind for c in source.channels]
    names = [f"ch{i}" for i in range(len(source.channels))]
    doc = {"sample_rate_hz": 2048.0, "excitation": "operational", "pose": pose,
           "simulator": {"protocol": "serial", "rig": str(DEMO_RIG), "test": "operational",
                         "pose": pose},
           "device": [{"name": "adc", "protocol": "serial", "port": "@simulator", "baud": 3_000_000,
                       "framing": "binary", "sources": names}],
           "channel": [{"name": c.name, "kind": c.kind, "unit": c.unit, "device": "adc", "source": n,
                        "scale": c.scale, "sensitivity": c.sensitivity,
                        "sensitivity_unit": c.sensitivity_unit,
                        "location": c.location, "direction": c.direction}
                       for n, c in zip(names, source.channels, strict=True)]}
    out = tmp_path / "op.h5"
    acquire(parse_session(doc, tmp_path / "session.toml"), out, duration_s=4.0, quiet=True, run_id="theta60")
    run = read_run(out, "theta60")
    assert run.excitation == "operational" and run.samples.shape[0] >= 4 * 2048
    assert [c.name for c in run.channels] == [c.name for c in source.channels]
    assert main(["--quiet", "identify", str(out), "--out", str(tmp_path / "m.csv"), "--fmin", "20",
                 "--fmax", "450"]) == 0
    rig = load_rig(DEMO_RIG)   # the simulator's arm is the independent truth model (fixtures/truth_arm.py)
    truth = simulate(rig, pose, excitation="operational", duration_s=0.1,
                     truth=bench_arm(rig)).natural_freq_hz
    found = ModalTable.read_csv(tmp_path / "m.csv").freq_hz("theta60")
    # 4 s hold ~140 cycles of the 35.6 Hz mode: its SSI frequency scatters by ~0.5 % (the 0.5 %
    # acceptance is the 60 s test above); 1 % here
    assert found.size == 3 and np.max(np.abs(found / truth[:3] - 1)) < 0.01, (found, truth[:3])


@pytest.mark.parametrize(("samples", "method", "code", "message"), [
    (np.random.default_rng(7).standard_normal((20000, 3)), "ssi", 2, "no stable mode"),
    (np.random.default_rng(7).standard_normal((20000, 3)), "fdd", 2, "no peak gave a decaying"),
    (np.random.default_rng(7).standard_normal((50, 3)), "ssi", 2, "too few"),
    (np.where(np.arange(20000)[:, None] % 2 == 0, np.nan, 1.0) * np.random.default_rng(7).standard_normal(
        (20000, 3)), "ssi", 2, "gaps everywhere"),
])
def test_records_without_modes_are_one_clear_line(tmp_path, capsys, samples, method, code, message):
    channels = [Channel(f"s{k}", "acceleration", "m/s^2") for k in range(samples.shape[1])]
    with RunWriter(tmp_path / "r.h5", "r", sample_rate_hz=256.0, channels=channels, excitation="operational",
                   pose={}) as w:
        w.append(samples)
    capsys.readouterr()
    args = ["identify", str(tmp_path / "r.h5"), "--out", str(tmp_path / "m.csv"), "--method", method]
    assert main(args) == code
    assert message in capsys.readouterr().err.strip().splitlines()[-1]


def test_one_output_channel_is_identified_with_a_warning(tmp_path, capsys):
    one = shear_frame_record(MASS, STIFF, ZETA, duration_s=120.0, seed=2)
    one = type(one)(one.samples[:, 4:], one.sample_rate_hz, one.freq_hz, one.damping_ratio, one.shapes[4:])
    run = _store(tmp_path / "one.h5", one)
    assert main(["identify", str(run), "--out", str(tmp_path / "m.csv")]) == 0
    assert "one output channel: no shape criterion can tell modes from noise peaks" in capsys.readouterr().err
