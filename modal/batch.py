"""Batch FRFs of many stored runs: serially, with helper processes forked from this one, on a pool of
local worker processes, or on an existing dask.distributed scheduler, chosen by measured cost when
not asked for.  Helpers and workers read a run from its (shared) path and return its FRFs; the
calling process writes every result back, each file only once no unfinished job reads it any more
(HDF5 locks a file being written), so files are never written concurrently and the results are the
same whichever path computed them."""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

from flexmodal.checked_io.children import ctrl_c_blocked, leave_ctrl_c_to_parent
from flexmodal.checked_io.errors import FlexmodalError
from flexmodal.checked_io.progress import progress_bar
from flexmodal.checked_io.text import one_line
from flexmodal.daq.store import expand_runs, run_entries, runs_named_once
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.runs_io import write_frf
from flexmodal.modal.skipped import RunsFailed
from flexmodal.modal.spectra import usable_cpus

AUTO_WORKERS = 2        # CPUs the automatic choice uses at most (this process and its helpers)
FORK_S = 0.01           # wall s a helper costs this process: its fork and the pages it copies after it
HELPER_SHARE = 0.85     # a helper's run rate over this process's (it writes every result, and the two
                        # processes' memory-bound passes slow each other: 2 / 1.085 from the 6-11 % of
                        # CPU two FFT threads lose; benchmarks/batch.py COST measures it, if idle)
GAIN_FORKS = 3.0        # fork helpers only when they are predicted to save this many times FORK_S

def frf_job(path: str, run_id: str, options: dict) -> FrfResult:
    """Stream one run from its file and compute its FRFs (the unit of work sent to a worker)."""
    from flexmodal.daq.store import open_run

    with open_run(path, run_id) as run:
        try:
            return compute_frf(run, **options)
        except OSError as exc:  # a damaged chunk met while streaming the samples
            raise ModalError(f"{path}: run {run_id!r}: cannot read the samples ({one_line(exc)})") from None


def _attempt(path: str, run_id: str, options: dict) -> FrfResult | FlexmodalError:
    """:func:`frf_job`, a bad run's error (bad input) returned instead of raised: it is delivered in its
    turn like a result (:func:`run_batch`).  Any other exception is a bug and propagates."""
    try:
        return frf_job(path, run_id, options)
    except FlexmodalError as exc:
        return exc


def idle_cpus() -> int:
    """CPUs this process may use that the others leave idle: its own, plus the CPUs the machine left
    idle since the last look (:func:`_idle_cpus_between` of /proc/stat samples: the one idle-CPU
    estimator here), rounded, at most the CPUs it may use: the FFT threads and lanes of the serial path.
    The first look is this module's import, so for a command the interval is the process's own
    start (a fraction of a second: the machine now, not the 1-minute load average, which also counts
    this process once it has run a while); a look less than a tick per CPU after the last one reuses
    that one's interval.  On a busy machine a second thread only adds contention (measured under
    load 6 on 2 CPUs: 8 runs of 60 s took 1.13 s with 2 threads, 0.82 s with 1)."""
    now = _cpu_ticks()
    before = _LOOK[0]
    if before is not None and now is not None and now[0] - before[0] >= (os.cpu_count() or 1):
        _LOOK[:] = [now, before]      # long enough: the next look starts here
    else:
        before = _LOOK[1]             # too short (or unknown): measure from the look before
    return max(1, min(usable_cpus(), 1 + round(_idle_cpus_between(before, now))))


def run_bytes(jobs: Sequence[tuple[str, str]]) -> list[int]:
    """Bytes of samples of every (file, run_id) job, from the file metadata."""
    import h5py

    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.h5file import open_read
    from flexmodal.daq.run_schema import member

    sizes = []
    for path, rid in jobs:
        with open_read(path) as f:   # a truncated file fails here at once, as everywhere else
            ds: object = f
            try:   # member by member: a path 'runs/r2/samples' follows an external link (to a FIFO: hang)
                for name in ("runs", rid, "samples"):
                    ds = member(ds, name, path) if isinstance(ds, h5py.Group) else None
            except DaqError:   # a link not followed, or broken: the job itself names it
                ds = None
            sizes.append(int(ds.size) * ds.dtype.itemsize if isinstance(ds, h5py.Dataset) else 0)
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


