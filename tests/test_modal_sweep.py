"""Swept-sine records (modal/sweep.py): where each sweep starts, and two-input H1 from one rectangular
segment per sweep, against the exact FRFs of the sampled modal model (fixtures.modal_sim, first-order
hold) and through ``flexmodal identify`` on UFF 58 time histories."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
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


@settings(max_examples=40, deadline=None, database=None, derandomize=True)
@given(n_sweeps=st.integers(1, 4), sweep_s=st.floats(10.0, 60.0), quiet_s=st.floats(0.0, 10.0),
       f_lo=st.floats(0.5, 5.0), f_hi=st.floats(20.0, 60.0), method=st.sampled_from(["linear",
       "logarithmic"]), down=st.booleans(), lead_s=st.floats(0.0, 5.0))
def test_sweep_starts_cuts_any_train_of_sweeps_at_their_starts(n_sweeps, sweep_s, quiet_s, f_lo, f_hi,
                                                               method, down, lead_s):
    """Any train of equal sweeps (up or down, linear or logarithmic, with or without quiet gaps and a
    lead): one start per sweep, the first at 0, each other one within two blocks (1/32 of the record)
    of the sweep's first sample; with a quiet gap before it, in the gap (never after the start)."""
    t = np.arange(int(sweep_s * FS)) / FS
    one = chirp(t, f_hi if down else f_lo, sweep_s, f_lo if down else f_hi, method=method)
    period = np.concatenate([one, np.zeros(int(quiet_s * FS))])
    x = np.concatenate([np.zeros(int(lead_s * FS)), np.tile(period, n_sweeps)])
    starts = sweep_starts(x[:, None])
    true = int(lead_s * FS) + period.size * np.arange(n_sweeps)
    assert starts is not None and starts.size == n_sweeps and starts[0] == 0, (starts, true)
    block = x.size // min(64, x.size // 128)                       # sweep_starts' block length
    assert np.all(np.abs(true[1:] - starts[1:]) <= 2 * block), (starts, true)
    if quiet_s >= 2 * block / FS:
        assert np.all(starts[1:] <= true[1:]), (starts, true)


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


def test_a_simulated_sweep_run_gets_one_segment_per_sweep_and_unbiased_damping():
    """The demo arm's sweep test (fixtures.rig_sim: one linear chirp over a 16 s run, zeta 1 %): the
    record labelled ``sweep`` is one rectangular segment (Welch/Hann at the default nfft 4096 put
    the 33 Hz mode's damping 35 % low); the three modes within 1e-4, damping within 1 %.  Given an
    nfft, the record is Welch-averaged as before."""
    from flexmodal.fixtures.rig_sim import DEMO_RIG, simulate
    from flexmodal.modal.identify import identify
    from flexmodal.models.rig import load_rig

    test = simulate(load_rig(DEMO_RIG), {"theta_deg": 30.0}, excitation="sweep", duration_s=16.0,
                    sample_rate_hz=1024.0, seed=2, damping_ratio=0.01, fmax_hz=450.0)
    names, kinds = [c.name for c in test.channels], [c.kind for c in test.channels]
    res = frf_of_record(test.samples, test.sample_rate_hz, names, kinds, excitation="sweep")
    assert res.provenance["sweeps"] == [0] and res.window == "rect" and res.nfft == test.samples.shape[0]
    modes = identify(res.freq_hz, res.H, fmin=5, fmax=450)
    fn, zeta = test.natural_freq_hz, test.damping_ratio
    keep = fn < 440
    assert modes.freq_hz.size == keep.sum() and np.allclose(modes.freq_hz, fn[keep], rtol=1e-4)
    assert np.allclose(modes.damping_ratio, zeta[keep], rtol=0.01), modes.damping_ratio
    welch = frf_of_record(test.samples, test.sample_rate_hz, names, kinds, excitation="sweep", nfft=4096)
    assert welch.window == "hann" and welch.nfft == 4096 and "sweeps" not in welch.provenance
