"""Benchmark: the same data through pyFRF, sdypy-EMA and flexmodal's modal engine.

1. FRFs: H1 + H2 + coherence of 16 responses x 1 reference, 600 s at 5 kHz (float32 record as
   stored by the run store), Hann window, nfft 8192, 50 % overlap: pyFRF vs modal.spectra/modal.frf.
2. Poles: pLSCF with a stabilisation diagram over orders 2, 4, ..., 60 (the orders sdypy computes for
   pol_order_high=30) on 30 FRFs x 2000 lines (6 modes, 40 dB noise): sdypy-EMA's LSCF (get_poles +
   its stabilisation and selection given the true frequencies) vs modal.lscf (stabilisation with
   frequency, damping and MAC criteria + automatic selection, no frequencies given).

3. The whole process: ``flexmodal frf`` (nfft 4096, H1 + coherence) on that record stored as a run
   (float32, the run store's layout), against pyFRF in this process on the same samples as float64
   and against the floor of h5py reading the samples plus the bare FFTs; where the process's time
   goes (interpreter, imports, estimate, the rest; the imports split into numpy + h5py, scipy.fft and
   flexmodal's own modules) and the bound the start-up puts on any ratio.
4. KERNEL: Welch H1 + H2 + coherence of that record in memory: CPU on one thread against its bare
   FFTs' CPU on one thread (the passes besides the FFT), wall with 2 threads against 1 thread, on the
   machine as it is and with the other core busy; beside them the least any numpy/scipy estimate
   does (FFTs straight from the record plus the two reductions H1, H2 and coherence need) against
   the same bare FFTs, where the estimate's CPU goes (each numpy / scipy.fft call of the engine timed),
   and the CPU of the estimate's Python glue (the part holding the GIL, which
   bounds what a second thread can gain).

Each round runs the reference first, then flexmodal, on the same data in this process; prints the
median wall and CPU times over ``--repeat`` rounds, their ratios and the differences of the results.
For the FRFs it also times the bare real FFTs that any Welch estimate of this record needs (one per
segment and channel, float32, all CPUs, data already in cache): pyFRF's time over that floor is the
largest ratio any implementation doing those transforms could reach.
Usage: ``python benchmarks/modal.py [--duration-s 600] [--lines 2000] [--repeat 5]`` (BLAS threads
as the environment sets them, e.g. ``OPENBLAS_NUM_THREADS=1``; modal.lscf itself uses one).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import os
import resource
import select
import shutil
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np
import scipy.fft

from flexmodal.fixtures.modal_sim import modal_frf, modal_response  # noqa: E402
from flexmodal.modal.frf import coherence, h1, h2  # noqa: E402
from flexmodal.modal.lscf import select_stable, stabilisation  # noqa: E402
from flexmodal.modal.spectra import welch_spectra  # noqa: E402

FN = np.array([12.0, 31.0, 55.0, 80.0, 120.0, 150.0])
ZETA = np.array([0.005, 0.02, 0.01, 0.05, 0.01, 0.02])


def _timed(reference, ours, repeat: int):
    """Median wall and CPU times (s, CPU of this process: every thread) of ``reference`` and ``ours``
    over ``repeat`` rounds, each round running the reference first and then ours on the same data (the
    machine is shared, so the two sides of a round see similar load); and the last results."""
    times = {reference: [], ours: []}
    out = {}
    for _ in range(repeat):
        for fn in (reference, ours):
            t0, c0 = time.perf_counter(), time.process_time()
            out[fn] = fn()
            times[fn].append((time.perf_counter() - t0, time.process_time() - c0))
    (tw, tc), (ow, oc) = (np.median(np.array(times[fn]), axis=0) for fn in (reference, ours))
    return (tw, tc, out[reference]), (ow, oc, out[ours])


def _ratio_line(name_ref: str, t_ref: float, c_ref: float, t_ours: float, c_ours: float, repeat: int) -> str:
    return (f"{name_ref} {t_ref:.3f} s, flexmodal {t_ours:.3f} s, ratio {t_ref / t_ours:.1f}x "
            f"(CPU {c_ref:.3f} s vs {c_ours:.3f} s, {c_ref / c_ours:.1f}x; medians of {repeat})")


FLOOR_ROWS = (16, 64, 256)     # transforms per call tried for the bare-FFT floor


def _fft_floor(n_transforms: int, nfft: int, repeat: int, workers: int = -1,
               clock=time.perf_counter) -> float:
    """Median time (s; wall, or the ``clock`` given, e.g. ``time.process_time`` for CPU) of
    ``n_transforms`` bare float32 real FFTs of ``nfft`` points by ``scipy.fft.rfft`` with ``workers``
    threads (default every CPU), data already in cache: the best over calls of FLOOR_ROWS transforms
    each (the fastest way this FFT library does them), so a ratio against it is a lower bound."""
    best = np.inf
    for rows in FLOOR_ROWS:
        block = np.random.default_rng(2).standard_normal((rows, nfft)).astype(np.float32)
        n_blocks = n_transforms / rows
        times = []
        for _ in range(repeat):
            t0 = clock()
            for _ in range(int(np.ceil(n_blocks))):
                scipy.fft.rfft(block, axis=-1, workers=workers)
            times.append((clock() - t0) * n_blocks / np.ceil(n_blocks))
        best = min(best, float(np.median(times)))
    return best


@functools.lru_cache(maxsize=1)
def _record(duration_s: float, fs: float, n_resp: int) -> np.ndarray:
    """1 random force + ``n_resp`` responses of 4 modes (1 % noise), float32 [n, 1 + n_resp]."""
    rng = np.random.default_rng(0)
    n = int(duration_s * fs)
    phi = rng.standard_normal((n_resp, 4))
    force = rng.standard_normal((n, 1))
    y = modal_response(force, fs, FN[:4] * 10, ZETA[:4], phi, phi[:1])
    y += 0.01 * y.std(axis=0) * rng.standard_normal(y.shape)
    return np.column_stack([force, y]).astype(np.float32)


def _pyfrf_arrays(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """pyFRF's excitation [1, 1, n] and response [1, n_resp, n] arrays of a record (force first)."""
    return samples[:, 0][None, None, :], np.ascontiguousarray(samples[:, 1:].T)[None]