def _cpu_ticks() -> tuple[int, int] | None:
    """(all, idle) clock ticks of the machine's CPUs so far, from the first line of /proc/stat (None
    where there is none); idle counts waiting for I/O too.  A niced process counts as busy: with
    the kernel's autogroups (one scheduling group per session) it competes at its group's weight."""
    try:
        with open("/proc/stat") as f:
            user, nice, system, idle, iowait, *rest = (int(v) for v in f.readline().split()[1:9])
    except (OSError, ValueError):
        return None
    return user + nice + system + idle + iowait + sum(rest), idle + iowait


def _idle_cpus_between(before: tuple[int, int] | None, after: tuple[int, int] | None) -> float:
    """CPUs the machine left available between two :func:`_cpu_ticks` samples, this process's own
    excluded (it kept one busy); 0 when unknown or less than a tick per CPU passed (in doubt, serial)."""
    cpus = os.cpu_count() or 1
    if before is None or after is None or after[0] - before[0] < cpus:
        return 0.0
    return cpus * (after[1] - before[1]) / (after[0] - before[0])


_LOOK: list = [_cpu_ticks(), None]   # idle_cpus' last sample and the one before (first: at import)


def _helpers_pay(elapsed_s: float, bytes_done: int, bytes_left: int, runs_left: int, idle: float,
                 usable: int | None = None) -> int:
    """Helper processes to fork for the rest of a batch (0: compute it here alone).

    From the runs done here so far (``elapsed_s`` wall, computing and writing, one FFT thread): the
    rest takes ``elapsed_s / bytes_done * bytes_left`` here.  With ``n`` helpers (one per CPU left
    ``idle`` while this process computed, at most AUTO_WORKERS CPUs in all) it takes that over
    ``1 + n * HELPER_SHARE`` (the measured rate of a helper against this process's, which also writes
    every result), and never less than one run of the rest; each helper costs FORK_S.  Helpers only
    when they save GAIN_FORKS times their forks: in doubt, serial.  ``usable``: the CPUs this process
    may use (default: its affinity now)."""
    if runs_left < 2 or bytes_done <= 0:
        return 0
    n = min(AUTO_WORKERS, usable_cpus() if usable is None else usable, 1 + int(idle + 0.5)) - 1
    if n < 1:
        return 0
    rest = elapsed_s / bytes_done * bytes_left
    gain = rest - max(rest / (1 + n * HELPER_SHARE), rest / runs_left) - n * FORK_S
    return n if gain >= GAIN_FORKS * n * FORK_S else 0


def run_batch(jobs: Sequence[tuple[str, str]], options: dict, *, workers: int | None = None,
              scheduler: str | None = None, out: str | None = None,
              on_done: Callable[[str, str, FrfResult], None] | None = None,
              keep_going: bool = False) -> list[FrfResult]:
    """FRFs of every (file, run_id) job in order.  ``workers`` 0 computes here (:func:`_here`: as many
    runs at once as idle CPUs), > 0 on a pool of that many local processes, None (automatic) here,
    with helper processes forked from this one once the measured cost of the runs done predicts a
    gain from them (:func:`_auto`); ``scheduler`` sends every job to an existing dask cluster.
    ``on_done(file, run_id, result)`` gets each result once no unfinished job reads the file it
    will be written to (``out`` if given, else its own file): that is when the caller may write it.
    A bad run (a FlexmodalError) raises its error in its turn, or with ``keep_going`` is delivered like
    a result, its error in place of the FRFs, and the batch goes on."""
    results: list[FrfResult | None] = [None] * len(jobs)
    deliver = _Deliver(jobs, on_done, lambda p: p if out is None else str(out))

    def done(k: int, result: FrfResult | FlexmodalError) -> None:
        if isinstance(result, FlexmodalError) and not keep_going:
            raise result
        results[k] = result
        deliver(k, result)

    if scheduler is not None:
        _on_cluster(jobs, options, scheduler, done)
    elif workers:
        _in_pool(jobs, options, int(workers), done)
    else:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):   # restored after: see _auto
            (_auto if workers is None else _here)(jobs, options, done)
    return results


