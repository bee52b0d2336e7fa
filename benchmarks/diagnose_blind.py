"""Benchmark of the gap diagnosis: blind accuracy (self-check) and time for 6 poses x 4 modes.

    python benchmarks/diagnose_blind.py [--cases 36] [--seeds 0] [--timing-runs 3] [--advice]

1. Time: seed 003's arm (examples/rigs/seed003_two_link.toml) at its six poses with a hidden joint
   stiffness + joint mass, four modes with shapes at its three sensors; the full diagnosis (every effect at
   every location, pairs of the best eight, leave-one-configuration-out) is timed, wall and CPU, best of
   ``--timing-runs``, and seed 003's Table 3 (6 poses x 2 modes) the same way; with the CPU per fitted
   candidate and per cross-validation fold (issue 28: <= 1.5 s CPU for seed 003, <= 1 s for 6 x 4).
2. Accuracy: ``--cases`` blind cases of fixtures/blind.py (the independent Timoshenko truth model);
   prints one line per case (truth, verdict, right or not, ambiguous, explained, held-out after; the
   table docs/diagnosis.md quotes), then top-1 effect and location accuracy, ``none`` accuracy, the
   held-out gap after a right verdict against 2x the injected scatter and how often effects outside
   the library are flagged, the coverage of the 95 % parameter and prediction intervals; per draw
   (``--seeds 101,102,...``: one draw of the generator each) and their mean and worst.  ``--advice``:
   each ambiguous verdict measured once more at the advised pose and at two random untested poses.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from flexmodal.compare.diagnosis import diagnose  # noqa: E402
from flexmodal.contract.table import ModalTable  # noqa: E402
from flexmodal.fixtures.blind import (  # noqa: E402
    advice_trials,
    format_advice,
    format_draws,
    format_summary,
    format_table,
    run_blind,
    summarise,
)
from flexmodal.models.effects import apply_effect  # noqa: E402
from flexmodal.models.frame import frame_modes  # noqa: E402
from flexmodal.models.rig import load_rig  # noqa: E402


def timing_case(seed: int = 0):
    """Seed 003's rig and six poses x four modes of the rig with a hidden elbow stiffness and mass."""
    rng = np.random.default_rng(seed)
    rig = load_rig(REPO / "examples" / "rigs" / "seed003_two_link.toml")
    real = apply_effect(apply_effect(rig, "joint_stiffness", "elbow", {"k_Nm_per_rad": 3000.0}),
                        "joint_mass", "elbow", {"mass_kg": 0.3, "inertia_kgm2": 2e-4})
    records = []
    for th in (0, 30, 60, 90, 120, 150):
        m = frame_modes(real, {"theta_deg": th}, 4)
        f = m.freq_hz * (1 + 0.005 * rng.standard_normal(4))
        for k in range(4):
            rec = {"config": f"theta{th}", "mode": k + 1, "freq_hz": f[k], "pose.theta_deg": th}
            rec.update({f"shape.{s}": m.sensor_shapes[i, k] for i, s in enumerate(m.sensor_names)})
            records.append(rec)
    return rig, ModalTable.from_records(records, "<benchmark>")


def _time(rig, table, runs: int, label: str) -> None:
    diagnose(rig, table)  # warm-up (imports, caches)
    walls, cpus = [], []
    for _ in range(runs):
        w0, c0 = time.perf_counter(), time.process_time()
        res = diagnose(rig, table)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    v, n = res.verdict, res.n_candidates
    cpu = min(cpus)
    folds = res.holdout.n_folds
    print(f"time, {label}: cpu {cpu:.2f} s (median {np.median(cpus):.2f}, spread {min(cpus):.2f}-"
          f"{max(cpus):.2f}), "
          f"wall {min(walls):.2f} s, best of {runs}; {n.fitted} candidates fitted, {n.cross_validated} "
          f"cross-validated over {folds} folds: {1e3 * cpu / n.fitted:.0f} ms CPU per fitted candidate, "
          f"{1e3 * cpu / (n.cross_validated * folds):.1f} ms per cross-validated fold; verdict "
          f"{v.effect}@{v.location} held-out {v.heldout_rms_rel_error_before:.2%} -> "
          f"{v.heldout_rms_rel_error_after:.2%}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=36)
    ap.add_argument("--seeds", default="0", help="comma-separated generator seeds (one draw each)")
    ap.add_argument("--timing-runs", type=int, default=3)
    ap.add_argument("--advice", action="store_true")
    args = ap.parse_args()

    if args.timing_runs > 0:
        from diagnosis_doc import seed003_table

        _time(*timing_case(), args.timing_runs, "6 poses x 4 modes with shapes")
        _time(load_rig(REPO / "examples" / "rigs" / "seed003_two_link.toml"),
              seed003_table(REPO / "tests" / "data"), args.timing_runs, "seed 003 (6 poses x 2 modes)")
    draws = []
    for seed in [int(x) for x in args.seeds.split(",") if x.strip()] if args.cases > 0 else []:
        results = run_blind(args.cases, seed=seed)
        print(f"draw seed {seed}:")
        print(format_table(results))
        print(format_summary(summarise(results)))
        draws.append(summarise(results))
        if args.advice:
            print(format_advice(advice_trials(results, seed=seed)))
    if len(draws) > 1:
        print(format_draws(draws))
    return 0


if __name__ == "__main__":
    sys.exit(main())
