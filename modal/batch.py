"""Batch FRFs of many stored runs: serially, on a pool of local worker processes, or on an existing
dask.distributed scheduler, chosen by measured cost when not asked for.  Workers stream a run from
its (shared) path and return its FRFs; the calling process writes every result back, each file only
once no worker reads it any more (HDF5 locks a file being written), so files are never written
concurrently and the results are the same whichever path computed them."""

from __future__ import annotations

import os
import signal
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from flexmodal.checked_io.children import ctrl_c_blocked, leave_ctrl_c_to_parent
from flexmodal.checked_io.text import one_line
from flexmodal.daq.store import expand_runs
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.runs_io import write_frf
from flexmodal.modal.spectra import usable_cpus

POOL_START_S = 0.4      # CPU s a pool's start takes from the lanes: its fork server's imports
AUTO_WORKERS = 2        # CPUs the automatic choice's pool and lane use at most
MIN_SPEEDUP = 1.2       # go parallel only when the predicted speed-up is at least this,
PAYS_FACTOR = 1.0       # the predicted saving at least the CPU a start-up takes,
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
    """True while computing the rest here is predicted no worse than with a pool joining in (one lane
    here and a process per other CPU, at most AUTO_WORKERS CPUs in all).

    From the runs done so far (``elapsed_s`` wall, ``cpu_s`` CPU of this process, every thread):
    the rest takes ``elapsed_s / bytes_done * bytes_left`` here; this process keeps ``cpu_s /
    elapsed_s`` CPUs busy (its run lanes and FFT threads: less than its lanes, as the Python and
    HDF5 parts of a run hold the GIL), the other processes of the machine take the 1-minute load
    average less that, and a pool's speed-up is the CPUs it could use (each process keeps one busy)
    over those this process already uses.  Parallel only for a speed-up of MIN_SPEEDUP or more
    saving PAYS_FACTOR start-ups (the pool starts in the background, so its start costs the CPU it
    takes from the lanes, not waiting)."""
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
    runs at once as idle CPUs), > 0 on a pool of that many local processes, None (automatic) here,
    with a pool joining in once the measured cost of the runs done predicts a gain from it
    (:func:`_serial_pays`); ``scheduler`` sends every job to an existing dask cluster.
    ``on_done(file, run_id, result)`` gets each result once no unfinished job reads the file it
    will be written to (``out`` if given, else its own file): that is when the caller may write it."""
    results: list[FrfResult | None] = [None] * len(jobs)
    deliver = _Deliver(jobs, on_done, lambda p: p if out is None else str(out))

    def done(k: int, result: FrfResult) -> None:
        results[k] = result
        deliver(k, result)

    if scheduler is not None:
        _on_cluster(jobs, options, scheduler, done)
    elif workers:
        _in_pool(jobs, options, int(workers), done)
    else:
        _here(jobs, options, done, run_bytes(jobs) if workers is None else None)
    return results


def _here(jobs, options: dict, done: Callable[[int, FrfResult], None], sizes: list[int] | None) -> None:
    """Every job, ``done(k, result)`` for each in order, computed in this process and, when the
    automatic choice says so, by a pool of processes joining in.

    The CPUs other processes leave idle (:func:`idle_cpus`) are shared out as lanes: as many runs
    at once as there are CPUs and runs left (threads: the reading and the FFTs release the GIL), the
    rest as FFT threads of each run, so one long run and many short ones both keep the idle CPUs
    busy.  With ``sizes`` (bytes of every run: the automatic choice), as soon as :func:`_serial_pays`
    says a pool would pay for the rest, a :class:`_Pool` of one process per idle CPU but one (at most
    AUTO_WORKERS CPUs in all) starts in the background while the lanes go on; once it runs, this
    process keeps one lane and the pool takes every other job (two in flight per process), so its
    start-up costs no waiting."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    cpus = idle_cpus()
    lanes = max(1, min(cpus, len(jobs)))
    threads = {"workers": max(1, cpus // lanes), **options}
    t0, c0 = time.perf_counter(), time.process_time()
    executor = ThreadPoolExecutor(lanes, thread_name_prefix="flexmodal-run") if lanes > 1 else None
    pool: _Pool | None = None
    running: dict = {}               # future -> job (lanes and pool alike)
    in_pool: set = set()             # those futures the pool computes
    held: dict[int, FrfResult] = {}  # results waiting for those of earlier jobs
    submitted = delivered = bytes_done = 0
    interrupted = False
    try:
        while delivered < len(jobs):
            if pool is None and sizes and executor and bytes_done and not _serial_pays(
                    time.perf_counter() - t0, time.process_time() - c0, bytes_done, sum(sizes[submitted:]),
                    len(jobs) - submitted):
                pool = _Pool(max(1, min(AUTO_WORKERS, cpus) - 1), options, background=True)
            joined = pool is not None and pool.ready.done() and pool.ready.exception() is None
            while submitted < len(jobs):
                if joined and len(in_pool) < 2 * pool.workers:
                    fut = pool.submit(jobs[submitted])
                    in_pool.add(fut)
                elif len(running) - len(in_pool) < (1 if joined else lanes):
                    fut = executor.submit(frf_job, *jobs[submitted], threads) if executor else None
                else:
                    break
                running[fut] = submitted
                submitted += 1
            if executor is None:     # one lane: computed right here
                k = running.pop(None)
                held[k] = frf_job(*jobs[k], threads)
            else:
                waits = set(running) | ({pool.ready} if pool is not None and not pool.ready.done() else set())
                finished, _ = wait(waits, return_when=FIRST_COMPLETED)
                for fut in finished & running.keys():
                    k = running.pop(fut)
                    if fut in in_pool:
                        in_pool.discard(fut)
                        if fut.exception() is not None:
                            raise _failed(jobs[k], fut.exception())
                    held[k] = fut.result()
                    bytes_done += sizes[k] if sizes is not None else 0
            while delivered in held:
                done(delivered, held.pop(delivered))
                delivered += 1
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:   # a pool that never joined in (the lanes were done first) is not waited for
        if pool is not None:
            pool.close(kill=interrupted or not pool.ready.done())
        if executor is not None:
            executor.shutdown(wait=not running, cancel_futures=True)


def _failed(job: tuple[str, str], exc: BaseException) -> ModalError:
    """A worker-side failure as one ModalError naming the run (a ModalError passes unchanged)."""
    return exc if isinstance(exc, ModalError) else ModalError(f"{job[0]}:{job[1]}: {exc}")


def _end_with_parent() -> None:
    """On Linux, have the kernel send this worker SIGTERM when its parent (the fork server) ends, so
    that a worker started while Ctrl-C ends the command cannot outlive it; leave at once if the parent
    is already gone (the worker then belongs to init)."""
    parent = os.getppid()
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):   # not Linux: the pipes to the caller still end it later
        return
    if parent == 1 or os.getppid() != parent:
        os._exit(1)


def _start_worker(pids) -> None:
    """Initializer of a pool worker: leave Ctrl-C to the caller (a terminal's Ctrl-C reaches every
    process of the command; the caller ends its workers), end with the fork server
    (:func:`_end_with_parent`), tell the caller its process id through the queue ``pids`` (so a Ctrl-C
    can end it at once, with the public ``os.kill``) and keep BLAS to one thread (the pool's processes
    already use every CPU it was given; a BLAS pool of its own in each would only oversubscribe them).
    With the environment variable ``FLEXMODAL_STOP_AT=worker-start`` a worker stops itself (SIGSTOP)
    first, so that a test can send Ctrl-C while a worker has not yet ignored it."""
    if os.environ.get("FLEXMODAL_STOP_AT") == "worker-start":
        os.kill(os.getpid(), signal.SIGSTOP)
    leave_ctrl_c_to_parent()
    _end_with_parent()
    pids.put(os.getpid())
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, "blas")     # this worker process's own state, for its whole life


