"""Benchmark: `flexmodal frf` on many runs, serial against 2 worker processes, as whole processes.

Writes ``--runs`` files (default 8 and 100) of one random run each (1 force + 16 accelerations,
``--duration-s`` at 5 kHz, float32, the run store's layout) into a temporary folder, then times, per
round and in this order: ``--workers 0`` (serial, the reference), the default (serial or cluster as
the measured cost decides) and ``--workers 2`` (a LocalCluster of 2 processes).  Prints medians and
spread (min-max) over ``--repeat`` rounds and the ratios against the serial run of the same rounds,
then the start-up cost of the LocalCluster alone (the figure behind ``modal.batch.CLUSTER_START_S``).
The machine may be shared: read the ratios, and the CPU load printed with them.
Usage: ``python benchmarks/batch.py [--runs 8 100] [--duration-s 60] [--repeat 3] [--folder DIR]``
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from memory import write_run  # noqa: E402  (benchmarks/memory.py: the same simulated record)


def write_runs(folder: str, n_runs: int, duration_s: float) -> list[str]:
    """``n_runs`` files of one run each, all holding the same simulated record (so their FRFs are
    the same; the work and the reading are not shared)."""
    paths = [os.path.join(folder, f"run{k:03d}.h5") for k in range(n_runs)]
    for k, path in enumerate(paths):
        write_run(path, duration_s, f"r{k}")
    return paths


def _frf_process(paths: list[str], extra: list[str], out: str) -> float:
    """Wall time (s) of one whole `flexmodal frf` process over ``paths`` writing into ``out``."""
    if os.path.exists(out):
        os.remove(out)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "flexmodal", "--quiet", "frf", *paths, "--nfft", "4096",
                    "--out", out, *extra], check=True, timeout=3600, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def bench(paths: list[str], repeat: int, folder: str) -> None:
    cases = {"serial (--workers 0)": ["--workers", "0"], "default (by cost)": [],
             "--workers 2": ["--workers", "2"]}
    times: dict[str, list[float]] = {name: [] for name in cases}
    out = os.path.join(folder, "frf_out.h5")
    for _ in range(repeat):
        for name, extra in cases.items():
            times[name].append(_frf_process(paths, extra, out))
    ref = np.median(times["serial (--workers 0)"])
    print(f"BATCH {len(paths)} runs of {os.path.getsize(paths[0]) / 1e6:.0f} MB, nfft 4096 "
          f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs):")
    for name, ts in times.items():
        print(f"     {name:22s} median {np.median(ts):7.2f} s (spread {min(ts):.2f}-{max(ts):.2f} s), "
              f"serial / this = {ref / np.median(ts):.2f}x")


def cluster_start_up(repeat: int) -> None:
    """Wall time of a fresh process that imports the batch module, starts its LocalCluster of 2
    processes (no task) and closes it."""
    code = ("import time; t = time.perf_counter()\n"
            "from flexmodal.modal import batch\n"
            "batch._on_cluster([], 0, {}, 2, None, lambda k, r: None)\n"
            "print(time.perf_counter() - t)\n")
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", f"if __name__ == '__main__':\n    exec({code!r})"],
                       check=True, timeout=300, stdout=subprocess.DEVNULL)
        runs.append(time.perf_counter() - t0)
    print(f"CLUSTER start-up + close of a 2-process LocalCluster (whole process): median "
          f"{np.median(runs):.2f} s (spread {min(runs):.2f}-{max(runs):.2f} s)")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, nargs="+", default=[8, 100])
    p.add_argument("--duration-s", type=float, default=60.0)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--folder", default=None, help="where the run files go (default: a temporary folder)")
    a = p.parse_args(argv)
    folder = tempfile.mkdtemp(prefix="flexmodal-batch-", dir=a.folder)
    try:
        for n_runs in a.runs:
            paths = write_runs(folder, n_runs, a.duration_s)
            bench(paths, a.repeat, folder)
            for path in paths:
                os.remove(path)
        cluster_start_up(a.repeat)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
