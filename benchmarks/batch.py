"""Benchmark: `flexmodal frf` on many runs, serial against 2 worker processes, as whole processes.

Writes ``--runs`` files (default 1, 8 and 100) of one random run each (1 force + 16 accelerations,
``--duration-s`` at 5 kHz, float32, the run store's layout) into a temporary folder, then times, per
round and in this order: serial on one CPU (``--workers 0`` with the process pinned to one CPU: the
reference), ``--workers 0`` (serial here, FFT threads on the idle CPUs), the default (serial or a
pool as the measured cost decides) and ``--workers 2`` (a pool of 2 local processes).  Prints
medians and spread (min-max) over ``--repeat`` rounds (one count per ``--runs`` entry, default 3, 3
and 1), the ratios against the one-CPU serial run and against ``--workers 0`` of the same rounds,
and the CPUs the serial and default processes kept busy (CPU time over wall time; the pool's workers
are the fork server's children, not counted); first the figures of the automatic choice's cost
model (COST: CPU per run and per byte, per-task overhead of a pool, CPU of a pool's start, the figure
behind ``modal.batch.POOL_START_S``), last the wall a pool adds (``--workers 2`` less ``--workers 0``
on two 1 s runs).  The machine
may be shared: read the ratios, and the load average printed with them.
Usage: ``python benchmarks/batch.py [--runs 1 8 100] [--duration-s 60] [--repeat 3 3 1] [--folder DIR]``
"""

from __future__ import annotations

import argparse
import os
import resource
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


def _one_cpu() -> None:
    """In the child before it starts: run on the first CPU of this process's mask only."""
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def _frf_process(paths: list[str], extra: list[str], out: str) -> tuple[float, float]:
    """Wall time and CPU time (s; the process and its worker processes) of one whole `flexmodal frf`
    process over ``paths`` writing into ``out`` (``extra`` ONE_CPU: ``--workers 0`` on one CPU)."""
    if os.path.exists(out):
        os.remove(out)
    pin = extra is ONE_CPU
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "flexmodal", "--quiet", "frf", *paths, "--nfft", "4096",
                    "--out", out, *extra], check=True, timeout=3600, stdout=subprocess.DEVNULL,
                   preexec_fn=_one_cpu if pin else None)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


ONE_CPU = ["--workers", "0"]
SERIAL = "serial (--workers 0)"
CASES = {"serial on 1 CPU": ONE_CPU, SERIAL: ["--workers", "0"], "default (by cost)": [],
         "--workers 2 (pool)": ["--workers", "2"]}


def bench(paths: list[str], repeat: int, folder: str) -> None:
    times: dict[str, list[tuple[float, float]]] = {name: [] for name in CASES}
    out = os.path.join(folder, "frf_out.h5")
    load = os.getloadavg()[0]
    for _ in range(repeat):
        for name, extra in CASES.items():
            times[name].append(_frf_process(paths, extra, out))
    wall = {name: np.array(ts)[:, 0] for name, ts in times.items()}
    print(f"BATCH {len(paths)} runs of {os.path.getsize(paths[0]) / 1e6:.0f} MB, nfft 4096 (load average "
          f"{load:.1f} before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} CPUs; ratios per round, "
          f"median):")
    for name, ts in times.items():
        cpu = np.array(ts)[:, 1]
        busy = "pool workers not counted" if "pool" in name else f"{np.median(cpu / wall[name]):.2f}"
        one = np.median(wall["serial on 1 CPU"] / wall[name])
        here = np.median(wall[SERIAL] / wall[name])
        print(f"     {name:22s} median {np.median(wall[name]):7.2f} s (spread {min(wall[name]):.2f}-"
              f"{max(wall[name]):.2f} s), serial on 1 CPU / this = {one:.2f}x, --workers 0 / this = "
              f"{here:.2f}x, CPUs busy {busy}")