def _pyfrf(exc: np.ndarray, resp: np.ndarray, fs: float, nfft: int):
    """pyFRF's H1, H2 and coherence, Hann, 50 % overlap."""
    import pyFRF

    f = pyFRF.FRF(int(fs), exc=exc, resp=resp, exc_type="f", resp_type="d", window="hann",
                  nperseg=nfft, noverlap=nfft // 2, fft_len=nfft)
    return f.get_H1(), f.get_H2(), f.get_coherence()


def bench_frf(duration_s: float, fs: float, n_resp: int, nfft: int, repeat: int) -> None:
    samples = _record(duration_s, fs, n_resp)
    n = samples.shape[0]
    window = np.hanning(nfft)          # pyFRF's Hann (symmetric), given to both

    def ours():
        s = welch_spectra(samples, fs, [0], list(range(1, n_resp + 1)), nfft, window_spec=window, workers=-1)
        return h1(s), h2(s), coherence(s)

    exc, resp = _pyfrf_arrays(samples)

    def theirs():
        return _pyfrf(exc, resp, fs, nfft)

    (t_theirs, c_theirs, (b1, b2, bc)), (t_ours, c_ours, (a1, a2, ac)) = _timed(theirs, ours, repeat)
    lines = slice(1, None)
    good = bc[:, lines] > 0.5

    def rel(a, b):
        return float(np.max((np.abs(a[:, 0, lines] - b[:, 0, lines]) / np.abs(b[:, 0, lines]))[good]))

    print(f"FRF  {n_resp} responses x 1 reference, {duration_s:g} s at {fs:g} Hz, nfft {nfft}: "
          + _ratio_line("pyFRF", t_theirs, c_theirs, t_ours, c_ours, repeat))
    n_fft = (n_resp + 1) * ((n - nfft) // (nfft // 2) + 1)
    floor = _fft_floor(n_fft, nfft, repeat)
    print(f"     FFT floor: the {n_fft} bare float32 FFTs alone take {floor:.3f} s (all CPUs, in cache), "
          f"so no Welch implementation can be more than {t_theirs / floor:.1f}x faster than pyFRF here")
    print(f"     max relative difference (coherence > 0.5): H1 {rel(a1, b1):.1e}, H2 {rel(a2, b2):.1e}, "
          f"coherence {np.max(np.abs(ac[:, lines] - bc[:, lines])[good]):.1e}")


def _child_env(cache: str | None) -> dict:
    """The environment of the timed child processes: with ``cache`` a folder, Python caches the
    bytecode of flexmodal's modules there (as an installed package has it), else none is written
    (``PYTHONDONTWRITEBYTECODE=1``, as in a sandbox that sets it: every module compiled each time)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONDONTWRITEBYTECODE", "PYTHONPYCACHEPREFIX")}
    if cache is None:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    else:
        env["PYTHONPYCACHEPREFIX"] = cache
    return env


def _child(command: list[str], env: dict) -> tuple[float, float]:
    """Wall and CPU time (s, user + system of the child) of one child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(command, check=True, timeout=600, stdout=subprocess.DEVNULL, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def _spread(values) -> str:
    return f"{np.median(values):.3f} s ({np.min(values):.3f}-{np.max(values):.3f})"


def bench_process(duration_s: float, fs: float, n_resp: int, nfft: int, repeat: int, folder: str) -> None:
    """The whole ``flexmodal frf`` process (start-up, imports, streaming the stored float32 run, H1 +
    coherence, writing them) against pyFRF in this process on the same samples as float64, and
    against the floor: h5py reading the samples plus the bare FFTs.  Then where the process's time
    goes (start-up, imports, the streamed estimate in this process, the rest) and the bound that the
    interpreter's own start-up puts on the ratio."""

    from flexmodal.daq.store import Channel, RunWriter, open_run
    from flexmodal.modal.batch import idle_cpus
    from flexmodal.modal.compute import compute_frf

    samples = _record(duration_s, fs, n_resp)
    path, out = os.path.join(folder, "bench_run.h5"), os.path.join(folder, "bench_frf.h5")
    cache = tempfile.mkdtemp(prefix="flexmodal-pyc-", dir=folder)
    channels = [Channel("F", "force", "N")] + [Channel(f"a{k}", "acceleration", "m/s^2")
                                               for k in range(1, n_resp + 1)]
    with RunWriter(path, "r", sample_rate_hz=fs, channels=channels, excitation="random", pose={}) as w:
        w.append(samples)
    n = samples.shape[0]
    exc, resp = _pyfrf_arrays(samples.astype(np.float64))
    del samples
    command = [sys.executable, "-m", "flexmodal", "--quiet", "frf", path, "--nfft", str(nfft),
               "--workers", "0", "--out", out]
    cached, uncached = _child_env(cache), _child_env(None)
    floors = {"python -c pass": [sys.executable, "-c", "pass"],
              "import numpy, h5py": [sys.executable, "-c", "import numpy, h5py"],
              "import numpy, h5py, scipy.fft": [sys.executable, "-c", "import numpy, h5py, scipy.fft"],
              "imports of `frf`": [sys.executable, "-c", "import flexmodal.app, flexmodal.api, "
                                   "flexmodal.modal.batch, flexmodal.checked_io.output"],
              "frf --help": [sys.executable, "-m", "flexmodal", "frf", "--help"]}

    def theirs():
        h1_, _, coh = _pyfrf(exc, resp, fs, nfft)
        return h1_, coh

    times: dict[str, list] = {k: [] for k in ("ours", "uncached", "estimate", *floors)}

    def ours():
        if os.path.exists(out):
            os.remove(out)
        times["ours"].append(_child(command, cached))

    def estimate():
        with open_run(path, "r") as run:
            compute_frf(run, nfft=nfft, workers=idle_cpus())

    try:
        _child(command, cached)                 # fills the bytecode cache
        (t_theirs, c_theirs, _), _ = _timed(theirs, ours, repeat)
        for _ in range(repeat):
            os.remove(out)
            times["uncached"].append(_child(command, uncached))
            for name, cmd in floors.items():
                times[name].append(_child(cmd, cached))
            t0, c0 = time.perf_counter(), time.process_time()
            estimate()
            times["estimate"].append((time.perf_counter() - t0, time.process_time() - c0))
        reads = np.array([_wall(lambda: _read(path)) for _ in range(repeat)])     # [round, (wall, CPU)]
        t_read, c_read = np.median(reads, axis=0)
        n_seg = (n - nfft) // (nfft // 2) + 1
        threads = idle_cpus()                   # the FFT threads the `frf` process uses now
        t_fft = _fft_floor((n_resp + 1) * n_seg, nfft, repeat, workers=threads)
        c_fft = _fft_floor((n_resp + 1) * n_seg, nfft, repeat, workers=1, clock=time.process_time)
        from flexmodal.modal.runs_io import read_frf

        got = read_frf(out, "r")
    finally:
        for p in (path, out):
            if os.path.exists(p):
                os.remove(p)
        shutil.rmtree(cache, ignore_errors=True)
    wall = {k: np.array(v)[:, 0] for k, v in times.items()}
    cpu = {k: float(np.median(np.array(v)[:, 1])) for k, v in times.items()}
    t_ours, floor = float(np.median(wall["ours"])), t_read + t_fft
    start = float(np.median(wall["import numpy, h5py"]))
    t_imports = float(np.median(wall["imports of `frf`"]))
    print(f"PROC whole `flexmodal frf` process, {n_resp} responses x 1 reference, {duration_s:g} s at "
          f"{fs:g} Hz, nfft {nfft}, H1 + coherence, bytecode cached: pyFRF in-process (float64) "
          f"{t_theirs:.3f} s, flexmodal process {_spread(wall['ours'])}, ratio {t_theirs / t_ours:.1f}x "
          f"(medians of {repeat}); CPU pyFRF {c_theirs:.3f} s, flexmodal process {cpu['ours']:.3f} s, "
          f"ratio {c_theirs / cpu['ours']:.1f}x; without a bytecode cache the process takes "
          f"{_spread(wall['uncached'])}")
    print(f"     floor: h5py read {t_read:.3f} s + bare FFTs {t_fft:.3f} s ({threads} thread(s), as the "
          f"process) = {floor:.3f} s; interpreter + imports of `frf` {t_imports:.3f} s beside it; "
          f"(process - imports) / floor = {(t_ours - t_imports) / floor:.2f} (target <= 2: process <= "
          f"{2 * floor + t_imports:.3f} s); process / floor = {t_ours / floor:.2f}; {got.n_averages} "
          f"segments; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    c_floor, c_imports = c_read + c_fft, cpu["imports of `frf`"]
    print(f"     in CPU (steadier on a shared machine): read {c_read:.3f} s + bare FFTs on 1 thread "
          f"{c_fft:.3f} s = {c_floor:.3f} s; imports of `frf` {c_imports:.3f} s; (process - imports) / "
          f"floor = {(cpu['ours'] - c_imports) / c_floor:.2f} (target <= 2)")
    def med(key: str, i: int) -> float:       # median wall (i = 0) or CPU (i = 1) time
        return float(np.median(np.array(times[key])[:, i]))

    rest = [med("ours", i) - med("imports of `frf`", i) - med("estimate", i) for i in (0, 1)]
    print("     where it goes, wall (CPU): " + "; ".join(
        f"{name} {_spread(wall[key])} ({cpu[key]:.3f})" for name, key in (
            ("`python -c pass`", "python -c pass"), ("`import numpy, h5py`", "import numpy, h5py"),
            ("all imports of `frf`", "imports of `frf`"), ("streamed estimate in-process", "estimate")))
        + f"; the rest (parser, checks, writing) {rest[0]:.3f} s ({rest[1]:.3f})")
    steps = [[med(key, i) for i in (0, 1)] for key in (
        "python -c pass", "import numpy, h5py", "import numpy, h5py, scipy.fft", "imports of `frf`")]
    added = [(steps[k][0] - steps[k - 1][0], steps[k][1] - steps[k - 1][1]) for k in (1, 2, 3)]
    print("     the imports of `frf`, wall (CPU): " + ", ".join(
        f"{name} {t:.3f} s ({c:.3f})" for name, (t, c) in zip(
            ("the interpreter", "numpy + h5py", "scipy.fft on top of them (its own imports: scipy.special, "
             "scipy's array-API layer)", "flexmodal's own modules (the most lazier imports could save)"),
            [tuple(steps[0])] + added, strict=True)))
    print(f"     bounds: any process that starts Python and imports numpy + h5py, reads and transforms "
          f"takes >= {start + floor:.3f} s, so none is more than {t_theirs / (start + floor):.1f}x faster "
          f"than pyFRF here; that start alone is {start / (t_theirs / 10):.2f}x pyFRF's time / 10")
    print(f"HELP `flexmodal frf --help`, bytecode cached: {_spread(wall['frf --help'])} "
          f"({cpu['frf --help']:.3f} s CPU)")


SPINNERS = {   # how the other core is kept busy -> (own session, pinned to one CPU, nice)
    "its own session (another user's job)": (True, False, 0),
    "our session": (False, False, 0),
    "our session, pinned to one CPU (taskset)": (False, True, 0),
    "our session, nice 19": (False, False, 19),
}


def _fair_share(how: str) -> float:
    """CPUs the estimate's 2 threads can get beside the spinner ``how`` on 2 otherwise idle CPUs under
    Linux's fair scheduler (1 thread gets 1 in every case): in its own session (autogroup: the 2 CPUs
    split equally between the two sessions) 1; in ours (3 equal threads on 2 CPUs) 4/3; in ours pinned
    to one CPU (one of ours shares that CPU with it) 3/2; at nice 19 (weight 15 against 1024 each)
    2 * 2048 / 2063."""
    own, pinned, nice = SPINNERS[how]
    if own:
        return 1.0
    if pinned:
        return 1.5
    weight = 1024 / 1.25 ** nice       # the kernel's nice-to-weight table: 1.25x per nice level
    return min(2.0, 2 * 2048 / (2048 + weight))


def _cpu_of(pid: int) -> float:
    """CPU time (s, user + system) of process ``pid`` so far (Linux /proc; nan elsewhere)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return float("nan")


@contextlib.contextmanager
def _other_core_busy(how: str = "its own session (another user's job)"):
    """A process spinning on one CPU while the block runs, started as SPINNERS[``how``] says; yields
    its pid once it is set up and spinning (it says so on its stdout; at most 60 s)."""
    own, pinned, nice = SPINNERS[how]
    code = "import os, sys\n"
    if pinned:
        code += f"os.sched_setaffinity(0, {{{max(os.sched_getaffinity(0))}}})\n"
    if nice:
        code += f"os.nice({nice})\n"
    code += "sys.stdout.write('.')\nsys.stdout.flush()\nwhile True: pass"
    spin = subprocess.Popen([sys.executable, "-c", code], start_new_session=own, stdout=subprocess.PIPE)
    try:
        if not select.select([spin.stdout], [], [], 60)[0] or spin.stdout.read(1) != b".":
            raise RuntimeError("the spinning process did not start")
        yield spin.pid
    finally:
        spin.kill()
        spin.wait(timeout=10)
        spin.stdout.close()


def bench_kernel(duration_s: float, fs: float, n_resp: int, nfft: int, repeat: int) -> None:
    """Welch H1 + H2 + coherence of the PROC record in memory (float32, Hann, nfft ``nfft``): its CPU
    on one thread against the CPU of its bare FFTs on one thread (the best of FLOOR_ROWS per call),
    and its wall time with 2 threads against 1 thread, on the machine as it is and with the other core
    busy (one spinning process).  Each round runs 1 thread then 2 threads; medians and spread (min-max)
    over ``repeat`` rounds, ratios per round; the load average with every line."""
    samples = _record(duration_s, fs, n_resp)
    n_fft = (n_resp + 1) * ((samples.shape[0] - nfft) // (nfft // 2) + 1)

    def estimate(threads: int):
        s = welch_spectra(samples, fs, [0], list(range(1, n_resp + 1)), nfft, workers=threads)
        return h1(s), h2(s), coherence(s)

    def rounds(spinner: int | None = None) -> dict:
        """Per round: the bare FFTs' CPU on one thread (the reference, first; not beside a spinner),
        then the estimate on 1 and 2 threads (wall, CPU, and the CPU the ``spinner`` process got)."""
        times: dict = {"fft": [], 1: [], 2: []}
        for _ in range(repeat):
            if spinner is None:
                times["fft"].append(_fft_floor(n_fft, nfft, 1, workers=1, clock=time.process_time))
            for threads in (1, 2):
                t0, c0 = time.perf_counter(), time.process_time()
                s0 = np.nan if spinner is None else _cpu_of(spinner)
                estimate(threads)
                s1 = np.nan if spinner is None else _cpu_of(spinner)
                times[threads].append((time.perf_counter() - t0, time.process_time() - c0, s1 - s0))
        return {k: np.array(v) for k, v in times.items()}

    estimate(1)                                 # warm: buffers, FFT plans
    load = os.getloadavg()[0]
    least = np.array([[_fft_floor(n_fft, nfft, 1, workers=1, clock=time.process_time),
                       *_least_pipeline(samples, nfft)] for _ in range(repeat)])
    glue = _glue_cpu(samples.shape[1], samples.shape[0], nfft, repeat)
    quiet = rounds()
    busy = {}
    for how in SPINNERS:
        with _other_core_busy(how) as pid:
            busy[how] = rounds(pid)
    c1, cf = quiet[1][:, 1], quiet["fft"]
    ratio = c1 / cf
    print(f"KERNEL Welch H1 + H2 + coherence, {n_resp} + 1 channels, {duration_s:g} s at {fs:g} Hz, nfft "
          f"{nfft}, float32 in memory (load average {load:.1f} on {os.cpu_count()} CPUs): CPU on 1 thread "
          f"{_spread(c1)}, its {n_fft} bare FFTs' CPU on 1 thread {_spread(cf)} (the reference, first in "
          f"each round): {np.median(ratio):.2f}x ({ratio.min():.2f}-{ratio.max():.2f}, per round) (target "
          f"<= 1.4); the passes besides the FFTs {np.median(c1 - cf):.3f} s")
    print("     where the CPU of 1 thread goes (thread time of each numpy / scipy.fft call of the engine, "
          f"medians of {repeat} calls; in brackets in units of the bare FFTs' median): "
          + _kernel_parts(lambda: estimate(1), float(np.median(cf)), repeat))
    def unit(cpu: np.ndarray) -> str:      # median CPU over the bare FFTs' CPU of the same round
        return f"{np.median(cpu / least[:, 0]):.2f}x"

    ratio = least[:, 1] / least[:, 0]
    print(f"     the least any numpy/scipy estimate does (FFTs straight from a strided view of the record, "
          f"no copy, window, mean removal or check, then the auto-spectra and the cross-spectra against "
          f"the reference, one call each per block; the best of blocks of {LEAST_BLOCKS} segments): "
          f"CPU {_spread(least[:, 1])} against its bare FFTs' {_spread(least[:, 0])}: "
          f"{np.median(ratio):.2f}x ({ratio.min():.2f}-{ratio.max():.2f}) (load average now "
          f"{os.getloadavg()[0]:.1f}); of which, in units of the bare FFTs: the FFTs from the record "
          f"{unit(least[:, 2])}, the auto-spectra {unit(least[:, 3])}, the cross-spectra "
          f"{unit(least[:, 4])}, the loop {unit(least[:, 1] - least[:, 2:].sum(axis=1))}")
    share = glue / np.median(c1)
    extra = np.median(quiet[2][:, 1]) / np.median(c1)
    print(f"     the Python glue (holds the GIL): the same blocks of segments of 16 samples (every call on "
          f"tiny arrays) {glue:.4f} s of CPU, {100 * share:.1f} % of 1 thread's CPU; with the 2 threads' "
          f"CPU {extra:.2f}x 1 thread's, two idle cores bound 2 / 1 at {extra * (1 - share) / 2 + share:.2f} "
          f"(glue serial, the rest halved)")
    t = quiet
    ratio = t[2][:, 0] / t[1][:, 0]
    print(f"     wall, as it is: 1 thread {_spread(t[1][:, 0])}, 2 threads {_spread(t[2][:, 0])}: 2 / 1 = "
          f"{np.median(ratio):.2f} ({ratio.min():.2f}-{ratio.max():.2f}) (target <= 0.6); CPU 2 threads "
          f"{np.median(t[2][:, 1]):.3f} s; CPUs got: 1 thread {np.median(t[1][:, 1] / t[1][:, 0]):.2f}, "
          f"2 threads {np.median(t[2][:, 1] / t[2][:, 0]):.2f} (medians of {repeat}; load average now "
          f"{os.getloadavg()[0]:.1f})")
    for how, t in busy.items():
        ratio = t[2][:, 0] / t[1][:, 0]
        got = [np.median(t[k][:, 1] / t[k][:, 0]) for k in (1, 2)]
        spin = [np.median(t[k][:, 2] / t[k][:, 0]) for k in (1, 2)]
        bound = extra / _fair_share(how)
        # the split between ours and the spinner measured here, carried to 2 CPUs with nobody else:
        # n threads holding a fraction q of the CPU the two processes got would get min(n, 2 q) CPUs
        idle = [t[k][:, 1] / np.minimum(k, 2 * t[k][:, 1] / (t[k][:, 1] + t[k][:, 2])) for k in (1, 2)]
        print(f"     wall, other core busy (a spinning process in {how}): 1 thread {_spread(t[1][:, 0])}, "
              f"2 threads {_spread(t[2][:, 0])}: 2 / 1 = {np.median(ratio):.2f} ({ratio.min():.2f}-"
              f"{ratio.max():.2f}) (target <= 0.6); CPUs got: 1 thread {got[0]:.2f}, 2 threads {got[1]:.2f} "
              f"({got[1] / got[0]:.2f}x), the spinner {spin[0]:.2f} and {spin[1]:.2f}; on 2 otherwise idle "
              f"CPUs fair scheduling gives 2 threads at most {_fair_share(how):.2f} CPUs here, 1 thread 1: "
              f"2 / 1 >= {bound:.2f} (the 2 threads' CPU {extra:.2f}x 1 thread's / {_fair_share(how):.2f}); "
              f"at the split between ours and the spinner measured here (ours / both), on 2 CPUs with "
              f"nobody else: 2 / 1 = {np.median(idle[1] / idle[0]):.2f} (load average now "
              f"{os.getloadavg()[0]:.1f})")


LEAST_BLOCKS = (4, 16)


def _least_pipeline(samples: np.ndarray, nfft: int) -> tuple[float, float, float, float]:
    """CPU (s, this thread) of the least a numpy/scipy Welch H1 + H2 + coherence of ``samples`` (first
    column the reference, half-overlapping segments of ``nfft``) does, the best over blocks of
    LEAST_BLOCKS segments: per block, one ``scipy.fft.rfft`` straight from a strided view of the
    record (no copy, window, mean removal or check), then the two reductions the estimators need,
    the auto-spectra (one ``einsum``) and the cross-spectra against the reference (conjugate, one
    batched ``matmul``).  Returns (all of it, the FFTs, the auto-spectra, the cross-spectra) of the
    best block size, each part timed around its own calls."""
    n, n_ch = samples.shape
    step = nfft // 2
    n_seg = (n - nfft) // step + 1
    isz = samples.itemsize
    best = (np.inf,) * 4
    for b in LEAST_BLOCKS:
        parts = np.zeros(3)
        t0 = time.thread_time()
        for first in range(0, n_seg, b):
            count = min(b, n_seg - first)
            rows = samples[first * step:]
            view = np.ndarray((count, nfft, n_ch), samples.dtype, rows,
                              strides=(step * n_ch * isz, n_ch * isz, isz))
            t1 = time.thread_time()
            spec = scipy.fft.rfft(view, axis=1, workers=1)
            t2 = time.thread_time()
            flat = spec.view(spec.real.dtype).reshape(count, -1)
            np.einsum("sk,sk->k", flat, flat)
            t3 = time.thread_time()
            np.matmul(spec.transpose(1, 2, 0), spec[:, :, :1].conj().transpose(1, 0, 2))
            parts += (t2 - t1, t3 - t2, time.thread_time() - t3)
        total = time.thread_time() - t0
        if total < best[0]:
            best = (total, *parts)
    return best


def _glue_cpu(n_ch: int, n_samples: int, nfft: int, repeat: int) -> float:
    """Median CPU (s, this thread) of the Welch estimate's Python glue for a record of ``n_samples`` x
    ``n_ch`` float32 and ``nfft``: the estimate (H1 + H2 + coherence, one thread) of the same number
    of blocks of the same number of segments, each of 16 samples, so every numpy call is on tiny
    arrays (below the size at which numpy lets the GIL go): the interpreter and call overhead, all
    of it holding the GIL."""
    from unittest import mock

    from flexmodal.modal import spectra

    step = nfft // 2
    n_seg = (n_samples - nfft) // step + 1
    block = max(1, min(n_seg, spectra._BLOCK_BYTES // (n_ch * nfft * 4)))
    tiny = np.random.default_rng(3).standard_normal(((n_seg - 1) * 8 + 16, n_ch)).astype(np.float32)
    times = []
    with mock.patch.object(spectra, "_BLOCK_BYTES", block * n_ch * 16 * 4):
        for _ in range(repeat):
            t0 = time.thread_time()
            s = welch_spectra(tiny, 5000.0, [0], list(range(1, n_ch)), 16, workers=1)
            h1(s), h2(s), coherence(s)
            times.append(time.thread_time() - t0)
    return float(np.median(times))


KERNEL_PARTS = {   # numpy / scipy.fft function as modal.spectra calls it -> the part of the estimate it is
    "fft.rfft": "FFTs",
    "subtract": "offset shift (the record's first read)",
    "add.reduce": "segment sums",
    "multiply": "window",
    "matmul": "cross-spectra product",
    "einsum": "auto-spectra",
}


class _Timed:
    """A stand-in for a module (numpy, scipy, scipy.fft) as ``modal.spectra`` sees it: every attribute
    is the module's own, except the KERNEL_PARTS functions, which add the thread CPU of each call to
    ``cpu`` under their part's name."""

    def __init__(self, module, cpu: dict, prefix: str = "") -> None:
        self._module, self._cpu, self._prefix = module, cpu, prefix

    def __getattr__(self, name: str):
        attr = getattr(self._module, name)
        key = self._prefix + name
        if key in KERNEL_PARTS:
            def timed(*args, **kwargs):
                t0 = time.thread_time()
                try:
                    return attr(*args, **kwargs)
                finally:
                    self._cpu[KERNEL_PARTS[key]] += time.thread_time() - t0
            return timed
        if any(part.startswith(key + ".") for part in KERNEL_PARTS):     # np.add -> np.add.reduce
            return _Timed(attr, self._cpu, key + ".")
        return attr


def _kernel_parts(fn, unit: float, repeat: int) -> str:
    """Median thread CPU, over ``repeat`` calls of ``fn`` (the Welch estimate on one thread), of its
    parts: the calls of modal.spectra to the numpy and scipy.fft functions of KERNEL_PARTS timed one by
    one (its module attributes ``np`` and ``scipy`` stood in for by _Timed while ``fn`` runs; the tiny
    matmul of the segment sums counts with the cross-spectra), the rest (Python, the small operations
    on a block's few lines and means, the reference's conjugate, H1 / H2 / coherence) what is left of
    the call's thread CPU; each also in units of ``unit`` (s: the bare FFTs' CPU)."""
    from unittest import mock

    from flexmodal.modal import spectra

    rounds = []
    for _ in range(repeat):
        cpu = dict.fromkeys(KERNEL_PARTS.values(), 0.0)
        with mock.patch.object(spectra, "np", _Timed(np, cpu)), \
                mock.patch.object(spectra, "scipy", _Timed(scipy, cpu)):
            t0 = time.thread_time()
            fn()
            total = time.thread_time() - t0
        rounds.append([*cpu.values(), total - sum(cpu.values()), total])
    *values, total = np.median(np.array(rounds), axis=0)
    parts = dict(zip([*KERNEL_PARTS.values(), "the rest"], values, strict=True))
    return "; ".join(f"{k} {v:.3f} s ({v / unit:.2f})" for k, v in parts.items()) + (
        f" (of {total:.3f} s, {total / unit:.2f})")


def _read(path: str) -> np.ndarray:
    import h5py

    with h5py.File(path, "r") as f:
        return f["runs/r/samples"][()]


def _wall(fn) -> tuple[float, float]:
    """Wall and CPU time (s) of ``fn()``."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def bench_lscf(n_frf: int, n_lines: int, repeat: int) -> None:
    from sdypy import EMA

    rng = np.random.default_rng(1)
    phi = rng.standard_normal((n_frf, FN.size))
    f = np.linspace(0, 200, n_lines + 1)[1:]
    H = modal_frf(f, FN, ZETA, phi, phi[:1])
    H = H + 0.01 * np.sqrt(np.mean(np.abs(H) ** 2)) * (rng.standard_normal(H.shape)
                                                       + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)

    def ours():
        return select_stable(stabilisation(f, H, range(2, 61, 2)))

    def theirs():
        m = EMA.Model(frf=H[:, 0], freq=f, lower=1, upper=200, pol_order_high=30, frf_form="accelerance")
        m.get_poles(show_progress=False)
        with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):   # its progress bar
            warnings.simplefilter("ignore")
            m.select_closest_poles(FN)
        return m.nat_freq, m.nat_xi

    (t_theirs, c_theirs, (ft, zt)), (t_ours, c_ours, (fo, zo, _)) = _timed(theirs, ours, repeat)

    def errors(fr, zr):
        """Relative errors per true mode of the nearest identified one (inf when none within 5 %)."""
        k = np.argmin(np.abs(fr[None, :] - FN[:, None]), axis=1)
        ef = np.abs(fr[k] / FN - 1)
        ez = np.abs(zr[k] / ZETA - 1)
        missing = ef > 0.05
        ef[missing] = ez[missing] = np.inf
        return ef, ez

    efo, ezo = errors(np.asarray(fo), np.asarray(zo))
    eft, ezt = errors(np.asarray(ft), np.asarray(zt))
    print(f"LSCF {n_frf} FRFs x {n_lines} lines, orders 2,4..60, 6 modes (sdypy-EMA given the true "
          "frequencies, flexmodal automatic selection): "
          + _ratio_line("sdypy-EMA", t_theirs, c_theirs, t_ours, c_ours, repeat))
    for name, ef, ez in (("sdypy-EMA", eft, ezt), ("flexmodal", efo, ezo)):
        print(f"     {name:9s} modes found {int(np.isfinite(ef).sum())}/{FN.size}; max error of found: "
              f"frequency {np.max(ef[np.isfinite(ef)], initial=0):.1e}, "
              f"damping {np.max(ez[np.isfinite(ez)], initial=0):.1e} (relative)")


CASES = ("frf", "process", "kernel", "lscf")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration-s", type=float, default=600.0)
    p.add_argument("--sample-rate-hz", type=float, default=5000.0)
    p.add_argument("--responses", type=int, default=16)
    p.add_argument("--nfft", type=int, default=8192)
    p.add_argument("--frfs", type=int, default=30)
    p.add_argument("--lines", type=int, default=2000)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--process-nfft", type=int, default=4096, help="nfft of the whole-process case")
    p.add_argument("--folder", default=tempfile.gettempdir(), help="where the run file is written")
    p.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES), help="which cases to run")
    a = p.parse_args(argv)
    if "frf" in a.cases:
        bench_frf(a.duration_s, a.sample_rate_hz, a.responses, a.nfft, a.repeat)
    if "process" in a.cases:
        bench_process(a.duration_s, a.sample_rate_hz, a.responses, a.process_nfft, a.repeat, a.folder)
    if "kernel" in a.cases:
        bench_kernel(a.duration_s, a.sample_rate_hz, a.responses, a.process_nfft, a.repeat)
    if "lscf" in a.cases:
        bench_lscf(a.frfs, a.lines, a.repeat)
    return 0


if __name__ == "__main__":
    sys.exit(main())
