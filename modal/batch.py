"""Batch FRFs of many stored runs: serially, on a dask.distributed LocalCluster (worker processes bound
to 127.0.0.1, no dashboard) or on an existing scheduler, chosen by measured cost when not asked for.
Workers stream a run from its (shared) path and return its FRFs; the calling process writes every
result back, each file only once no worker reads it any more (HDF5 locks a file being written), so
files are never written concurrently and the results are the same whichever path computed them."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from flexmodal.daq.store import expand_runs
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.runs_io import write_frf

CLUSTER_START_S = 6.0   # import distributed, start 2 worker processes, first task (benchmarks/batch.py)
AUTO_WORKERS = 2        # processes of the cluster the automatic choice starts
MIN_SPEEDUP = 1.5       # go parallel only when the predicted speed-up is at least this,
PAYS_FACTOR = 3.0       # the predicted saving at least 3 start-ups,
MIN_PARALLEL_RUNS = 4   # and at least this many runs remain


def frf_job(path: str, run_id: str, options: dict) -> FrfResult:
    """Stream one run from its file and compute its FRFs (the unit of work sent to a worker)."""
    from flexmodal.daq.store import open_run

    with open_run(path, run_id) as run:
        return compute_frf(run, **options)


def run_bytes(jobs: Sequence[tuple[str, str]]) -> list[int]:
    """Bytes of samples of every (file, run_id) job, from the file metadata."""
    import h5py

    sizes = []
    for path, rid in jobs:
        with h5py.File(path, "r", libver="latest", swmr=True) as f:
            ds = f.get(f"runs/{rid}/samples")
            sizes.append(0 if ds is None else int(ds.size) * ds.dtype.itemsize)
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
    """True while computing the rest here is predicted no worse than a cluster of AUTO_WORKERS.

    From the runs done so far (``elapsed_s`` wall, ``cpu_s`` CPU of this process, every thread):
    the rest takes ``elapsed_s / bytes_done * bytes_left`` here; this process keeps ``cpu_s /
    elapsed_s`` CPUs busy (its FFT threads), the other processes of the machine take the 1-minute
    load average less that, and a cluster's speed-up is the CPUs it could use over those this process
    already uses.  Parallel only for a speed-up of MIN_SPEEDUP or more saving PAYS_FACTOR start-ups."""
    cpus = os.cpu_count() or 1
    if runs_left < MIN_PARALLEL_RUNS or cpus < 2 or bytes_done == 0 or elapsed_s <= 0:
        return True
    rest = elapsed_s / bytes_done * bytes_left
    busy = max(1.0, cpu_s / elapsed_s)
    free = min(cpus, max(1.0, cpus - (os.getloadavg()[0] - busy)))
    speedup = min(AUTO_WORKERS, free) / busy
    return speedup < MIN_SPEEDUP or rest * (1 - 1 / speedup) < PAYS_FACTOR * CLUSTER_START_S


def run_batch(jobs: Sequence[tuple[str, str]], options: dict, *, workers: int | None = None,
              scheduler: str | None = None, out: str | None = None,
              on_done: Callable[[str, str, FrfResult], None] | None = None) -> list[FrfResult]:
    """FRFs of every (file, run_id) job in order.  ``workers`` 0 computes serially here, > 0 on a
    LocalCluster of that many processes, None (automatic) serially for as long as the measured cost
    of the runs done predicts no gain from a cluster (:func:`_serial_pays`), then on a cluster of
    AUTO_WORKERS;
    ``scheduler`` sends every job to an existing cluster.  ``on_done(file, run_id, result)`` gets each
    result once no unfinished job reads the file it will be written to (``out`` if given, else its
    own file): that is when the caller may write it."""
    results: list[FrfResult | None] = [None] * len(jobs)
    deliver = _Deliver(jobs, on_done, lambda p: p if out is None else str(out))

    def done(k: int, result: FrfResult) -> None:
        results[k] = result
        deliver(k, result)

    first = 0
    if scheduler is None and not workers:
        sizes = run_bytes(jobs) if workers is None else None
        t0, c0 = time.perf_counter(), time.process_time()
        while first < len(jobs):
            if sizes is not None and not _serial_pays(time.perf_counter() - t0, time.process_time() - c0,
                                                      sum(sizes[:first]), sum(sizes[first:]),
                                                      len(jobs) - first):
                workers = AUTO_WORKERS
                break
            done(first, frf_job(*jobs[first], {"workers": -1, **options}))
            first += 1
        if first == len(jobs):
            return results
    _on_cluster(jobs, first, options, workers, scheduler, done)
    return results


def _on_cluster(jobs, first: int, options: dict, workers: int | None, scheduler: str | None,
                done: Callable[[int, FrfResult], None]) -> None:
    """Jobs ``first``.. on a LocalCluster of ``workers`` processes (bound to 127.0.0.1, no dashboard,
    no HTTP routes) or on the cluster at ``scheduler``; ``done(k, result)`` in completion order."""
    import dask
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except OSError as exc:
            raise ModalError(f"scheduler {scheduler}: cannot connect ({exc})") from None
    else:
        quiet_http = {"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []}
        with dask.config.set(quiet_http):
            cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                   host="127.0.0.1", dashboard_address=None, silence_logs=40,
                                   scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
            client = Client(cluster)
    interrupted = False
    try:
        futures = {client.submit(frf_job, str(Path(jobs[k][0]).resolve()), jobs[k][1], options, pure=False): k
                   for k in range(first, len(jobs))}   # absolute paths: workers run elsewhere
        for fut in as_completed(list(futures)):
            k = futures[fut]
            try:
                result = fut.result()
            except ModalError:
                raise
            except Exception as exc:  # a worker-side failure: name the run
                raise ModalError(f"{jobs[k][0]}:{jobs[k][1]}: {exc}") from None
            done(k, result)
    except KeyboardInterrupt:  # Ctrl-C: leave now (the CLI ends the cluster's processes with its own)
        interrupted = True
        raise
    finally:
        if not interrupted:
            client.close()
            if cluster is not None:
                cluster.close()


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
