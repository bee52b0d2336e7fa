"""The moving-arm simulator (fixtures/moving_arm.py): its time-varying modal recurrence against a plain
per-sample loop and against scipy's filter for frozen parameters, its path modes against the truth
model solved afresh, its encoders and harmonics, and the `moving` test of the device simulators."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from flexmodal.fixtures.moving_arm import (
    ELBOW_SWEEP,
    PathModes,
    Trajectory,
    frozen_truth,
    simulate_moving,
    varying_modal_response,
)
from flexmodal.fixtures.rig_sim import DEMO_RIG
from flexmodal.fixtures.sim_source import sim_source
from flexmodal.models.rig import load_rig


def _two_modes(freq_start, freq_end):
    s = np.linspace(0.0, 1.0, 5)
    f = np.outer(1 - s, freq_start) + np.outer(s, freq_end)
    zeta = np.full_like(f, 0.02)
    shapes = np.tile(np.array([[1.0, 0.5], [0.3, -1.0], [0.7, 0.2]]), (5, 1, 1))
    driving = np.tile(np.array([[1.0, 0.8]]), (5, 1, 1))
    return PathModes(s, f, zeta, shapes, driving)


def _loop_reference(load, fs, s, modes):
    """The recurrence z_(k+1) = exp(lambda_k dt) z_k + dt p_k sample by sample (the slow way)."""
    dt = 1 / fs
    f, zeta = modes.at(s)
    out = np.zeros((load.shape[0], modes.shapes.shape[1]))
    z = np.zeros(f.shape[1], complex)
    for k in range(load.shape[0]):
        i = min(int(s[k] * 4), 3)
        w = s[k] * 4 - i
        shape = (1 - w) * modes.shapes[i] + w * modes.shapes[i + 1]
        drive = (1 - w) * modes.driving[i] + w * modes.driving[i + 1]
        wn = 2 * np.pi * f[k]
        lam = -zeta[k] * wn + 1j * wn * np.sqrt(1 - zeta[k] ** 2)
        p = load[k] @ drive
        out[k] = shape @ ((lam**2 * z).imag / lam.imag + p)
        z = np.exp(lam * dt) * z + dt * p
    return out


def test_varying_response_equals_the_per_sample_recurrence():
    rng = np.random.default_rng(1)
    fs, n = 1000.0, 3000
    modes = _two_modes([40.0, 90.0], [80.0, 50.0])     # the two frequencies cross half-way
    s = 0.5 * (1 - np.cos(np.linspace(0, 2 * np.pi, n)))
    load = rng.standard_normal((n, 1))
    fast = varying_modal_response(load, fs, s, modes)
    np.testing.assert_allclose(fast, _loop_reference(load, fs, s, modes), rtol=1e-9,
                               atol=1e-9 * np.abs(fast).max())


def test_frozen_parameters_give_the_impulse_invariant_filter():
    """With the pose still, each mode is the discrete system with pole exp(lambda dt): scipy's lfilter of
    (1 - a z^-1) form on the complex coordinate, an independent implementation."""
    rng = np.random.default_rng(2)
    fs, n = 2000.0, 40000
    modes = _two_modes([55.0, 210.0], [55.0, 210.0])
    load = rng.standard_normal((n, 1))
    fast = varying_modal_response(load, fs, np.zeros(n), modes)     # several chunks of the recurrence
    dt = 1 / fs
    expected = np.zeros((n, 3))
    for r, f in enumerate((55.0, 210.0)):
        wn = 2 * np.pi * f
        lam = -0.02 * wn + 1j * wn * np.sqrt(1 - 0.02**2)
        p = load[:, 0] * modes.driving[0, 0, r]
        z = signal.lfilter([0.0, dt], [1.0, -np.exp(lam * dt)], p.astype(complex))
        expected += np.outer((lam**2 * z).imag / lam.imag + p, modes.shapes[0, :, r])
    np.testing.assert_allclose(fast, expected, rtol=1e-8, atol=1e-8 * np.abs(expected).max())


def test_path_modes_are_the_truth_model_along_the_sweep():
    rig = load_rig(DEMO_RIG)
    rec = simulate_moving(rig, Trajectory({"theta_deg": 0.0}, {"theta_deg": 150.0}, 20.0),
                          sample_rate_hz=1024.0, grid=31, orders=(36.0,))
    assert rec.modes.freq_hz.shape[1] == 3                              # three modes below 0.45 x 1024 Hz
    for theta in (0.0, 37.5, 95.0, 150.0):
        t = np.arccos(1 - 2 * theta / 150.0) / (2 * np.pi) * 20.0        # the first time the sweep is there
        f_path, z_path = rec.frozen(np.array([t]))
        f, z = frozen_truth(rig, {"theta_deg": theta}, 0.45 * 1024.0)
        np.testing.assert_allclose(f_path[0], f, rtol=1e-3)                # 5 deg grid, linear in between
        np.testing.assert_allclose(z_path[0], z, rtol=1e-2)
    enc = rec.samples[:, -1]
    assert rec.channels[-1].name == "enc_elbow" and rec.channels[-1].unit == "deg"
    np.testing.assert_allclose(enc, ELBOW_SWEEP.pose_at(rec.trajectory.s(rec.t_s))["theta_deg"],
                               atol=360 / 4096 / 2 + 1e-9)
    peak_deg_per_s = 150 / 2 * 2 * np.pi / 20                          # at t = 5 s, a quarter period
    assert rec.harmonic_hz(np.array([5.0]))[0, 0] == pytest.approx(36 * 100 * peak_deg_per_s / 360)


def test_moving_source_streams_counts_of_a_sweep_that_loops():
    src = sim_source(None, "moving", 256.0)
    assert [c.kind for c in src.channels][-1] == "encoder"
    deg = src.physical(0, src.counts.shape[0])[:, -1]
    assert deg.min() == pytest.approx(0.0, abs=0.1) and deg.max() == pytest.approx(150.0, abs=0.1)
    assert abs(deg[-1] - deg[0]) < 0.1                                    # the record loops seamlessly
    assert np.abs(src.counts[:, :-1]).max() < 2**15 - 1                    # no clipping of the accelerometers


def test_session_example_records_the_moving_arm_over_serial(tmp_path):
    """examples/sessions/serial-moving-sim.toml: `acquire` starts `sim serve --test moving`, stores the
    accelerometers and the elbow encoder as an operational run whose pose comes from the encoder; the
    encoder follows the simulated sweep from its start (0 deg, at rest) to the exact counts."""
    from flexmodal.daq.acquire import acquire
    from flexmodal.daq.session import load_session
    from flexmodal.daq.store import read_run
    from flexmodal.fixtures.sim_source import MOVING_PERIOD_S, MOVING_SPAN_DEG

    example = Path(__file__).resolve().parents[1] / "examples" / "sessions" / "serial-moving-sim.toml"
    session = tmp_path / "serial-moving-sim.toml"
    session.write_text(example.read_text().replace('"../rigs/demo_arm.toml"', f'"{DEMO_RIG}"'))
    out = tmp_path / "moving.h5"
    acquire(load_session(session), out, duration_s=3.0, quiet=True, run_id="m1")
    run = read_run(out, "m1")
    names = [c.name for c in run.channels]
    assert names == ["a1", "a2", "a3", "a4", "a5", "enc_elbow"] and run.excitation == "operational"
    enc = run.samples[:, -1]
    first = next(iter(json.loads(run.attrs["first_index"]).values()))  # the device's sample index of row 0
    t = (first + np.arange(enc.size)) / run.sample_rate_hz
    expected = MOVING_SPAN_DEG * 0.5 * (1 - np.cos(2 * np.pi * t / MOVING_PERIOD_S))
    np.testing.assert_allclose(enc, expected, atol=360 / 4096)         # one count
    assert run.pose["theta_deg"] == pytest.approx(enc.mean())           # pose_from: the encoder's mean


def test_tool_arm_modes_veer_along_the_elbow_sweep():
    """fixtures/rigs/tool_arm.toml (the veering case of docs/oma.md): along the elbow sweep the truth
    model's modes near 75-115 Hz stay >= 14 Hz apart while their shapes exchange — the lower mode at 0
    deg is the upper one at 150 deg — and the path's modes, followed by MAC from pose to pose, are the
    frequency-sorted ones (a veering, not a crossing)."""
    from flexmodal.fixtures.moving_arm import TOOL_RIG, path_modes

    rig = load_rig(TOOL_RIG)
    inputs = [(j.name, "rotation") for j in rig.joints] + [("link1@0.05", "transverse")]
    modes = path_modes(rig, ELBOW_SWEEP, inputs, 460.0, grid=31)
    f = modes.freq_hz
    np.testing.assert_array_equal(np.argsort(f, axis=1), np.tile(np.arange(f.shape[1]), (f.shape[0], 1)))
    pair = [k for k in range(f.shape[1]) if 70 < f[0, k] < 120]
    assert len(pair) == 2 and np.min(f[:, pair[1]] - f[:, pair[0]]) > 14.0
    lo0, lo1, hi1 = modes.shapes[0][:, pair[0]], modes.shapes[-1][:, pair[0]], modes.shapes[-1][:, pair[1]]

    def mac(a, b):
        return (a @ b) ** 2 / ((a @ a) * (b @ b))

    assert mac(lo0, hi1) > 0.95 and mac(lo0, lo1) < 0.5
