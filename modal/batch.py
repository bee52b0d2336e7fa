"""Batch FRFs of many stored runs: serially, on a dask.distributed LocalCluster (worker processes bound
to 127.0.0.1, no dashboard) or on an existing scheduler.  Workers read a run and return its FRFs; the
calling process writes every result back, so files are never written concurrently and the results are
the same whichever path computed them."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from flexmodal.daq.store import expand_runs
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.runs_io import write_frf


def frf_job(path: str, run_id: str, options: dict) -> FrfResult:
    """Read one run and compute its FRFs (the unit of work sent to a worker)."""
    from flexmodal.daq.store import read_run

    return compute_frf(read_run(path, run_id), **options)


def run_batch(jobs: Sequence[tuple[str, str]], options: dict, *, workers: int | None = None,
              scheduler: str | None = None,
              on_done: Callable[[str, str, FrfResult], None] | None = None) -> list[FrfResult]:
    """FRFs of every (file, run_id) job in order.  ``workers`` > 0 starts a LocalCluster of that many
    processes, ``scheduler`` connects to an existing one, neither computes serially here.
    ``on_done(file, run_id, result)`` is called as each result arrives (in completion order)."""
    if scheduler is None and not workers:
        results = []
        for path, rid in jobs:
            results.append(frf_job(path, rid, options))
            if on_done:
                on_done(path, rid, results[-1])
        return results
    from distributed import Client, LocalCluster, as_completed

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except OSError as exc:
            raise ModalError(f"scheduler {scheduler}: cannot connect ({exc})") from None
        cluster = None
    else:
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                               host="127.0.0.1", dashboard_address=None, silence_logs=40)
        client = Client(cluster)
    try:
        futures = [client.submit(frf_job, p, r, options, pure=False) for p, r in jobs]
        index = {f.key: k for k, f in enumerate(futures)}
        results: list[FrfResult | None] = [None] * len(jobs)
        for fut in as_completed(futures):
            k = index[fut.key]
            try:
                results[k] = fut.result()
            except ModalError:
                raise
            except Exception as exc:  # a worker-side failure: name the run
                raise ModalError(f"{jobs[k][0]}:{jobs[k][1]}: {exc}") from None
            if on_done:
                on_done(*jobs[k], results[k])
        return results
    finally:
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

    from rich.progress import Progress

    with Progress(transient=True, disable=quiet, console=_stderr_console()) as bar:
        task = bar.add_task("FRFs", total=len(jobs))

        def done(path: str, rid: str, result: FrfResult) -> None:
            target = str(out) if out is not None else path
            write_frf(target, rid, result)
            written.append((target, rid))
            bar.advance(task)

        run_batch(jobs, options, workers=workers, scheduler=scheduler, on_done=done)
    order = {(str(out) if out is not None else p, r): k for k, (p, r) in enumerate(jobs)}
    return sorted(written, key=order.__getitem__)


def _stderr_console():
    from rich.console import Console

    return Console(file=sys.stderr)