class _Pool:
    """``workers`` local processes for :func:`frf_job`, from a fork server that has imported only this
    module (no threads or open files of the caller are inherited), one FFT thread each.  Each reports
    its process id at start; :meth:`close` with ``kill`` ends them at once (SIGTERM), without the
    private process table of the executor.  ``background`` starts the processes in a thread of this
    process (the fork server's imports take 0.3-1 s) and completes :attr:`ready` once they run, so the
    caller keeps computing meanwhile.

    The fork server is started (when none runs yet) with SIGINT blocked (:func:`ctrl_c_blocked`):
    it and every worker it forks start deaf to a terminal's Ctrl-C, through the interpreter's start,
    the fork server's imports and the worker's start, until the worker ignores it
    (:func:`_start_worker`); the caller alone answers it."""

    def __init__(self, workers: int, options: dict, background: bool = False) -> None:
        import multiprocessing
        import threading
        from concurrent.futures import Future, ProcessPoolExecutor
        from multiprocessing import forkserver, resource_tracker

        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload([__name__])
        resource_tracker.ensure_running()   # first: it starts deaf to SIGINT itself, then unblocks SIGINT
        with ctrl_c_blocked():              # fork and exec of the fork server: milliseconds
            forkserver.ensure_running()
        self.workers = workers
        self.options = {**options, "workers": 1}
        self.pids = context.SimpleQueue()
        self.executor = ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker,
                                            initargs=(self.pids,))
        self.ready: Future = Future()
        self._lock = threading.Lock()
        self._abandoned = False
        if background:   # not a daemon: the interpreter's exit waits for it to end what it started
            threading.Thread(target=self._start, name="flexmodal-pool-start").start()
        else:
            self.ready.set_result(True)

    def _start(self) -> None:
        try:   # one trivial task per process: each is spawned (and has started) when its task returns
            for fut in [self.executor.submit(os.getpid) for _ in range(self.workers)]:
                fut.result()
            self.ready.set_result(True)
        except BaseException as exc:  # noqa: BLE001 - a pool that cannot start: handed to the caller
            self.ready.set_exception(exc)
        with self._lock:
            if self._abandoned:     # closed while starting: ended here, once the executor is free
                self._end(kill=True)

    def submit(self, job: tuple[str, str]):
        """Future of the FRFs of one (file, run_id) job (absolute path: the fork server keeps its own
        folder)."""
        return self.executor.submit(frf_job, str(Path(job[0]).resolve()), job[1], self.options)

    def close(self, kill: bool) -> None:
        """Shut the pool down; with ``kill`` (Ctrl-C, or a pool no longer needed) end its processes
        now, not after their jobs.  A pool still starting in the background is never waited for (the
        executor is busy spawning): the processes started so far are ended now, the others by the
        starting thread once spawned (the interpreter's exit waits for that thread: a process spawned
        after this one's exit had removed the executor's semaphores would print a traceback)."""
        with self._lock:
            if not self.ready.done():
                self._abandoned = True
                self._kill()
                return
        self._end(kill)

    def _kill(self) -> None:
        while not self.pids.empty():
            try:
                os.kill(self.pids.get(), signal.SIGTERM)
            except ProcessLookupError:   # ended already
                pass

    def _end(self, kill: bool) -> None:
        if kill:
            self._kill()
        self.executor.shutdown(wait=not kill, cancel_futures=True)