def _here(jobs, options: dict, done: Callable[[int, FrfResult], None]) -> None:
    """Every job, ``done(k, result)`` for each in order, computed in this process: the CPUs other
    processes leave idle (:func:`idle_cpus`) are shared out as lanes, as many runs at once as there
    are CPUs and runs left (threads: the reading and the FFTs release the GIL), the rest as FFT
    threads of each run, so one long run and many short ones both keep the idle CPUs busy."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    cpus = idle_cpus()
    lanes = max(1, min(cpus, len(jobs)))
    threads = {"workers": max(1, cpus // lanes), **options}
    if lanes == 1:
        for k, job in enumerate(jobs):
            done(k, _attempt(*job, threads))
        return
    executor = ThreadPoolExecutor(lanes, thread_name_prefix="flexmodal-run")
    running: dict = {}               # future -> job
    held: dict[int, FrfResult] = {}  # results waiting for those of earlier jobs
    submitted = delivered = 0
    try:
        while delivered < len(jobs):
            while submitted < len(jobs) and len(running) < lanes:
                running[executor.submit(_attempt, *jobs[submitted], threads)] = submitted
                submitted += 1
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in finished:
                held[running.pop(fut)] = fut.result()
            while delivered in held:
                done(delivered, held.pop(delivered))
                delivered += 1
    finally:   # Ctrl-C or a failure: the runs still running are not waited for
        executor.shutdown(wait=not running, cancel_futures=True)


def _auto(jobs, options: dict, done: Callable[[int, FrfResult], None]) -> None:
    """Every job, ``done(k, result)`` for each in order: computed here one after the other (a lone run
    with the idle CPUs as FFT threads, else one), and, once :func:`_helpers_pay` says so from the runs
    done and the CPUs left idle meanwhile, shared with :class:`_Helpers` forked from this process.
    Helpers are forked between two runs, when this process runs no other thread (the run's reader
    thread has ended; a process with threads of its own stays serial: a thread's lock held at the
    fork would stay held in the helper): they start at once, with everything imported.  With one
    FFT thread this process is pinned to the CPU it runs on meanwhile, a helper to the next
    (:func:`_this_cpu_first`; the mask is restored after).  The caller
    (:func:`run_batch`) keeps BLAS to one thread meanwhile, helpers inherit it: after each call an
    OpenBLAS thread spins on another CPU for a while, the helper's (8 runs of 60 s here: 0.28 s of
    CPU with one BLAS thread, 0.30-0.39 s with two, and 0.1 s more at numpy's import)."""
    import time

    one = {**options, "workers": idle_cpus() if len(jobs) == 1 else 1}
    sizes = run_bytes(jobs) if len(jobs) > 1 else []
    mask, cpus = _this_cpu_first() if one["workers"] == 1 else (None, None)
    t0, ticks = time.perf_counter(), _cpu_ticks()
    try:
        if cpus:
            os.sched_setaffinity(0, cpus[:1])
        for k, job in enumerate(jobs):
            done(k, _attempt(*job, one))
            if k + 1 < len(jobs) and _forkable():
                n = _helpers_pay(time.perf_counter() - t0, sum(sizes[:k + 1]), sum(sizes[k + 1:]),
                                 len(jobs) - k - 1, _idle_cpus_between(ticks, _cpu_ticks()),
                                 len(cpus) if cpus else None)
                if n:
                    _Helpers(n, jobs, k + 1, one, cpus if cpus and len(cpus) == n + 1 else None).share(done)
                    return
    finally:
        if cpus:
            os.sched_setaffinity(0, mask)


