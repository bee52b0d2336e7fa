"""Benchmark: peak memory and time of `flexmodal frf` on long runs, against the in-memory path.

Writes runs of 1 force + 16 accelerations at 5 kHz, float32, ``--durations`` long (default 600 s and
7200 s: 0.2 GB and 2.4 GB) into ``--folder`` (default the temporary folder), one 60 s simulated
record repeated.  For each: the whole `flexmodal frf` process (nfft 4096, H1 + coherence) in a child
process, its peak RSS (``ru_maxrss`` of the child) and wall time over ``--repeat`` rounds; the ratio
of the time per second of record between the longest and the shortest run (1.0 = linear); and, in
another child process, the FRFs of the same run computed from the samples read whole into memory,
compared with the streamed ones (largest relative difference of H and absolute of coherence).
The files are deleted at the end.  Usage: ``python benchmarks/memory.py [--durations 600 7200]``
"""

from __future__ import annotations

import argparse
import functools
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from flexmodal.daq.store import Channel, RunWriter
from flexmodal.fixtures.modal_sim import modal_response

FS = 5000.0
N_RESP = 16
PIECE_S = 60.0

IN_MEMORY = """
import sys
import numpy as np
from flexmodal.daq.store import read_run
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.runs_io import read_frf
run = read_run(sys.argv[1], "r")
ours = compute_frf(run, nfft=4096, workers=-1)
streamed = read_frf(sys.argv[2], "r")
print(np.max(np.abs(streamed.H - ours.H) / np.abs(ours.H)),
      np.max(np.abs(streamed.coherence - ours.coherence)))
"""


@functools.cache
def _piece() -> np.ndarray:
    """60 s of 1 random force + 16 responses of 3 modes at 5 kHz, float32 [n, 17]."""
    rng = np.random.default_rng(0)
    n = int(PIECE_S * FS)
    phi = rng.standard_normal((N_RESP, 3))
    force = rng.standard_normal((n, 1))
    y = modal_response(force, FS, np.array([120.0, 310.0, 800.0]), np.array([0.01, 0.02, 0.01]), phi,
                       phi[:1])
    return np.column_stack([force, y]).astype(np.float32)


def write_run(path: str, duration_s: float, run_id: str = "r") -> None:
    """One random run of ``duration_s`` seconds into ``path``: the same 60 s simulated record
    appended over and over."""
    piece = _piece()
    channels = [Channel("F", "force", "N")] + [Channel(f"a{k}", "acceleration", "m/s^2")
                                               for k in range(1, N_RESP + 1)]
    total = int(duration_s * FS)
    with RunWriter(path, run_id, sample_rate_hz=FS, channels=channels, excitation="random", pose={}) as w:
        for start in range(0, total, piece.shape[0]):
            w.append(piece[:min(piece.shape[0], total - start)])


def _child(args: list[str]) -> tuple[float, float, float, str]:
    """(wall s, CPU s, peak RSS MB, stdout) of one child Python process (CPU and RSS of that child
    alone: run in a fresh intermediate process so RUSAGE_CHILDREN holds nothing else)."""
    wrapper = ("import resource, subprocess, sys, time\n"
               "t = time.perf_counter()\n"
               "out = subprocess.run(sys.argv[1:], check=True, capture_output=True, text=True).stdout\n"
               "wall = time.perf_counter() - t\n"
               "r = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
               "print(wall, r.ru_utime + r.ru_stime, r.ru_maxrss / 1024)\n"
               "print(out, end='')\n")
    done = subprocess.run([sys.executable, "-c", wrapper, sys.executable, *args], check=True,
                          capture_output=True, text=True, timeout=7200)
    head, _, rest = done.stdout.partition("\n")
    wall, cpu, rss = (float(v) for v in head.split())
    return wall, cpu, rss, rest


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--durations", type=float, nargs="+", default=[600.0, 7200.0])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--folder", default=tempfile.gettempdir())
    p.add_argument("--no-in-memory", action="store_true", help="skip the in-memory comparison")
    a = p.parse_args(argv)
    per_second, fixed = {}, (0.0, 0.0)
    for duration in [1.0, *a.durations]:    # the 1 s run: the fixed cost (start-up, imports, writing)
        path = os.path.join(a.folder, f"flexmodal-memory-{int(duration)}s.h5")
        out = os.path.join(a.folder, f"flexmodal-memory-{int(duration)}s-frf.h5")
        try:
            t0 = time.perf_counter()
            write_run(path, duration)
            t_write = time.perf_counter() - t0
            walls, cpus, peaks = [], [], []
            for _ in range(a.repeat):
                if os.path.exists(out):
                    os.remove(out)
                wall, cpu, rss, _ = _child(["-m", "flexmodal", "--quiet", "frf", path, "--nfft", "4096",
                                       "--workers", "0", "--out", out])
                walls.append(wall)
                cpus.append(cpu)
                peaks.append(rss)
            if duration == 1.0:
                fixed = (float(np.median(walls)), float(np.median(cpus)))
                print(f"FIXED cost: `flexmodal frf` on a 1 s run, wall median {fixed[0]:.2f} s, "
                      f"CPU {fixed[1]:.2f} s")
                continue
            per_second[duration] = ((np.median(walls) - fixed[0]) / duration,
                                    (np.median(cpus) - fixed[1]) / duration)
            size_gb = os.path.getsize(path) / 1e9
            print(f"MEMORY {duration:g} s run ({size_gb:.2f} GB, written in {t_write:.0f} s): "
                  f"`flexmodal frf` peak RSS {max(peaks):.0f} MB, wall median {np.median(walls):.2f} s "
                  f"(spread {min(walls):.2f}-{max(walls):.2f} s; load average {os.getloadavg()[0]:.1f}), "
                  f"CPU median {np.median(cpus):.2f} s")
            if not a.no_in_memory:
                _, _, rss, text = _child(["-c", IN_MEMORY, path, out])
                dh, dc = (float(v) for v in text.split())
                print(f"     in-memory path (samples read whole, peak RSS {rss:.0f} MB): max relative "
                      f"difference of H {dh:.1e}, of coherence {dc:.1e} (absolute)")
        finally:
            for f in (path, out):
                if os.path.exists(f):
                    os.remove(f)
    if len(per_second) > 1:
        lo, hi = min(per_second), max(per_second)
        (wall_hi, cpu_hi), (wall_lo, cpu_lo) = per_second[hi], per_second[lo]
        print(f"     time per second of record beyond the fixed cost, {hi:g} s run / {lo:g} s run: "
              f"wall {wall_hi / wall_lo:.2f}, CPU {cpu_hi / cpu_lo:.2f} (1.00 = linear)")
    rusage = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"     (this driver process peaked at {rusage:.0f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