def _in_pool(jobs, options: dict, workers: int, done: Callable[[int, FrfResult], None]) -> None:
    """Every job on a :class:`_Pool` of ``workers`` processes; ``done(k, result)`` in completion
    order.  Each process opens the runs it computes read-only, and only the caller writes."""
    from concurrent.futures import FIRST_COMPLETED, wait

    pool = _Pool(workers, options)
    interrupted = False
    try:
        futures = {pool.submit(job): k for k, job in enumerate(jobs)}
        while futures:
            finished, _ = wait(futures, return_when=FIRST_COMPLETED)
            for fut in finished:
                k = futures.pop(fut)
                if fut.exception() is not None:
                    raise _failed(jobs[k], fut.exception())
                done(k, fut.result())
    except KeyboardInterrupt:  # Ctrl-C: leave now, not after the running jobs; the workers are the fork
        interrupted = True     # server's children, so the CLI's ending of its own would miss them
        raise
    finally:
        pool.close(kill=interrupted)


def _on_cluster(jobs, options: dict, scheduler: str, done: Callable[[int, FrfResult], None]) -> None:
    """Every job on the dask.distributed cluster at ``scheduler`` (its workers read the runs
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
                   for k in range(len(jobs))}   # absolute paths: workers run elsewhere
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
    if out is not None:
        _check_out_runs(out, jobs)
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


def _check_out_runs(out: str | Path, jobs: Sequence[tuple[str, str]]) -> None:
    """ModalError when ``out`` already holds, under the id of an input run, another run with its own
    samples: the FRFs of ``FILE:r1`` would be stored as that run's (replacing its own), beside samples
    they were not computed from.  A run group holding only FRFs (an earlier ``--out``) is replaced;
    ``out`` being the input file itself is writing back."""
    from flexmodal.daq.h5file import open_read

    if not Path(out).is_file():
        return
    foreign = [(p, r) for p, r in jobs if not os.path.samefile(p, out)]
    if not foreign:
        return
    with open_read(out) as f:
        for path, rid in foreign:
            if f"runs/{rid}/samples" in f:
                raise ModalError(f"--out {out}: run {rid!r} there is another run with its own samples; the "
                                 f"FRFs of {path}:{rid} would replace its own and sit beside data they were "
                                 "not computed from (choose another --out)")


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
