"""Batch FRFs of many stored runs: serially, on a pool of local worker processes, or on an existing
dask.distributed scheduler, chosen by measured cost when not asked for.  Workers stream a run from
its (shared) path and return its FRFs; the calling process writes every result back, each file only
once no worker reads it any more (HDF5 locks a file being written), so files are never written
concurrently and the results are the same whichever path computed them."""

from __future__ import annotations

import collections
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from flexmodal.checked_io.text import one_line
from flexmodal.daq.store import expand_runs
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.runs_io import write_frf
from flexmodal.modal.spectra import usable_cpus

POOL_START_S = 1.0      # start 2 worker processes, their imports, first task (benchmarks/batch.py)
AUTO_WORKERS = 2        # processes of the pool the automatic choice starts
MIN_SPEEDUP = 1.5       # go parallel only when the predicted speed-up is at least this,
PAYS_FACTOR = 3.0       # the predicted saving at least 3 start-ups,
MIN_PARALLEL_RUNS = 4   # and at least this many runs remain


def frf_job(path: str, run_id: str, options: dict) -> FrfResult:
    """Stream one run from its file and compute its FRFs (the unit of work sent to a worker)."""
    from flexmodal.daq.store import open_run

    with open_run(path, run_id) as run:
        try:
            return compute_frf(run, **options)
        except OSError as exc:  # a damaged chunk met while streaming the samples
            raise ModalError(f"{path}: run {run_id!r}: cannot read the samples ({one_line(exc)})") from None


def idle_cpus() -> int:
    """CPUs the other processes leave idle (the CPUs this process may use less the 1-minute load
    average, rounded; at least 1): the FFT threads of the serial path.  On a busy machine a second
    thread only adds contention (measured under load 6 on 2 CPUs: 8 runs of 60 s took 1.13 s with 2
    threads, 0.82 s with 1)."""
    cpus = usable_cpus()
    return max(1, min(cpus, cpus - round(os.getloadavg()[0])))


def run_bytes(jobs: Sequence[tuple[str, str]]) -> list[int]:
    """Bytes of samples of every (file, run_id) job, from the file metadata."""
    from flexmodal.daq.h5file import open_read

    sizes = []
    for path, rid in jobs:
        with open_read(path) as f:   # a truncated file fails here at once, as everywhere else
            try:
                ds = f.get(f"runs/{rid}/samples")
            except (KeyError, RuntimeError, OSError):   # a broken link: the job itself names it
                ds = None
            sizes.append(int(ds.size) * ds.dtype.itemsize if hasattr(ds, "dtype") else 0)
    return sizes


class _Deliver:
    """Hands each result to ``on_done`` once no unfinished job still reads the file it goes to (the
    caller's process is the only writer, and never writes a file a worker has open)."""

    def __init__(self, jobs, on_done, target: Callable[[str], str]) -> None:
        self.jobs, self.on_done, self.target = jobs, on_done, target
        self.pending: dict[str, int] = {}
        for p, _ in jobs:
            self.pending[str(p)] = self.pending.get(str(p), 0) + 1
        self.held: list[tuple[int, FrfResult]] = []

    def __call__(self, k: int, result: FrfResult) -> None:
        self.pending[str(self.jobs[k][0])] -= 1
        self.held.append((k, result))
        ready = [(j, r) for j, r in self.held if not self.pending.get(self.target(str(self.jobs[j][0])), 0)]
        self.held = [h for h in self.held if h not in ready]
        if self.on_done:
            for j, r in sorted(ready, key=lambda h: h[0]):
                self.on_done(*self.jobs[j], r)


def _serial_pays(elapsed_s: float, cpu_s: float, bytes_done: int, bytes_left: int, runs_left: int) -> bool:
    """True while computing the rest here is predicted no worse than a pool of AUTO_WORKERS processes.

    From the runs done so far (``elapsed_s`` wall, ``cpu_s`` CPU of this process, every thread):
    the rest takes ``elapsed_s / bytes_done * bytes_left`` here; this process keeps ``cpu_s /
    elapsed_s`` CPUs busy (its run lanes and FFT threads), the other processes of the machine take
    the 1-minute load average less that, and a pool's speed-up is the CPUs it could use over those
    this process already uses.  Parallel only for a speed-up of MIN_SPEEDUP or more saving
    PAYS_FACTOR start-ups."""
    cpus = usable_cpus()
    if runs_left < MIN_PARALLEL_RUNS or cpus < 2 or bytes_done == 0 or elapsed_s <= 0:
        return True
    rest = elapsed_s / bytes_done * bytes_left
    busy = max(1.0, cpu_s / elapsed_s)
    free = min(cpus, max(1.0, cpus - (os.getloadavg()[0] - busy)))
    speedup = min(AUTO_WORKERS, free) / busy
    return speedup < MIN_SPEEDUP or rest * (1 - 1 / speedup) < PAYS_FACTOR * POOL_START_S


