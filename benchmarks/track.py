"""Tracking the modes of a moving arm: the figures of docs/oma.md's tracking section.

1. Accuracy: the demo arm's elbow sweeping 0 -> 150 -> 0 deg in 90 s (fixtures/moving_arm.py, 1024 Hz,
   seed 3) with motor/gear harmonics of motor orders 36, 80 and 260 (gear ratio 100): per tracked mode,
   the share of all windows where it is tracked within 1 % of the truth model's frozen-pose frequency
   (solved at poses 2.5 deg apart, linear between), the largest frequency error (a swap would show as
   tens of %), the share of its window estimates with damping within 30 % of the truth where the
   window holds >= 50 periods (median error), and the same two shares over the modal map's pose bins;
   the harmonic orders found against those simulated, and how many tracks follow a harmonic.
2. Diagnosis: the demo arm with a hidden compliant elbow, `diagnose` on the tracked map of one sweep and
   on a frozen-pose campaign of operational records: verdict, fitted stiffness, held-out error.
3. Speed (``--speed``): a 10-minute 16-channel record of the same sweep (16 accelerometers along the
   arm, 1024 Hz) tracked in one process (one BLAS thread in SSI); its CPU time against real time (the
   wall time on the shared 2-core machine depends on the other users).

Prints markdown table rows; tests/test_track_docs.py checks that every row of parts 1-2 stands in
docs/oma.md.  Usage: ``python benchmarks/track.py [--speed]``.
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np

from flexmodal.fixtures.moving_arm import ELBOW_SWEEP, Trajectory, frozen_truth, simulate_moving
from flexmodal.fixtures.rig_sim import DEMO_RIG
from flexmodal.modal.track import TrackOptions, track_modes
from flexmodal.models.rig import Point, Sensor, load_rig

MOTOR_ORDERS = (36.0, 80.0, 260.0)
FMAX_HZ = 400.0


def _track(rec):
    names, kinds = [c.name for c in rec.channels], [c.kind for c in rec.channels]
    return track_modes(rec.samples, rec.sample_rate_hz, names, kinds, {"theta_deg": "enc_elbow"},
                       TrackOptions(fmax=FMAX_HZ))


def accuracy_rows() -> list[str]:
    rig = load_rig(DEMO_RIG)
    rec = simulate_moving(rig, ELBOW_SWEEP, sample_rate_hz=1024.0, orders=MOTOR_ORDERS, seed=3)
    res = _track(rec)
    grid = np.arange(0.0, 150.1, 2.5)
    truth = [frozen_truth(rig, {"theta_deg": th}, FMAX_HZ) for th in grid]
    f_grid, z_grid = np.array([t[0] for t in truth]), np.array([t[1] for t in truth])
    rows = [f"| elbow sweep 0-150-0 deg in 90 s | {len(res.windows)} windows of {res.window_s:.2f} s every "
            f"{res.hop_s:.2f} s, {res.skipped} skipped | {len(res.tracks)} modes tracked | | | |"]
    table = res.table
    for k, tr in enumerate(res.tracks):
        theta = np.array([res.windows[i].pose["theta_deg"] for i in tr.windows])
        f_true, z_true = np.interp(theta, grid, f_grid[:, k]), np.interp(theta, grid, z_grid[:, k])
        err = np.abs(tr.freq_hz / f_true - 1)
        zerr = np.abs(tr.damping_ratio / z_true - 1)[f_true * res.window_s >= 50]
        rows_k = table.frame[table.frame["mode"] == k + 1]
        theta_bins = rows_k["pose.theta_deg"].to_numpy()
        map_f = np.abs(rows_k["freq_hz"].to_numpy() / np.interp(theta_bins, grid, f_grid[:, k]) - 1)
        map_z = np.abs(rows_k["damping_ratio"].to_numpy() / np.interp(theta_bins, grid, z_grid[:, k]) - 1)
        covered = np.sum(err < 0.01) / len(res.windows)
        rows.append(f"| mode {k + 1} ({f_true.min():.0f}-{f_true.max():.0f} Hz) | {covered:.0%} "
                    f"| {err.max():.1%} | {np.mean(zerr < 0.3):.0%} ({np.median(zerr):.0%}) "
                    f"| {np.mean(map_f < 0.01):.0%} of {len(rows_k)} "
                    f"| {np.mean(map_z < 0.3):.0%} ({np.median(map_z):.0%}) |")
    found = np.sort(np.array(res.orders["theta_deg"]))
    simulated = np.array(MOTOR_ORDERS) * rec.gear_ratio
    on_harmonic = 0
    for tr in res.tracks:
        speed = np.array([abs(res.windows[i].rate_deg_per_s["theta_deg"]) / 360 for i in tr.windows])
        near = np.abs(tr.freq_hz[:, None] / (speed[:, None] * simulated[None, :]) - 1) < 0.02
        on_harmonic += int(near.any(axis=1).mean() > 0.5)
    rows.append(f"| harmonics (orders {', '.join(f'{o:.0f}' for o in simulated)} per joint rev) | found "
                f"{', '.join(f'{o:.0f}' for o in found)} ({len(res.harmonics)} harmonic poles) | "
                f"{on_harmonic} reported as modes | | | |")
    return rows


def diagnosis_rows() -> list[str]:
    """The demo arm with its hidden compliant elbow (fixtures.demo.DEMO_EFFECTS): `diagnose` on the tracked
    map of one sweep against `diagnose` on a frozen-pose campaign (60 s operational records at 0, 25,
    ..., 150 deg, SSI-cov; a pose whose record yields fewer than the three modes is left out, as a lab
    would repeat it)."""
    import pandas as pd

    from flexmodal.compare.diagnosis import diagnose
    from flexmodal.contract.table import ModalTable
    from flexmodal.fixtures.demo import DEMO_EFFECTS
    from flexmodal.fixtures.rig_sim import simulate
    from flexmodal.fixtures.truth_arm import bench_arm
    from flexmodal.modal.identify import modes_table
    from flexmodal.modal.oma import identify_output_only

    rig = load_rig(DEMO_RIG)
    rec = simulate_moving(rig, ELBOW_SWEEP, sample_rate_hz=1024.0, orders=MOTOR_ORDERS, seed=7,
                          effects=DEMO_EFFECTS)
    tracked = diagnose(rig, _track(rec).table)
    frames, left_out = [], []
    for k, theta in enumerate(range(0, 151, 25)):   # a loop over the campaign's poses
        op = simulate(rig, {"theta_deg": float(theta)}, excitation="operational", duration_s=60.0,
                      sample_rate_hz=1024.0, effects=DEMO_EFFECTS, seed=20 + k, truth=bench_arm(rig))
        found, outs = identify_output_only(op.samples, 1024.0, [c.name for c in op.channels],
                                           [c.kind for c in op.channels], fmin=20.0, fmax=FMAX_HZ)
        if found.modes.freq_hz.size == 3:
            frames.append(modes_table(found.modes, outs, config=f"theta{theta}",
                                      pose={"theta_deg": float(theta)}).frame)
        else:
            left_out.append(theta)
    frozen = diagnose(rig, ModalTable.from_frame(pd.concat(frames, ignore_index=True)))
    rows = []
    kept = [str(t) for t in range(0, 151, 25) if t not in left_out]
    campaign = f"frozen campaign, 60 s at {', '.join(kept)} deg"
    for name, d in ((f"tracked map of one 90 s sweep, {len(tracked.configs or ())} pose bins", tracked),
                    (campaign, frozen)):
        v = d.verdict
        rows.append(f"| {name} | {v.effect} at {v.location} | k = {v.params.get('k_Nm_per_rad'):.0f} N m/rad "
                    f"(simulated 8000) | held-out RMS error {v.heldout_rms_rel_error_before:.1%} -> "
                    f"{v.heldout_rms_rel_error_after:.2%} |")
    ratio = tracked.verdict.heldout_rms_rel_error_after / frozen.verdict.heldout_rms_rel_error_after
    rows.append(f"| held-out error, tracked / frozen | {ratio:.2f} | | |")
    return rows


def speed_rows() -> list[str]:
    rig = load_rig(DEMO_RIG)
    spots = [("link1", f) for f in np.linspace(0.1, 1.0, 6)] + [("link2", f)
                                                                 for f in np.linspace(0.1, 1.0, 10)]
    rig16 = dataclasses.replace(rig, sensors=tuple(Sensor(f"s{i + 1}", Point(link, float(f)))
                                                   for i, (link, f) in enumerate(spots)))
    rec = simulate_moving(rig16, Trajectory({"theta_deg": 0.0}, {"theta_deg": 150.0}, 90.0), duration_s=600.0,
                          sample_rate_hz=1024.0, orders=MOTOR_ORDERS, seed=4)
    t0, c0 = time.perf_counter(), time.process_time()
    res = _track(rec)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return [f"| 10 min x 16 channels at 1024 Hz | {len(res.windows)} windows, {len(res.tracks)} modes | "
            f"CPU {cpu:.0f} s = {cpu / 600:.2f} x real time (wall {wall:.0f} s on the shared machine) |"]

if __name__ == "__main__":
    print("\n".join(accuracy_rows()))
    print("\n".join(diagnosis_rows()))
    if "--speed" in sys.argv[1:]:
        print("\n".join(speed_rows()))
