"""`flexmodal frf` and `flexmodal identify` on real HDF5 run files and UFF files: batch on a
LocalCluster and on a scheduler started on 127.0.0.1 equals the serial path; garbage in -> exit 2."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from flexmodal.app import main
from flexmodal.contract.table import ModalTable
from flexmodal.daq.store import Channel, RunWriter, expand_runs
from flexmodal.fixtures.modal_sim import modal_response
from flexmodal.modal.batch import run_batch
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.runs_io import read_frf
from flexmodal.modal.uff import write_frfs

FS = 256.0
FN, ZETA = np.array([12.0, 31.0, 55.0]), np.array([0.02, 0.01, 0.01])
PHI = np.array([[1.0, 0.8, 0.3], [0.5, -0.6, 0.9], [0.2, -0.9, -0.7]])
CHANNELS = [Channel("force", "force", "N", location="p1", direction="z")] + [
    Channel(f"a{k + 1}", "acceleration", "m/s^2", location=f"p{k + 1}", direction="z") for k in range(3)]


def _write_run(path, run_id, seed, n=4096, samples=None, excitation="random"):
    if samples is None:
        f = np.random.default_rng(seed).standard_normal((n, 1))
        samples = np.column_stack([f, modal_response(f, FS, FN, ZETA, PHI, PHI[[0]])])
    with RunWriter(path, run_id, sample_rate_hz=FS, channels=CHANNELS, excitation=excitation,
                   pose={"theta_deg": seed}) as w:
        w.append(samples)
    return path


@pytest.fixture(scope="module")
def twenty_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("runs")
    return [str(_write_run(d / f"r{k:02d}.h5", f"run{k}", k, n=1024)) for k in range(20)]


def _same(a: list[FrfResult], b: list[FrfResult]) -> None:
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.H, y.H) and np.array_equal(x.coherence, y.coherence)


@pytest.mark.slow
def test_frf_cli_with_two_workers_equals_serial_path(twenty_runs, capsys):
    serial = run_batch(expand_runs(twenty_runs), {"nfft": 256})
    assert main(["--quiet", "frf", *twenty_runs, "--workers", "2", "--nfft", "256"]) == 0
    assert capsys.readouterr().out.split() == [f"{p}:run{k}" for k, p in enumerate(twenty_runs)]
    stored = [read_frf(p, f"run{k}") for k, p in enumerate(twenty_runs)]
    _same(serial, stored)
    with h5py.File(twenty_runs[0], "r") as f:   # plain h5py sees the docs/hdf5-format.md layout
        g = f["runs/run0/frf"]
        assert g["H"].shape == (3, 1, 129) and g["coherence"].shape == (3, 129)
        assert g.attrs["estimator"] == "H1" and g.attrs["nfft"] == 256 and g.attrs["n_averages"] == 7


def test_frf_cli_against_a_scheduler_on_loopback(twenty_runs, capsys):
    from distributed import LocalCluster

    runs = twenty_runs[:3]
    serial = run_batch(expand_runs(runs), {"nfft": 256, "estimator": "H2"})
    with LocalCluster(host="127.0.0.1", protocol="tcp", n_workers=1, processes=False,
                      dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        assert main(["--quiet", "frf", *runs, "--scheduler", cluster.scheduler_address, "--nfft", "256",
                     "--estimator", "H2"]) == 0
    _same(serial, [read_frf(p, f"run{k}") for k, p in enumerate(runs)])
    assert read_frf(runs[0], "run0").estimator == "H2"


def test_identify_hdf5_computes_frfs_and_writes_modal_table(tmp_path, capsys):
    run = _write_run(tmp_path / "long.h5", "theta7", 7, n=64 * 1024)
    out = tmp_path / "modes.csv"
    assert main(["identify", str(run), "--out", str(out), "--fmin", "5", "--fmax", "100"]) == 0
    assert capsys.readouterr().out.strip() == str(out)
    table = ModalTable.read_csv(out)
    assert np.allclose(table.freq_hz("theta7"), FN, rtol=2e-3)
    assert table.pose("theta7") == {"theta_deg": 7}
    assert set(table.sensors) == {"a1", "a2", "a3"}
    assert (table.frame["source"] == "experiment").all()


def test_identify_uff_frfs(tmp_path):
    from flexmodal.fixtures.modal_sim import modal_frf

    f = np.linspace(0, 100, 1001)
    H = modal_frf(f, FN, ZETA, PHI, PHI[[0]])
    H[..., 0] = 0
    uff = tmp_path / "frf.uff"
    write_frfs(uff, FrfResult(f, H, np.ones((3, f.size)), "H1", "hann", 2000, 10, 200.0, "accelerance",
                              ("1+z", "2+z", "3+z"), ("1+z",)))
    out = tmp_path / "modes.csv"
    assert main(["identify", str(uff), "--out", str(out), "--fmin", "5",
                 "--uff", str(tmp_path / "m.uff")]) == 0
    table = ModalTable.read_csv(out)
    assert np.allclose(table.freq_hz("frf"), FN, rtol=1e-4)
    assert np.allclose(table.frame["damping_ratio"], ZETA, rtol=1e-2)
    import pyuff

    modes = pyuff.UFF(str(tmp_path / "m.uff")).read_sets()
    assert [m["type"] for m in modes] == [55, 55, 55]


def test_identify_uff_time_histories_with_force_reference(tmp_path):
    import pyuff

    n = 64 * 1024
    f = np.random.default_rng(3).standard_normal((n, 1))
    samples = np.column_stack([f, modal_response(f, FS, FN, ZETA, PHI, PHI[[0]])])
    sets = [pyuff.prepare_58(func_type=1, rsp_node=k + 1, rsp_dir=3, ref_node=1, ref_dir=3,
                             ordinate_spec_data_type=13 if k == 0 else 12, orddenom_spec_data_type=0,
                             abscissa_spec_data_type=17, data=samples[:, k], x=np.arange(n) / FS,
                             abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=1 / FS, num_pts=n, id1="t")
            for k in range(4)]
    uff = tmp_path / "time.uff"
    pyuff.UFF(str(uff)).write_sets(sets, mode="overwrite")
    out = tmp_path / "modes.csv"
    assert main(["identify", str(uff), "--out", str(out), "--fmin", "5", "--fmax", "100"]) == 0
    table = ModalTable.read_csv(out)
    assert np.allclose(table.freq_hz("time"), FN, rtol=2e-3)
    assert table.sensors == ["2+z", "3+z", "4+z"]


def _error_line(capsys) -> str:
    err = capsys.readouterr().err   # not stripped: a progress bar's empty line above the error counts
    assert err.endswith("\n") and err.count("\n") == 1, repr(err)
    return err[:-1]


@pytest.mark.parametrize(("damage", "message"), [
    ("nan", "only 0 of 15 segments usable, 8 needed (channel 'a1' holds nan at sample 100)"),
    ("constant", "'a2' is constant"), ("short", "shorter than one segment")])
def test_garbage_runs_exit_2_with_one_line(tmp_path, capsys, damage, message):
    f = np.random.default_rng(0).standard_normal((2048, 1))
    samples = np.column_stack([f, modal_response(f, FS, FN, ZETA, PHI, PHI[[0]])])
    nfft = "256"
    if damage == "nan":   # a NaN every 160 samples: each of the 15 segments of 256 holds one
        samples[100::160, 1] = np.nan
    elif damage == "constant":
        samples[:, 2] = 1.5
    else:
        nfft = "4096"
    run = _write_run(tmp_path / "bad.h5", "bad", 0, samples=samples)
    assert main(["frf", str(run), "--nfft", nfft]) == 2
    assert message in _error_line(capsys)


def test_garbage_uff_exits_2(tmp_path, capsys):
    import pyuff

    bad = tmp_path / "shapes.uff"
    pyuff.UFF(str(bad)).write_sets([pyuff.prepare_58(
        func_type=2, rsp_node=1, rsp_dir=3, ref_node=1, ref_dir=3, orddenom_spec_data_type=13,
        abscissa_spec_data_type=18, ordinate_spec_data_type=12, data=np.ones(16), x=np.arange(16.0),
        abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=1.0, num_pts=16, id1="auto")], mode="overwrite")
    assert main(["identify", str(bad), "--out", str(tmp_path / "m.csv")]) == 2
    assert "function types [2] are not supported" in _error_line(capsys)
    mixed = tmp_path / "mixed.uff"
    sets = [pyuff.prepare_58(func_type=1, rsp_node=k + 1, rsp_dir=3, ref_node=1, ref_dir=3,
                             ordinate_spec_data_type=13 if k == 0 else 12, orddenom_spec_data_type=0,
                             abscissa_spec_data_type=17, data=np.random.rand(64),
                             x=np.arange(64) * dt, abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=dt,
                             num_pts=64, id1="t") for k, dt in enumerate((0.01, 0.02))]
    pyuff.UFF(str(mixed)).write_sets(sets, mode="overwrite")
    assert main(["identify", str(mixed), "--out", str(tmp_path / "m.csv")]) == 2
    assert "mismatched sample rates" in _error_line(capsys)