def run_batch(jobs: Sequence[tuple[str, str]], options: dict, *, workers: int | None = None,
              scheduler: str | None = None, out: str | None = None,
              on_done: Callable[[str, str, FrfResult], None] | None = None) -> list[FrfResult]:
    """FRFs of every (file, run_id) job in order.  ``workers`` 0 computes here (:func:`_here`: as many
    runs at once as idle CPUs), > 0 on a pool of that many local processes, None (automatic) here
    for as long as the measured cost of the runs done predicts no gain from a pool
    (:func:`_serial_pays`), then on a pool of AUTO_WORKERS; ``scheduler`` sends every job to an
    existing dask cluster.
    ``on_done(file, run_id, result)`` gets each result once no unfinished job reads the file it
    will be written to (``out`` if given, else its own file): that is when the caller may write it."""
    results: list[FrfResult | None] = [None] * len(jobs)
    deliver = _Deliver(jobs, on_done, lambda p: p if out is None else str(out))

    def done(k: int, result: FrfResult) -> None:
        results[k] = result
        deliver(k, result)

    first = 0
    if scheduler is None and not workers:
        first = _here(jobs, options, done, run_bytes(jobs) if workers is None else None)
        if first == len(jobs):
            return results
        workers = AUTO_WORKERS
    if scheduler is None:
        _in_pool(jobs, first, options, int(workers), done)
    else:
        _on_cluster(jobs, first, options, scheduler, done)
    return results


