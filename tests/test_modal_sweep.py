"""Swept-sine records (modal/sweep.py): where each sweep starts, and two-input H1 from one rectangular
segment per sweep, against the exact FRFs of the sampled modal model (fixtures.modal_sim, first-order
hold) and through ``flexmodal identify`` on UFF 58 time histories."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import chirp

from flexmodal.app import main
from flexmodal.contract.table import ModalTable
from flexmodal.fixtures.modal_sim import modal_frf, modal_response
from flexmodal.modal.compute import frf_of_record
from flexmodal.modal.frf import h1
from flexmodal.modal.spectra import Spectra
from flexmodal.modal.sweep import sweep_starts

FS = 125.0
FN, ZETA = np.array([11.2, 22.6, 33.2]), np.array([0.01, 0.008, 0.012])
PHI = np.array([[1.0, 0.7, -0.5], [0.6, -0.9, 0.8]])          # outputs x modes
PHI_IN = np.array([[1.0, 0.5, 0.9], [0.8, -0.6, -0.7]])       # the two drives x modes


def _two_drive_record(sweep_s: float = 60.0, quiet_s: float = 25.0) -> tuple[np.ndarray, np.ndarray]:
    """Drives [n, 2] and accelerations [n, 2]: an exponential sweep 1-50 Hz driven in phase, then in
    anti-phase, each followed by ``quiet_s`` of silence (the responses ring down: 1e-6 at 11 Hz)."""
    t = np.arange(int(sweep_s * FS)) / FS
    s = np.concatenate([chirp(t, 1.0, sweep_s, 50.0, method="logarithmic"), np.zeros(int(quiet_s * FS))])
    drives = np.concatenate([np.column_stack([s, s]), np.column_stack([s, -s])])
    return drives, modal_response(drives, FS, FN, ZETA, PHI, PHI_IN)


def test_sweep_starts_finds_each_sweep_and_refuses_random_and_impact_forces():
    drives, _ = _two_drive_record()
    starts = sweep_starts(drives)
    assert starts.size == 2 and starts[0] == 0
    assert int(60.0 * FS) <= starts[1] <= drives.shape[0] // 2     # in the quiet gap before the 2nd
    assert sweep_starts(drives[::-1]).size == 2                    # down-sweeps
    rng = np.random.default_rng(3)
    assert sweep_starts(rng.standard_normal((drives.shape[0], 2))) is None
    hits = np.zeros((drives.shape[0], 1))
    hits[100:106, 0] = hits[9000:9006, 0] = np.sin(np.pi * np.arange(6) / 5)
    assert sweep_starts(hits) is None


def test_two_input_h1_of_one_segment_per_sweep_is_the_exact_frf():
    drives, y = _two_drive_record()
    samples = np.column_stack([drives, y])
    res = frf_of_record(samples, FS, ["u1", "u2", "a1", "a2"], ["force", "force", "acceleration",
                                                               "acceleration"], sweeps=sweep_starts(drives))
    assert res.window == "rect" and res.n_averages == 2 and res.provenance["excitation"] == "sweep"
    assert res.freq_hz[1] == pytest.approx(FS / res.nfft) and res.nfft >= drives.shape[0] // 2 - 1
    exact = modal_frf(res.freq_hz, FN, ZETA, PHI, PHI_IN, sample_rate_hz=FS)
    band = (res.freq_hz > 2.0) & (res.freq_hz < 45.0)
    err = np.abs(res.H[..., band] - exact[..., band]) / np.abs(exact[..., band]).max(axis=-1, keepdims=True)
    assert err.max() < 1e-4, err.max()
    assert res.coherence[:, band].min() > 1 - 1e-9            # two segments, two inputs: determined


def test_h1_is_the_minimum_norm_solution_where_the_inputs_carry_nothing():
    """Lines with no input energy (one input silent, or both): H1 is G_xf G_ff+ there, never NaN."""
    g_ff = np.zeros((2, 2, 3), complex)
    g_ff[:, :, 0] = [[2.0, 0.5], [0.5, 1.0]]
    g_ff[0, 0, 1] = 4.0                                      # the second input silent at line 1
    g_xf = np.ones((1, 2, 3), complex)
    H = h1(Spectra(np.arange(3.0), g_xf, g_ff, np.ones((1, 3)), 1))
    assert np.allclose(H[0, :, 0], np.linalg.solve(g_ff[:, :, 0].T, g_xf[0, :, 0]))
    assert np.allclose(H[0, :, 1], [0.25, 0.0]) and np.allclose(H[0, :, 2], 0.0)
    one = h1(Spectra(np.arange(2.0), np.ones((1, 1, 2), complex), np.array([[[1.0, 0.0]]], complex),
                     np.ones((1, 2)), 1))
    assert np.array_equal(one, np.array([[[1.0, 0.0]]], complex))


def test_a_two_drive_sweep_record_in_uff_gives_its_modes_and_damping(tmp_path, capsys):
    """The beam-ring's two-input test in miniature (symmetric then antisymmetric sweep of two drives,
    UFF 58 time histories): H1 of one segment per sweep; the three modes within 0.05 %, damping
    within 5 %, no extra mode."""
    pyuff = pytest.importorskip("pyuff")
    drives, y = _two_drive_record()
    y = y + 1e-4 * np.abs(y).max() * np.random.default_rng(4).standard_normal(y.shape)
    t = np.arange(drives.shape[0]) / FS
    chans = [(1, drives[:, 0], 13), (2, drives[:, 1], 13), (11, y[:, 0], 12), (12, y[:, 1], 12)]
    sets = [pyuff.prepare_58(func_type=1, rsp_node=node, rsp_dir=3, ref_node=1, ref_dir=3,
                             ordinate_spec_data_type=kind, orddenom_spec_data_type=0,
                             abscissa_spec_data_type=17, data=data, x=t, abscissa_spacing=1, abscissa_min=0.0,
                             abscissa_inc=1 / FS, num_pts=t.size, id1="sweeps")
            for node, data, kind in chans]
    path = tmp_path / "sweeps.uff"
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    code = main(["identify", str(path), "--out", str(tmp_path / "m.csv"), "--fmin", "5", "--fmax", "45"])
    assert code == 0, capsys.readouterr().err
    table = ModalTable.read_csv(tmp_path / "m.csv")
    found, damping = table.freq_hz("sweeps"), table.frame["damping_ratio"].to_numpy()
    assert found.size == 3 and np.all(np.abs(found / FN - 1) < 5e-4), found
    assert np.all(np.abs(damping / ZETA - 1) < 0.05), damping