def _forkable() -> bool:
    """Whether helpers may be forked now: the platform has fork and this process runs no other thread
    (a lock another thread holds at the fork stays held in the helper)."""
    return hasattr(os, "fork") and threading.active_count() == 1


def _this_cpu_first() -> tuple[set[int] | None, list[int] | None]:
    """(this thread's CPU mask, its CPUs with the one it runs on first), or (None, None) where Linux's
    /proc and affinity calls are missing or only one CPU is usable.  :func:`_auto` pins itself to that
    CPU while it computes and a helper to the next: a run's reader thread then stays on the CPU of
    its FFTs. Unpinned, that thread takes another CPU in turns: the same runs took 5-8 % more CPU in
    all (`frf`, 100 runs of 60 s with a helper, load 10), and with the kernel's autogroups a session
    whose threads sit on two CPUs has its weight split between them, so beside other sessions' work
    the serial path ran at 0.79-0.88x the pinned one (benchmarks/batch.py, load 3-5)."""
    try:
        mask = os.sched_getaffinity(0)
        with open("/proc/thread-self/stat") as f:
            here = int(f.read().rsplit(")", 1)[1].split()[36])
    except (AttributeError, OSError, ValueError, IndexError):
        return None, None
    if len(mask) < 2 or here not in mask:
        return None, None
    return mask, [here, *sorted(mask - {here})]