def _here(jobs, options: dict, done: Callable[[int, FrfResult], None], sizes: list[int] | None) -> int:
    """Jobs computed in this process, in order, ``done(k, result)`` for each; returns how many.

    The CPUs other processes leave idle (:func:`idle_cpus`) are shared out as lanes: as many runs
    at once as there are CPUs and runs left (threads: the reading and the FFTs release the GIL), the
    rest as FFT threads of each run, so one long run and many short ones both keep the idle CPUs
    busy.  With ``sizes`` (bytes of every run: the automatic choice) it stops submitting as soon as
    :func:`_serial_pays` says a pool would pay for the rest; the runs already started finish here."""
    from concurrent.futures import ThreadPoolExecutor

    cpus = idle_cpus()
    lanes = max(1, min(cpus, len(jobs)))
    threads = {"workers": max(1, cpus // lanes), **options}
    t0, c0 = time.perf_counter(), time.process_time()
    pool = ThreadPoolExecutor(lanes, thread_name_prefix="flexmodal-run") if lanes > 1 else None
    running: collections.deque = collections.deque()
    submitted = finished = 0
    last = len(jobs)                 # jobs[last:] go to a pool
    try:
        while submitted < last or running:
            while submitted < last and len(running) < lanes:
                if sizes is not None and not _serial_pays(time.perf_counter() - t0, time.process_time() - c0,
                                                          sum(sizes[:finished]), sum(sizes[finished:]),
                                                          len(jobs) - submitted):
                    last = submitted
                    break
                running.append(pool.submit(frf_job, *jobs[submitted], threads) if pool else None)
                submitted += 1
            if not running:
                break
            fut = running.popleft()
            done(finished, fut.result() if fut is not None else frf_job(*jobs[finished], threads))
            finished += 1
    finally:
        if pool is not None:
            pool.shutdown(wait=not running, cancel_futures=True)
    return finished


def _failed(job: tuple[str, str], exc: BaseException) -> ModalError:
    """A worker-side failure as one ModalError naming the run (a ModalError passes unchanged)."""
    return exc if isinstance(exc, ModalError) else ModalError(f"{job[0]}:{job[1]}: {exc}")


def _end_with_parent() -> None:
    """Initializer of a pool worker: on Linux, have the kernel send it SIGTERM when its parent (the
    fork server) ends, so that a worker started while Ctrl-C ends the command cannot outlive it; leave
    at once if the parent is already gone (the worker then belongs to init)."""
    parent = os.getppid()
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):   # not Linux: the pipes to the caller still end it later
        return
    if parent == 1 or os.getppid() != parent:
        os._exit(1)


def _in_pool(jobs, first: int, options: dict, workers: int, done: Callable[[int, FrfResult], None]) -> None:
    """Jobs ``first``.. on ``workers`` local processes, one FFT thread each; ``done(k, result)`` in
    completion order.  The processes come from a fork server that has imported only this module
    (no threads or open files of the caller are inherited; 0.3-1 s to start, not the seconds of a
    dask LocalCluster); each opens the runs it computes read-only, and only the caller writes."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload([__name__])
    one_thread = {**options, "workers": 1}
    pool = ProcessPoolExecutor(workers, mp_context=context, initializer=_end_with_parent)
    interrupted = False
    try:
        futures = {pool.submit(frf_job, str(Path(jobs[k][0]).resolve()), jobs[k][1], one_thread): k
                   for k in range(first, len(jobs))}   # absolute: the fork server keeps its own folder
        while futures:
            finished, _ = wait(futures, return_when=FIRST_COMPLETED)
            for fut in finished:
                k = futures.pop(fut)
                if fut.exception() is not None:
                    raise _failed(jobs[k], fut.exception())
                done(k, fut.result())
    except KeyboardInterrupt:  # Ctrl-C: leave now, not after the running jobs; the workers are the fork
        interrupted = True     # server's children, so the CLI's ending of its own would miss them
        for process in list((pool._processes or {}).values()):   # no public way before Python 3.14
            process.terminate()
        raise
    finally:
        pool.shutdown(wait=not interrupted, cancel_futures=True)


def _on_cluster(jobs, first: int, options: dict, scheduler: str,
                done: Callable[[int, FrfResult], None]) -> None:
    """Jobs ``first``.. on the dask.distributed cluster at ``scheduler`` (its workers read the runs
    from the same paths); ``done(k, result)`` in completion order."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ModalError(f"--scheduler {scheduler}: dask.distributed is not installed "
                         "(pip install 'flexmodal[cluster]')") from None
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, ValueError, TypeError) as exc:  # unreachable, or not an address (ValueError)
        raise ModalError(f"--scheduler {scheduler!r}: cannot connect ({one_line(exc)}; expected an address "
                         "such as tcp://127.0.0.1:8786)") from None
    interrupted = False
    try:
        futures = {client.submit(frf_job, str(Path(jobs[k][0]).resolve()), jobs[k][1], options, pure=False): k
                   for k in range(first, len(jobs))}   # absolute paths: workers run elsewhere
        for fut in as_completed(list(futures)):
            k = futures[fut]
            if fut.status == "error":
                raise _failed(jobs[k], fut.exception())
            done(k, fut.result())
    except KeyboardInterrupt:  # Ctrl-C: leave now (the CLI ends the cluster's processes with its own)
        interrupted = True
        raise
    finally:
        if not interrupted:
            client.close()


def frf_batch(paths: Sequence[str | Path], options: dict, *, workers: int | None = None,
              scheduler: str | None = None, out: str | Path | None = None, quiet: bool = False
              ) -> list[tuple[str, str]]:
    """Compute and write back the FRFs of all runs in ``paths`` (into ``out`` instead if given);
    returns the (file written, run_id) pairs.  Progress goes to stderr unless ``quiet``."""
    jobs = expand_runs(paths)
    if out is not None and len({r for _, r in jobs}) != len(jobs):
        raise ModalError(f"--out {out}: two input runs share a run id, they cannot go into one file")
    written = []
    with _progress(len(jobs), quiet) as advance:

        def done(path: str, rid: str, result: FrfResult) -> None:
            target = str(out) if out is not None else path
            write_frf(target, rid, result)
            written.append((target, rid))
            advance()

        run_batch(jobs, options, workers=workers, scheduler=scheduler, on_done=done,
                  out=None if out is None else str(out))
    order = {(str(out) if out is not None else p, r): k for k, (p, r) in enumerate(jobs)}
    return sorted(written, key=order.__getitem__)


@contextmanager
def _progress(total: int, quiet: bool) -> Iterator[Callable[[], None]]:
    """A transient progress bar on stderr (rich, imported only when shown); yields its advance."""
    if quiet:
        yield lambda: None
        return
    from rich.console import Console
    from rich.progress import Progress

    with Progress(transient=True, console=Console(file=sys.stderr)) as bar:
        task = bar.add_task("FRFs", total=total)
        yield lambda: bar.advance(task)