def pool_start_up(folder: str, repeat: int) -> None:
    """Wall time `--workers 2` adds to `--workers 0` on two 1 s runs: starting the pool's fork server
    and its 2 processes, their imports and first tasks."""
    paths = write_runs(folder, 2, 1.0)
    out = os.path.join(folder, "frf_out.h5")
    extra = []
    for _ in range(repeat):
        pool = _frf_process(paths, ["--workers", "2"], out)[0]
        extra.append(pool - _frf_process(paths, ["--workers", "0"], out)[0])
    for path in paths:
        os.remove(path)
    print(f"POOL start-up of 2 local processes (--workers 2 less --workers 0 on two 1 s runs): median "
          f"{np.median(extra):.2f} s (spread {min(extra):.2f}-{max(extra):.2f} s)")


COST = """
import os, sys, time
import numpy as np
from flexmodal.modal.batch import _Pool, frf_job
from flexmodal.modal.runs_io import write_frf
path, rid, repeat = sys.argv[1], sys.argv[2], int(sys.argv[3])
options = {"nfft": 4096, "workers": 1}
cpu, writes = [], []
for k in range(repeat + 1):
    c0 = time.process_time()
    result = frf_job(path, rid, options)
    c1 = time.process_time()
    write_frf(path + ".out.h5", f"r{k}", result)
    cpu.append(c1 - c0)
    writes.append(time.process_time() - c1)
os.remove(path + ".out.h5")
here, write = float(np.median(cpu[1:])), float(np.median(writes[1:]))   # the first also imports
pool = _Pool(1, options)
try:
    pool.submit((path, rid)).result()       # started, warm
    walls = []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        pool.submit((path, rid)).result()
        walls.append((time.perf_counter() - t0, time.process_time() - c0))
finally:
    pool.close(kill=False)
wall, parent = np.median(np.array(walls), axis=0)
print(here, wall, parent, write)
"""


def cost(folder: str, duration_s: float, repeat: int) -> None:
    """The figures of the automatic choice's cost model (modal.batch): CPU of one run of
    ``duration_s`` in-process (one FFT thread, per byte of samples); the round trip of the same run
    through a warm pool of one process (its wall less the run's CPU: the per-task overhead when the
    worker's CPU is idle; and the CPU the caller spends per task: sending, receiving, unpickling the
    result); the CPU of writing its FRFs (the caller's, whatever computed them); the CPU of
    starting the pool (its fork server's imports: ``python -c 'import flexmodal.modal.batch'``), the
    figure behind ``modal.batch.POOL_START_S``."""
    path = write_runs(folder, 1, duration_s)[0]
    out = subprocess.run([sys.executable, "-c", COST, path, "r0", str(repeat)], check=True, timeout=600,
                         capture_output=True, text=True).stdout.split()
    here, wall, parent, write = (float(v) for v in out)
    starts = []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-c", "import flexmodal.modal.batch"], check=True, timeout=600)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        starts.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    size = os.path.getsize(path)
    os.remove(path)
    print(f"COST one run of {duration_s:g} s ({size / 1e6:.0f} MB, 17 channels) in-process: {here:.3f} s CPU "
          f"({here / size * 1e9:.2f} ns per byte); through a warm 1-process pool: {wall:.3f} s wall "
          f"(per-task overhead {wall - here:+.3f} s), caller's CPU per task {parent:.4f} s; writing its FRFs "
          f"{write:.4f} s CPU; pool start "
          f"(fork server's imports): {np.median(starts):.2f} s CPU ({min(starts):.2f}-{max(starts):.2f}); "
          f"medians of {repeat}, load average {os.getloadavg()[0]:.1f}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, nargs="+", default=[1, 8, 100])
    p.add_argument("--duration-s", type=float, default=60.0)
    p.add_argument("--repeat", type=int, nargs="+", default=[3, 3, 1], help="rounds per --runs entry")
    p.add_argument("--folder", default=None, help="where the run files go (default: a temporary folder)")
    a = p.parse_args(argv)
    folder = tempfile.mkdtemp(prefix="flexmodal-batch-", dir=a.folder)
    try:
        cost(folder, a.duration_s, max(3, a.repeat[0]))
        for n_runs, repeat in zip(a.runs, a.repeat + a.repeat[-1:] * len(a.runs), strict=False):
            paths = write_runs(folder, n_runs, a.duration_s)
            bench(paths, repeat, folder)
            for path in paths:
                os.remove(path)
        pool_start_up(folder, a.repeat[0])
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