class _Helpers:
    """``n`` processes forked from this one that share the jobs from ``first`` on with it: each takes
    the next job not yet taken (so the runs are shared by speed, and this process, which also writes
    every result, takes fewer), reads it from its file and sends its FRFs back through a pipe.

    A thread per helper here receives its results and hands it its next job as soon as one arrives
    (the helper waits only for the hand-over); results are written in run order by the caller, a
    failure raised when its run's turn comes (as serially: every earlier run is written first).  With
    ``cpus`` (this process's CPU, where it is pinned already, then one per helper) each helper is
    pinned to its own (:func:`_this_cpu_first`).  A helper
    starts with SIGINT blocked, ignores it, and asks the kernel to end it with this process; Ctrl-C
    or a failure here ends the helpers (SIGTERM) before this process goes on, and a job whose helper
    died is computed here."""

    def __init__(self, n: int, jobs, first: int, options: dict, cpus: list[int] | None = None) -> None:
        self.jobs, self.options, self.first, self.next = jobs, options, first, first
        self.lock = threading.Lock()
        self.replies: queue.SimpleQueue = queue.SimpleQueue()
        self.helpers: list[tuple[int, object, object]] = []    # (pid, jobs to it, results from it)
        parent = os.getpid()
        self.cpus = cpus                # this process's CPU, then one per helper (None: unpinned)
        try:
            for i in range(n):
                if not self._fork(i, parent):
                    break
        except BaseException:   # Ctrl-C (delivered once SIGINT is unblocked): end those forked
            self.close(kill=True)
            raise
        for _, to_helper, from_helper in self.helpers:
            threading.Thread(target=self._relay, args=(to_helper, from_helper), name="flexmodal-helper",
                             daemon=True).start()

    def _fork(self, i: int, parent: int) -> bool:
        """Fork helper ``i`` (False: the system has no process left for it)."""
        from multiprocessing.connection import Pipe

        inbox, to_helper = Pipe(duplex=False)
        from_helper, outbox = Pipe(duplex=False)
        with ctrl_c_blocked():          # the helper starts deaf to Ctrl-C
            try:
                pid = os.fork()
            except OSError:
                for conn in (inbox, outbox, to_helper, from_helper):
                    conn.close()
                return False
            if pid == 0:                # the helper: it never returns into the caller's frames
                code = 1
                try:
                    leave_ctrl_c_to_parent()
                    _end_with_parent(parent)
                    if self.cpus:
                        os.sched_setaffinity(0, {self.cpus[i + 1]})
                    for conn in (to_helper, from_helper, *(c for h in self.helpers for c in h[1:])):
                        conn.close()
                    _serve(self.jobs, self.options, inbox, outbox)
                    code = 0
                finally:
                    os._exit(code)
            self.helpers.append((pid, to_helper, from_helper))   # before a Ctrl-C can come
        inbox.close()
        outbox.close()
        return True

    def take(self) -> int | None:
        """The next job not yet taken (None: none left)."""
        with self.lock:
            if self.next >= len(self.jobs):
                return None
            self.next += 1
            return self.next - 1

    def _relay(self, to_helper, from_helper) -> None:
        """Hand one helper its jobs and queue its replies (k, result, error); a helper that ended
        with a job queues (k, None, None): computed here."""
        k = self.take()
        try:
            while k is not None:
                try:
                    to_helper.send(k)
                    reply = from_helper.recv()
                except (EOFError, OSError):
                    self.replies.put((k, None, None))
                    return
                except Exception as exc:  # noqa: BLE001 - a reply that cannot be unpickled here
                    reply = (k, None, _failed(self.jobs[k], exc))
                k = self.take()
                self.replies.put(reply)
        finally:
            to_helper.close()   # the helper ends on end of file
            from_helper.close()

    def share(self, done: Callable[[int, FrfResult], None]) -> None:
        """Compute here the jobs the helpers leave, ``done(k, result)`` for every job from the first
        in order; the helpers are ended (on Ctrl-C or a failure) or waited for on the way out."""
        held: dict[int, tuple] = {}
        delivered = self.first
        ended = False
        try:
            while delivered < len(self.jobs):
                k = self.take()
                if k is not None:
                    held[k] = self._here(k)
                while (reply := self._reply(block=k is None and delivered not in held)) is not None:
                    held[reply[0]] = reply[1:] if reply[1] is not None or reply[2] is not None \
                        else self._here(reply[0])
                while delivered in held:
                    result, error = held.pop(delivered)
                    if error is not None:
                        raise error
                    done(delivered, result)
                    delivered += 1
            ended = True
        finally:
            self.close(kill=not ended)

    def _here(self, k: int) -> tuple:
        try:
            return _attempt(*self.jobs[k], self.options), None
        except Exception as exc:  # noqa: BLE001 - raised in run order, as serially
            return None, exc

    def _reply(self, block: bool) -> tuple | None:
        try:
            return self.replies.get(block=block)
        except queue.Empty:
            return None

    def close(self, kill: bool) -> None:
        """Wait for the helpers to end (they do once no job is left); with ``kill``, end them now."""
        for pid, _, _ in self.helpers:
            if kill:
                try:
                    os.kill(pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        for pid, _, _ in self.helpers:
            try:
                os.waitpid(pid, 0)
            except ChildProcessError:   # reaped already (SIGCHLD ignored by the calling program)
                pass


def _serve(jobs, options: dict, inbox, outbox) -> None:
    """A helper's loop: compute each job whose index comes through ``inbox`` and send (k, result,
    error) through ``outbox``, until end of file."""
    while True:
        try:
            k = inbox.recv()
        except EOFError:
            return
        try:
            reply = (k, _attempt(*jobs[k], options), None)
        except Exception as exc:  # noqa: BLE001 - sent, raised by the caller in run order
            reply = (k, None, exc)
        try:
            outbox.send(reply)
        except OSError:          # the caller is gone
            return
        except Exception as exc:  # noqa: BLE001 - a failure that cannot be pickled: its message
            outbox.send((k, None, _failed(jobs[k], exc if reply[2] is None else reply[2])))


def _failed(job: tuple[str, str], exc: BaseException) -> ModalError:
    """A worker-side failure as one ModalError naming the run (a ModalError passes unchanged)."""
    return exc if isinstance(exc, ModalError) else ModalError(f"{job[0]}:{job[1]}: {exc}")


def _end_with_parent(parent: int | None = None) -> None:
    """On Linux, have the kernel send this worker SIGTERM when its parent (the fork server, or the
    process ``parent`` that forked this helper) ends, so that a worker started while Ctrl-C ends the
    command cannot outlive it; leave at once if the parent is already gone (the worker then belongs
    to init)."""
    parent = os.getppid() if parent is None else parent
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
    private process table of the executor.

    The fork server is started (when none runs yet) with SIGINT blocked (:func:`ctrl_c_blocked`):
    it and every worker it forks start deaf to a terminal's Ctrl-C, through the interpreter's start,
    the fork server's imports and the worker's start, until the worker ignores it
    (:func:`_start_worker`); the caller alone answers it."""

    def __init__(self, workers: int, options: dict) -> None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
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

    def submit(self, job: tuple[str, str]):
        """Future of the FRFs of one (file, run_id) job (absolute path: the fork server keeps its own
        folder)."""
        return self.executor.submit(frf_job, str(Path(job[0]).resolve()), job[1], self.options)

    def close(self, kill: bool) -> None:
        """Shut the pool down; with ``kill`` (Ctrl-C) end its processes now, not after their jobs."""
        if kill:
            while not self.pids.empty():
                try:
                    os.kill(self.pids.get(), signal.SIGTERM)
                except ProcessLookupError:   # ended already
                    pass
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
                done(k, fut.result() if fut.exception() is None else _failed(jobs[k], fut.exception()))
    except KeyboardInterrupt:  # Ctrl-C: leave now, not after the running jobs; the workers are the fork
        interrupted = True     # server's children, so the CLI's ending of its own would miss them
        raise
    finally:
        pool.close(kill=interrupted)


SCHEDULER_WAIT_S = 30.0  # a dask.distributed Client's own timeout covers the TCP connect, not the handshake


def _client(client_type, scheduler: str):
    """A dask.distributed client of ``scheduler``, or ModalError naming the address: unreachable, not
    an address, or silent (a server that accepts the connection and never answers, e.g. a web server
    or a port forward to nothing, held Client() for ever: it is made in a daemon thread, waited on for
    :data:`SCHEDULER_WAIT_S`).  A client that connects only after that wait is closed at once: it would
    stay registered as dask's default client (global state) with nobody to close it."""
    box: dict[str, object] = {}
    lock = threading.Lock()

    def connect() -> None:
        try:
            client = client_type(scheduler, timeout="10s")
        except BaseException as exc:   # handed to the caller's thread
            box["error"] = exc
            return
        with lock:
            abandoned = bool(box.get("abandoned"))
            box["client"] = client
        if abandoned:
            with contextlib.suppress(Exception):   # nobody is left to hear of it
                client.close()

    thread = threading.Thread(target=connect, name="flexmodal-scheduler-connect", daemon=True)
    thread.start()
    thread.join(SCHEDULER_WAIT_S)
    with lock:
        silent = "client" not in box and "error" not in box
        box["abandoned"] = silent
    exc = box.get("error")
    if silent or isinstance(exc, OSError | ValueError | TypeError):   # ValueError: not an address
        why = f"no answer within {SCHEDULER_WAIT_S:g} s" if silent else one_line(exc)
        raise ModalError(f"--scheduler {scheduler!r}: cannot connect ({why}; expected the address of a "
                         "dask.distributed scheduler such as tcp://127.0.0.1:8786)")
    if exc is not None:
        raise exc
    return box["client"]


def _on_cluster(jobs, options: dict, scheduler: str, done: Callable[[int, FrfResult], None]) -> None:
    """Every job on the dask.distributed cluster at ``scheduler`` (its workers read the runs
    from the same paths); ``done(k, result)`` in completion order."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ModalError(f"--scheduler {scheduler}: dask.distributed is not installed "
                         "(pip install 'flexmodal[cluster]')") from None
    client = _client(Client, scheduler)
    interrupted = False
    try:
        futures = {client.submit(frf_job, str(Path(jobs[k][0]).resolve()), jobs[k][1], options, pure=False): k
                   for k in range(len(jobs))}   # absolute paths: workers run elsewhere
        for fut in as_completed(list(futures)):
            k = futures[fut]
            done(k, _failed(jobs[k], fut.exception()) if fut.status == "error" else fut.result())
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
    returns the (file written, run_id) pairs.  Progress goes to stderr unless ``quiet``.  A bad run
    (or a file that holds none) does not stop the others: every good run is written, then
    :class:`~flexmodal.modal.errors.RunsFailed` names each bad one (one bad run alone: its own error)."""
    jobs, failed = [], []
    for entry in run_entries(paths):
        try:
            jobs += expand_runs([entry])
        except FlexmodalError as exc:      # a file missing, unreadable or holding no runs
            failed.append((-1, str(entry), exc))
    runs_named_once(jobs)
    if out is not None and len({r for _, r in jobs}) != len(jobs):
        raise ModalError(f"--out {out}: two input runs share a run id, they cannot go into one file")
    if out is not None:
        _check_out_runs(out, jobs)
    written = []
    with progress_bar(len(jobs), "FRFs", quiet) as advance:

        def done(path: str, rid: str, result: FrfResult | FlexmodalError) -> None:
            if isinstance(result, FlexmodalError):
                failed.append((order[(str(path), rid)], f"{path}:{rid}", result))
            else:
                target = str(out) if out is not None else path
                write_frf(target, rid, result)
                written.append((order[(str(path), rid)], target, rid))
            advance()

        order = {(str(p), r): k for k, (p, r) in enumerate(jobs)}
        run_batch(jobs, options, workers=workers, scheduler=scheduler, on_done=done,
                  out=None if out is None else str(out), keep_going=True)
    done_runs = [(target, rid) for _, target, rid in sorted(written)]
    if len(failed) == 1 and not done_runs:
        raise failed[0][2]
    if failed:
        raise RunsFailed(done_runs, [(name, exc) for _, name, exc in sorted(failed, key=lambda f: f[0])])
    return done_runs


def _check_out_runs(out: str | Path, jobs: Sequence[tuple[str, str]]) -> None:
    """ModalError when ``out`` already holds, under the id of an input run, another run with its own
    samples: the FRFs of ``FILE:r1`` would be stored as that run's (replacing its own), beside samples
    they were not computed from.  A run group holding only FRFs (an earlier ``--out``) is replaced;
    ``out`` being the input file itself is writing back."""
    import h5py

    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.h5file import open_read
    from flexmodal.daq.run_schema import member

    if not Path(out).is_file():
        return
    foreign = [(p, r) for p, r in jobs if not os.path.samefile(p, out)]
    if not foreign:
        return
    with open_read(out) as f:
        for path, rid in foreign:
            try:   # member by member: 'runs/r1/samples' in f opens an external link on the way (a FIFO: hang)
                runs = member(f, "runs", f"--out {out}")
                run = member(runs, rid, f"--out {out}: runs") if isinstance(runs, h5py.Group) else None
            except DaqError as exc:   # the FRFs would be written through that link: refused
                raise ModalError(str(exc)) from None
            if isinstance(run, h5py.Group) and run.get("samples", getlink=True) is not None:
                raise ModalError(f"--out {out}: run {rid!r} there is another run with its own samples; the "
                                 f"FRFs of {path}:{rid} would replace its own and sit beside data they were "
                                 "not computed from (choose another --out)")
