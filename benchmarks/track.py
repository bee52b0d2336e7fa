"""Tracking the modes of a moving arm: the figures of docs/oma.md's tracking section.

1. Accuracy: the demo arm's elbow sweeping 0 -> 150 -> 0 deg in 90 s (fixtures/moving_arm.py, 1024 Hz,
   seed 3) with motor/gear harmonics of motor orders 36, 80 and 260 (gear ratio 100): per tracked mode,
   the share of all windows where it is tracked within 1 % of the truth model's frozen-pose frequency
   (solved afresh at the window's pose), the share of its estimates with damping within 30 % of the
   truth, the largest frequency error (a swap would show as tens of %); the harmonic orders found
   against those simulated, and how many tracks follow a harmonic.
2. Speed (``--speed``): a 10-minute 16-channel record of the same sweep (16 accelerometers along the
   arm, 1024 Hz) tracked on one process; time against real time.

Prints markdown table rows; tests/test_track_docs.py checks that every row of part 1 stands in
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
    rows = [f"| elbow sweep | windows {len(res.windows)} of {res.window_s:.2f} s every {res.hop_s:.2f} s, "
            f"{res.skipped} skipped | {len(res.tracks)} modes tracked |"]
    for k, tr in enumerate(res.tracks):
        theta = np.array([res.windows[i].pose["theta_deg"] for i in tr.windows])
        f_true, z_true = np.interp(theta, grid, f_grid[:, k]), np.interp(theta, grid, z_grid[:, k])
        err = np.abs(tr.freq_hz / f_true - 1)
        periods = f_true * res.window_s
        zerr = np.abs(tr.damping_ratio / z_true - 1)[periods >= 50]
        rows.append(f"| mode {k + 1} ({f_true.min():.0f}-{f_true.max():.0f} Hz) | within 1 % over "
                    f"{np.sum(err < 0.01) / len(res.windows):.0%} of the sweep | damping within 30 % in "
                    f"{np.mean(zerr < 0.3):.0%} of its windows (median error {np.median(zerr):.0%}) | "
                    f"largest error {err.max():.1%} |")
    found = np.sort(np.array(res.orders["theta_deg"]))
    simulated = np.array(MOTOR_ORDERS) * rec.gear_ratio
    on_harmonic = 0
    for tr in res.tracks:
        speed = np.array([abs(res.windows[i].rate_deg_per_s["theta_deg"]) / 360 for i in tr.windows])
        near = np.abs(tr.freq_hz[:, None] / (speed[:, None] * simulated[None, :]) - 1) < 0.02
        on_harmonic += int(near.any(axis=1).mean() > 0.5)
    rows.append(f"| harmonics (orders {', '.join(f'{o:.0f}' for o in simulated)} per joint rev) | found "
                f"{', '.join(f'{o:.0f}' for o in found)} ({len(res.harmonics)} harmonic poles) | "
                f"{on_harmonic} reported as modes |")
    return rows


def speed_rows() -> list[str]:
    rig = load_rig(DEMO_RIG)
    spots = [("link1", f) for f in np.linspace(0.1, 1.0, 6)] + [("link2", f) for f in np.linspace(0.1, 1.0, 10)]
    rig16 = dataclasses.replace(rig, sensors=tuple(Sensor(f"s{i + 1}", Point(link, float(f)))
                                                   for i, (link, f) in enumerate(spots)))
    rec = simulate_moving(rig16, Trajectory({"theta_deg": 0.0}, {"theta_deg": 150.0}, 90.0), duration_s=600.0,
                          sample_rate_hz=1024.0, orders=MOTOR_ORDERS, seed=4)
    t0 = time.perf_counter()
    res = _track(rec)
    dt = time.perf_counter() - t0
    return [f"| 10 min x 16 channels at 1024 Hz | {len(res.windows)} windows, {len(res.tracks)} modes | "
            f"{dt:.0f} s = {dt / 600:.2f} x real time |"]


if __name__ == "__main__":
    print("\n".join(accuracy_rows()))
    if "--speed" in sys.argv[1:]:
        print("\n".join(speed_rows()))
