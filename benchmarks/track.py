"""Tracking the modes of a moving arm: the figures of docs/oma.md's tracking section.

1. Accuracy: the demo arm's elbow sweeping 0 -> 150 -> 0 deg in 90 s (fixtures/moving_arm.py, 1024 Hz,
   seed 3) with motor/gear harmonics of motor orders 36, 80 and 260 (gear ratio 100): per tracked mode,
   the share of all windows where it is tracked within 1 % of the truth model's frozen-pose frequency
   (solved at poses 2.5 deg apart, linear between), the largest frequency error (a swap would show as
   tens of %), the share of its window estimates with damping within 30 % of the truth where the
   window holds >= 50 periods (median error), and the same two shares over the modal map's pose bins;
   the harmonic orders found against those simulated, and how many tracks follow a harmonic.
   The same for the two-joint path (the wrist arm), the veering case (the tool arm) and true crossings
   (two arms on one rigid bench sweeping opposite ways: which branch, and which arm, each track follows).
2. Diagnosis: the demo arm with a hidden compliant elbow, `diagnose` on the tracked map of one sweep and
   on a frozen-pose campaign of operational records: verdict, fitted stiffness, held-out error.
3. Speed (``--speed [MINUTES]``): a 10-minute (or MINUTES) 16-channel record of the same sweep (16
   accelerometers along the arm, 1024 Hz) tracked in one process (one BLAS thread in SSI); its CPU time
   against real time (the wall time on the shared 2-core machine depends on the other users).

Prints markdown table rows; tests/test_track_docs.py checks that every row of parts 1-2 stands in
docs/oma.md (one slow test per table: about 30-70 s of CPU each, so tens of minutes at a load of 10+).
Usage: ``OPENBLAS_CORETYPE=Haswell OPENBLAS_NUM_THREADS=1 python benchmarks/track.py [--speed [MINUTES]]``
(docs/oma.md's kernel: under another kernel a figure at its rounding edge may move).
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np

from flexmodal.fixtures.moving_arm import (
    ELBOW_SWEEP,
    TOOL_RIG,
    WRIST_PATH,
    WRIST_RIG,
    Trajectory,
    frozen_truth,
    simulate_moving,
)
from flexmodal.fixtures.rig_sim import DEMO_RIG
from flexmodal.modal.track import TrackOptions, track_modes
from flexmodal.models.rig import Point, Sensor, load_rig

MOTOR_ORDERS = (36.0, 80.0, 260.0)
FMAX_HZ = 400.0


def _track(rec, fmax_hz: float = FMAX_HZ, **options):
    names, kinds = [c.name for c in rec.channels], [c.kind for c in rec.channels]
    return track_modes(rec.samples, rec.sample_rate_hz, names, kinds, rec.pose_from,
                       TrackOptions(fmax=fmax_hz, **options))


def _path_parameter(path: Trajectory, pose) -> float:
    """Where on the path (0..1) a pose lies, from its most moving variable."""
    v = max(path.start, key=lambda u: abs(path.end[u] - path.start[u]))
    return (pose[v] - path.start[v]) / (path.end[v] - path.start[v])


def accuracy_rows(rig_path=DEMO_RIG, path: Trajectory = ELBOW_SWEEP, fmax_hz: float = FMAX_HZ, seed: int = 3,
                  label: str = "elbow sweep 0-150-0 deg in 90 s", **track) -> list[str]:
    """Per tracked mode: windows within 1 % (share of all windows), largest error, damping within 30 % in
    windows holding >= 50 periods (median error; share of estimates within 2x the closed-form bound),
    map bins within 1 %, map bins with damping within 30 % (median error); then the harmonics."""
    return _accuracy(rig_path, path, fmax_hz, seed, label, MOTOR_ORDERS, **track)[0]


def _accuracy(rig_path, path: Trajectory, fmax_hz: float, seed: int, label: str, orders, **track):
    from flexmodal.modal.track import damping_bound

    rig = load_rig(rig_path)
    rec = simulate_moving(rig, path, sample_rate_hz=1024.0, orders=orders, seed=seed)
    res = _track(rec, fmax_hz, **track)
    span = max(abs(path.end[v] - path.start[v]) for v in path.start)
    s_grid = np.linspace(0.0, 1.0, int(round(span / 2.5)) + 1)   # frozen-pose truth every 2.5 deg
    poses = path.pose_at(s_grid)
    truth = [frozen_truth(rig, {v: float(p[g]) for v, p in poses.items()}, fmax_hz)
             for g in range(s_grid.size)]
    n_true = min(t[0].size for t in truth)
    f_grid, z_grid = np.array([t[0][:n_true] for t in truth]), np.array([t[1][:n_true] for t in truth])
    rows = [f"| {label} | {len(res.windows)} windows of {res.window_s:.2f} s every "
            f"{res.hop_s:.2f} s, {res.skipped} skipped | {len(res.tracks)} modes tracked | | | |"]
    table = res.table
    for k, tr in enumerate(res.tracks):
        s_win = np.array([_path_parameter(path, res.windows[i].pose) for i in tr.windows])
        truth_k = np.array([np.interp(s_win, s_grid, f_grid[:, r]) for r in range(n_true)]).T
        r = int(np.argmin(np.median(np.abs(tr.freq_hz[:, None] / truth_k - 1), axis=0)))   # the truth's mode
        f_true, z_true = truth_k[:, r], np.interp(s_win, s_grid, z_grid[:, r])
        err = np.abs(tr.freq_hz / f_true - 1)
        held = f_true * res.window_s >= 50
        zerr = np.abs(tr.damping_ratio / z_true - 1)[held]
        bound = (damping_bound(tr.freq_hz, tr.damping_ratio, tr.span_s)[held] if tr.span_s.size
                 else np.full(zerr.size, np.inf))
        rows_k = table.frame[table.frame["mode"] == k + 1]
        s_bins = np.array([_path_parameter(path, {v: row[f"pose.{v}"] for v in path.start})
                           for _, row in rows_k.iterrows()])
        map_f = np.abs(rows_k["freq_hz"].to_numpy() / np.interp(s_bins, s_grid, f_grid[:, r]) - 1)
        map_z = np.abs(rows_k["damping_ratio"].to_numpy() / np.interp(s_bins, s_grid, z_grid[:, r]) - 1)
        covered = np.sum(err < 0.01) / len(res.windows)
        rows.append(f"| mode {k + 1} ({f_grid[:, r].min():.0f}-{f_grid[:, r].max():.0f} Hz) | {covered:.0%} "
                    f"| {err.max():.1%} | {np.mean(zerr < 0.3):.0%} ({np.median(zerr):.0%}; "
                    f"{np.mean(zerr < 2 * bound):.0%} within 2 sigma; {np.median(tr.span_s):.1f} s) "
                    f"| {np.mean(map_f < 0.01):.0%} of {len(rows_k)} "
                    f"| {np.mean(map_z < 0.3):.0%} ({np.median(map_z):.0%}) |")
    if not orders:
        return rows, res
    simulated = np.array(orders) * rec.gear_ratio
    on_harmonic = 0
    for tr in res.tracks:
        speed = np.array([[abs(res.windows[i].rate_deg_per_s[v]) / 360 for v in rec.driven]
                          for i in tr.windows])
        near = np.abs(tr.freq_hz[:, None, None] - speed[:, :, None] * simulated[None, None, :]) < 0.02 * \
            tr.freq_hz[:, None, None]
        on_harmonic += int(near.any(axis=(1, 2)).mean() > 0.5)
    found = "; ".join(f"{v}: {', '.join(f'{o:.0f}' for o in sorted(res.orders[v]))}" for v in rec.driven)
    rows.append(f"| harmonics (orders {', '.join(f'{o:.0f}' for o in simulated)} per joint rev) | found "
                f"{found} ({len(res.harmonics)} harmonic poles) | {on_harmonic} reported as modes | | | |")
    return rows, res


def two_joint_rows() -> list[str]:
    """The two-joint path: the wrist arm (the demo arm with a wrist) along WRIST_PATH, modes below 450 Hz,
    the windows sized by tracking itself (80 periods of the slowest mode it finds, 18-25 Hz)."""
    return accuracy_rows(WRIST_RIG, WRIST_PATH, 450.0, seed=11,
                         label="elbow 0-120-0 deg with wrist 0-(-90)-0 deg in 120 s")


def veering_rows() -> list[str]:
    """The veering case: the tool arm (TOOL_RIG) along the elbow sweep, no harmonics, windows sized for
    its slowest mode (36-44 Hz) by ``fmin`` = 30 Hz; the accuracy rows
    (a track that swapped branches would show errors of tens of %) and the MAC of each of the two
    veering tracks' shapes at the sweep's two ends (their shapes exchange along the branch)."""
    from flexmodal.contract.mac import mac

    rows, res = _accuracy(TOOL_RIG, ELBOW_SWEEP, FMAX_HZ, 13, "veering: tool arm, elbow sweep 0-150-0 deg in "
                          "90 s, no harmonics", (), fmin=30.0)
    ends = []
    for k, tr in enumerate(res.tracks):
        if not 70 < np.median(tr.freq_hz) < 120:
            continue
        theta = np.array([res.windows[i].pose["theta_deg"] for i in tr.windows])
        first, last = tr.shapes[:, np.argmin(theta)], tr.shapes[:, np.argmax(theta)]
        ends.append(f"mode {k + 1}: {float(mac(first[:, None], last[:, None])[0, 0]):.2f}")
    rows.append(f"| MAC of a veering track's shapes at 0 and 150 deg | {'; '.join(ends)} | | | | |")
    return rows


def crossing_rows(seed: int = 17) -> list[str]:
    """True crossings: two demo arms on one rigid bench (fixtures.moving_arm.simulate_two_arms), the first's
    elbow sweeping 0 -> 150 -> 0 deg while the second's sweeps 150 -> 0 -> 150 deg in 90 s, no harmonics;
    nothing couples them, so each of the three modes of one arm crosses the same mode of the other where
    the poses meet (75 deg, at 22.5 and 67.5 s).  Per track: the branch it follows (arm and mode, the truth
    model's frozen-pose modes of each arm at the window's pose of that arm), the share of all windows
    within 1 % of that branch, the largest error, the share of its windows whose shape lies mostly on
    that arm's sensors (a swap would put it on the other's), and the crossings it runs through."""
    from flexmodal.fixtures.moving_arm import CROSSING, SECOND, simulate_two_arms

    rig = load_rig(DEMO_RIG)
    bench = simulate_two_arms(rig, ELBOW_SWEEP, CROSSING, sample_rate_hz=1024.0, seed=seed)
    names, kinds = [c.name for c in bench.channels], [c.kind for c in bench.channels]
    res = track_modes(bench.samples, bench.sample_rate_hz, names, kinds, bench.pose_from,
                      TrackOptions(fmax=FMAX_HZ))
    arm_b = np.array([n.startswith(SECOND) for n in res.outputs])
    truth = {}   # (arm, theta) -> frozen-pose frequencies, solved once per window pose
    rows = [f"| crossing: two demo arms on a rigid bench, elbows 0-150-0 and 150-0-150 deg in 90 s, no "
            f"harmonics | {len(res.windows)} windows of {res.window_s:.2f} s every {res.hop_s:.2f} s, "
            f"{res.skipped} skipped | {len(res.tracks)} modes tracked | | |"]
    for k, tr in enumerate(res.tracks):
        f_true = []
        for i in tr.windows:   # a loop over the track's windows: both arms' truth at their poses
            pose = res.windows[i].pose
            row = []
            for arm, var in (("A", "theta_deg"), ("B", SECOND + "theta_deg")):
                key = (arm, round(pose[var], 1))
                if key not in truth:
                    truth[key] = frozen_truth(rig, {"theta_deg": key[1]}, FMAX_HZ)[0][:3]
                row.append(truth[key])
            f_true.append(np.concatenate(row))
        err = np.abs(tr.freq_hz[:, None] / np.array(f_true) - 1)   # [windows, 6 branches]
        branch = int(np.argmin(np.median(err, axis=0)))
        arm = "AB"[branch // 3]
        on_arm = np.sum(tr.shapes[arm_b] ** 2, axis=0) / np.sum(tr.shapes ** 2, axis=0)
        on_arm = on_arm if arm == "B" else 1 - on_arm
        t = np.array([res.windows[i].t_s for i in tr.windows])
        crossed = sum(int(t.min() < c - res.window_s and t.max() > c + res.window_s) for c in (22.5, 67.5))
        f_b = np.array(f_true)[:, branch]
        rows.append(f"| mode {k + 1}: arm {arm} mode {branch % 3 + 1} ({f_b.min():.0f}-{f_b.max():.0f} Hz) "
                    f"| {np.sum(err[:, branch] < 0.01) / len(res.windows):.0%} | {err[:, branch].max():.1%} "
                    f"| {np.mean(on_arm > 0.5):.0%} on arm {arm}'s sensors | {crossed} of 2 crossings |")
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


def speed_rows(duration_s: float = 600.0) -> list[str]:
    rig = load_rig(DEMO_RIG)
    spots = [("link1", f) for f in np.linspace(0.1, 1.0, 6)] + [("link2", f)
                                                                 for f in np.linspace(0.1, 1.0, 10)]
    rig16 = dataclasses.replace(rig, sensors=tuple(Sensor(f"s{i + 1}", Point(link, float(f)))
                                                   for i, (link, f) in enumerate(spots)))
    rec = simulate_moving(rig16, Trajectory({"theta_deg": 0.0}, {"theta_deg": 150.0}, 90.0),
                          duration_s=duration_s, sample_rate_hz=1024.0, orders=MOTOR_ORDERS, seed=4)
    t0, c0 = time.perf_counter(), time.process_time()
    res = _track(rec)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return [f"| {duration_s / 60:g} min x 16 channels at 1024 Hz | {len(res.windows)} windows, "
            f"{len(res.tracks)} modes | CPU {cpu:.0f} s = {cpu / duration_s:.2f} x real time "
            f"(wall {wall:.0f} s on the shared machine) |"]

if __name__ == "__main__":
    print("\n".join(accuracy_rows()))
    print("\n".join(two_joint_rows()))
    print("\n".join(veering_rows()))
    print("\n".join(crossing_rows()))
    print("\n".join(diagnosis_rows()))
    if "--speed" in sys.argv[1:]:   # --speed [minutes], default 10
        rest = sys.argv[sys.argv.index("--speed") + 1:]
        print("\n".join(speed_rows(60.0 * float(rest[0]) if rest else 600.0)))
