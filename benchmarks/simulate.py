"""The simulated rig's record (what `flexmodal sim serve` computes before it streams) against its floor.

    python benchmarks/simulate.py [--rates 100000 1000000] [--repeat 3]

For each rate: the CPU of ``fixtures.sim_source.sim_source`` (the demo arm, impact test, 8 s record, 7
channels) per sample, and the floor any exact simulation of that record pays: scipy's ``lfilter`` of
every mode's force over the whole record (two outputs: accelerations and the displacement-like
channels) plus the draw of the record's noise; their ratio, and the cost per sample at the highest rate
over that at the lowest (1.0: linear in the number of samples).  Medians over ``--repeat`` rounds (CPU
time of this process: other load on the machine inflates wall time, not these).
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np
from scipy import signal


def _cpu(fn) -> float:
    t = time.process_time()
    fn()
    return time.process_time() - t


def floor_s(rate_hz: float, n_modes: int, n_channels: int, record_s: float = 8.0) -> float:
    """CPU of the least an exact simulation does: one lfilter per mode and output kind over the whole
    record (a second-order section each) and the record's Gaussian noise."""
    n = int(record_s * rate_hz)
    x = np.random.default_rng(0).standard_normal(n)
    b, a = signal.butter(2, 0.1)

    def least() -> None:
        for _ in range(2 * n_modes):
            signal.lfilter(b, a, x)
        np.random.default_rng(1).standard_normal((n, n_channels))

    return _cpu(least)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rates", type=float, nargs="+", default=[100_000.0, 1_000_000.0])
    p.add_argument("--repeat", type=int, default=3)
    a = p.parse_args(argv)
    from flexmodal.fixtures.sim_source import sim_source

    sim_source(None, "impact", 2048.0)   # imports and the truth model's caches, outside the timing
    per_sample = {}
    for rate in a.rates:
        n = int(8.0 * rate)
        ours, floor = [], []
        for _ in range(a.repeat):
            source = None

            def run(rate=rate) -> None:
                nonlocal source
                source = sim_source(None, "impact", rate)

            ours.append(_cpu(run))
            n_ch = source.counts.shape[1]
            n_modes = _modes_below(rate)
            floor.append(floor_s(rate, n_modes, n_ch))
        o, f = float(np.median(ours)), float(np.median(floor))
        per_sample[rate] = o / n
        print(f"SIM {rate:g} Hz, {n} samples x {n_ch} channels, {n_modes} modes: sim_source {o:.3f} s CPU "
              f"({1e9 * o / n:.0f} ns a sample; rounds {', '.join(f'{x:.2f}' for x in ours)}), floor "
              f"(lfilter x {2 * n_modes} + noise) {f:.3f} s: ratio {o / f:.2f}x; peak RSS so far "
              f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB", flush=True)
    lo, hi = min(per_sample), max(per_sample)
    if hi > lo:
        print(f"LINEARITY cost a sample at {hi:g} Hz / at {lo:g} Hz: {per_sample[hi] / per_sample[lo]:.2f} "
              f"(1.0 = linear in the number of samples)")
    return 0


def _modes_below(rate_hz: float) -> int:
    """How many of the demo arm's truth modes the simulation at ``rate_hz`` keeps (below 0.45 x rate)."""
    from flexmodal.fixtures.rig_sim import DEMO_RIG
    from flexmodal.fixtures.truth_arm import bench_arm, truth_modes
    from flexmodal.models.rig import load_rig

    rig = load_rig(DEMO_RIG)
    tm = truth_modes(rig, {v: 30.0 if v.endswith("_deg") else 0.0 for v in rig.pose_variables}, 12,
                     bench_arm(rig))
    return int(np.sum(tm.freq_hz < 0.45 * rate_hz))


if __name__ == "__main__":
    raise SystemExit(main())
