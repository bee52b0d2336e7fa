"""Batch FRFs: the demo-like multi-run file works by default (serial chosen by cost, each file written
by this process only), the cost rule itself, a pool of local processes and a scheduler and two
workers started with the `dask` CLI on 127.0.0.1 give FRFs identical to the serial path."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from flexmodal.app import main
from flexmodal.checked_io.text import natural_order
from flexmodal.daq.store import Channel, RunWriter, expand_runs
from flexmodal.fixtures.modal_sim import modal_response
from flexmodal.modal import batch
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.runs_io import read_frf

FS = 256.0
FN, ZETA = np.array([12.0, 31.0, 55.0]), np.array([0.02, 0.01, 0.01])
PHI = np.array([[1.0, 0.8, 0.3], [0.5, -0.6, 0.9], [0.2, -0.9, -0.7]])
CHANNELS = [Channel("force", "force", "N")] + [Channel(f"a{k}", "acceleration", "m/s^2") for k in (1, 2, 3)]


def _runs_file(path: Path, run_ids, n: int = 2048) -> Path:
    for k, rid in enumerate(run_ids):
        f = np.random.default_rng(k).standard_normal((n, 1))
        with RunWriter(path, rid, sample_rate_hz=FS, channels=CHANNELS, excitation="random",
                       pose={"k": k}) as w:
            w.append(np.column_stack([f, modal_response(f, FS, FN, ZETA, PHI, PHI[[0]])]))
    return path


def test_default_frf_on_the_demo_runs_file_writes_every_run_serially(tmp_path, capsys, monkeypatch):
    """The demo's ten simulated runs (impact and random at five poses) stored as in its runs.h5: the
    default `flexmodal frf` picks the serial path (no cluster is started) and writes every run."""
    from flexmodal.fixtures import demo
    from flexmodal.models.rig import load_rig

    path = tmp_path / "runs.h5"
    runs = demo.simulate_campaign(load_rig(demo.DEMO_RIG), demo.DEMO_POSES)
    for run in runs:
        demo.store_test(path, run.run_id, run.test)

    def no_pool(*args, **kwargs):
        raise AssertionError("worker processes were started for small runs")

    monkeypatch.setattr(batch, "_in_pool", no_pool)
    assert main(["--quiet", "frf", str(path)]) == 0
    ids = natural_order(run.run_id for run in runs)   # theta30 before theta120, as every listing
    assert len(ids) == 10 and capsys.readouterr().out.split() == [f"{path}:{rid}" for rid in ids]
    for rid in ids:
        frf = read_frf(path, rid)
        assert frf is not None and frf.H.shape[1] == 1
        if rid.endswith("random"):
            assert frf.provenance["segments_skipped"] == 0 and frf.n_averages >= 8


def test_cost_rule_forks_helpers_only_where_idle_cpus_make_them_pay(monkeypatch):
    """The rest of a batch predicted from the runs done here (wall per byte); a helper per CPU left
    idle (at most AUTO_WORKERS CPUs in all) runs at HELPER_SHARE of this process's rate and costs
    FORK_S; helpers only for a gain of GAIN_FORKS forks."""
    monkeypatch.setattr(batch, "usable_cpus", lambda: 2)
    run = 21 * 10 ** 6             # benchmarks/batch.py's runs of 60 s: 21 MB, 0.035 s each here
    # 8 runs, one done, 7 left (0.245 s): a helper saves 0.245 (1 - 1 / 1.85) - 0.01 = 0.10 s > 0.03 s
    assert batch._helpers_pay(0.035, run, 7 * run, 7, idle=1.0) == 1
    # 3 runs left save 0.105 - 0.057 - 0.01 = 0.038 s; 2 left 0.070 - 0.038 - 0.01 = 0.022 s < 3 forks;
    # 1 left: nothing to share
    assert batch._helpers_pay(0.035, run, 3 * run, 3, idle=1.0) == 1
    assert batch._helpers_pay(0.035, run, 2 * run, 2, idle=1.0) == 0
    assert batch._helpers_pay(0.035, run, run, 1, idle=1.0) == 0
    # tiny runs (the demo's: 3 ms each): 9 left save 0.012 s < 3 forks
    assert batch._helpers_pay(0.003, run, 9 * run, 9, idle=1.0) == 0
    # no CPU left idle while this process computed (the other one busy, or unknown): serial
    assert batch._helpers_pay(0.035, run, 99 * run, 99, idle=0.4) == 0
    assert batch._helpers_pay(0.035, run, 99 * run, 99, idle=0.0) == 0
    # more idle CPUs than AUTO_WORKERS allows: one helper; one usable CPU: none
    monkeypatch.setattr(batch, "usable_cpus", lambda: 8)
    assert batch._helpers_pay(0.035, run, 99 * run, 99, idle=7.0) == batch.AUTO_WORKERS - 1
    monkeypatch.setattr(batch, "usable_cpus", lambda: 1)
    assert batch._helpers_pay(0.035, run, 99 * run, 99, idle=1.0) == 0


def test_idle_cpus_are_the_available_ticks_between_two_samples(monkeypatch):
    """/proc/stat's ticks: idle and I/O wait are available; under a tick per CPU is unknown (0: serial)."""
    monkeypatch.setattr(batch.os, "cpu_count", lambda: 2)
    assert batch._idle_cpus_between((1000, 300), (1100, 350)) == 1.0
    assert batch._idle_cpus_between((1000, 300), (1001, 301)) == 0.0
    assert batch._idle_cpus_between(None, (1100, 350)) == 0.0
    total, available = batch._cpu_ticks()
    assert total >= available >= 0


def test_serial_fft_threads_are_the_cpus_other_processes_leave_idle(monkeypatch):
    """This process's CPU plus those the machine left idle since the last look (/proc/stat ticks, the
    one estimator): on 2 CPUs, the other one idle -> 2 threads, a third busy -> 1, all busy -> 1; a look
    under a tick per CPU after the last measures from the look before."""
    monkeypatch.setattr(batch, "usable_cpus", lambda: 2)
    monkeypatch.setattr(batch.os, "cpu_count", lambda: 2)
    monkeypatch.setattr(batch, "_LOOK", [(1000, 0), None])
    # (total, available) ticks at each look: +100 ticks, of which idle 50 (1 CPU), 20, 0, then 1 tick later
    for sample, threads in (((1100, 50), 2), ((1200, 70), 1), ((1300, 70), 1), ((1301, 71), 1)):
        monkeypatch.setattr(batch, "_cpu_ticks", lambda sample=sample: sample)
        assert batch.idle_cpus() == threads
    assert batch._LOOK == [(1300, 70), (1200, 70)]
    monkeypatch.setattr(batch, "_cpu_ticks", lambda: (1310, 120))     # 10 ticks after the last look
    assert batch.idle_cpus() == 2                  # measured from (1200, 70): 50 of 110 idle -> 0.9 CPU


def test_results_wait_until_no_job_reads_their_file():
    jobs = [("a.h5", "r0"), ("b.h5", "r0"), ("a.h5", "r1")]
    got = []
    deliver = batch._Deliver(jobs, lambda p, r, res: got.append((p, r, res)), lambda p: p)
    deliver(0, "A0")
    assert got == []                          # a.h5 still has r1 being read
    deliver(1, "B0")
    assert got == [("b.h5", "r0", "B0")]
    deliver(2, "A1")
    assert got[1:] == [("a.h5", "r0", "A0"), ("a.h5", "r1", "A1")]
    into_out = []
    deliver = batch._Deliver(jobs, lambda p, r, res: into_out.append(r), lambda p: "out.h5")
    deliver(0, "A0")
    assert into_out == ["r0"]                 # --out: no job reads out.h5


def test_pool_of_two_processes_equals_serial_and_names_a_failing_run(tmp_path, monkeypatch):
    """`--workers 2`: two local processes (from a fork server, so the caller's folder change does not
    matter: they get absolute paths) compute the runs of two files given by relative names; the FRFs
    written by this process equal the serial ones bit for bit.  A run that fails in a worker becomes
    one ModalError naming its file and run."""
    monkeypatch.chdir(tmp_path)
    files = [_runs_file(Path(f"f{j}.h5"), ["r0", "r1", "r2"], n=1024).name for j in range(2)]
    serial = batch.run_batch(expand_runs(files), {"nfft": 256}, workers=0)
    assert main(["--quiet", "frf", *files, "--workers", "2", "--nfft", "256"]) == 0
    stored = [read_frf(p, f"r{k}") for p in files for k in range(3)]
    for a, b in zip(serial, stored, strict=True):
        assert np.array_equal(a.H, b.H) and np.array_equal(a.coherence, b.coherence)
    with pytest.raises(ModalError, match=r"f[01]\.h5:r[012]: record of 1024 samples is shorter than one "
                                         r"segment \(nfft 4096\)$"):
        batch.run_batch(expand_runs(files), {"nfft": 4096}, workers=2)   # longer than the 1024 samples


def test_serial_path_runs_as_many_runs_at_once_as_idle_cpus_with_the_same_results(tmp_path, monkeypatch):
    """`--workers 0` with 2 idle CPUs: two runs at a time in threads of this process (each with one
    FFT thread), written in order, each file only once no run of it is being read; the FRFs equal
    those of one run at a time bit for bit.  One run alone gets both CPUs as FFT threads."""
    import threading

    files = [str(_runs_file(tmp_path / f"f{j}.h5", ["r0", "r1", "r2"], n=4096)) for j in range(2)]
    jobs = expand_runs(files)
    monkeypatch.setattr(batch, "idle_cpus", lambda: 1)
    one = batch.run_batch(jobs, {"nfft": 256}, workers=0)
    seen = []
    real = batch.frf_job
    both = threading.Barrier(2, timeout=60)     # the first two runs must be running at the same time

    def spy(path, run_id, options):
        seen.append((threading.current_thread().name, options["workers"]))
        if len(seen) <= 2 and not both.broken:
            both.wait()
        return real(path, run_id, options)

    monkeypatch.setattr(batch, "frf_job", spy)
    monkeypatch.setattr(batch, "idle_cpus", lambda: 2)
    written = []
    two = batch.run_batch(jobs, {"nfft": 256}, workers=0, on_done=lambda p, r, res: written.append((p, r)))
    assert len({name for name, _ in seen[:2]}) == 2 and {w for _, w in seen} == {1}
    assert written == [(p, r) for p, r in jobs]
    for a, b in zip(one, two, strict=True):
        assert np.array_equal(a.H, b.H) and np.array_equal(a.coherence, b.coherence)
    seen.clear()
    both.abort()                                # one run alone: nothing to wait for
    batch.run_batch(jobs[:1], {"nfft": 256}, workers=0)
    assert [w for _, w in seen] == [2]


def _spy_processes(monkeypatch, log: Path) -> None:
    """Have every run computed append the id of the process computing it to ``log`` (helpers are forked
    from this process, so they compute through the same patched function).  This process computes its
    first run, then waits for a helper to have started one (so one surely takes part, however slowly
    it starts)."""
    real, here = batch.compute_frf, os.getpid()

    def compute(run, **options):
        with log.open("a") as f:
            f.write(f"{os.getpid()} {run.run_id}\n")
        deadline = time.monotonic() + 600      # a hang guard: a forked process starts at once
        while os.getpid() == here and len(log.read_text().splitlines()) > 1 and \
                {line.split()[0] for line in log.read_text().splitlines()} == {str(here)}:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        return real(run, **options)

    monkeypatch.setattr(batch, "compute_frf", compute)


def _helpers_ended(log: Path) -> bool:
    """Whether every process but this one that computed a run (a helper) has ended and been waited for."""
    helpers = {int(line.split()[0]) for line in log.read_text().splitlines()} - {os.getpid()}
    for pid in helpers:
        try:
            os.waitpid(pid, os.WNOHANG)
            return False
        except ChildProcessError:     # waited for already
            pass
    return bool(helpers)


def test_automatic_choice_forks_a_helper_with_the_same_results_in_order(tmp_path, monkeypatch):
    """Automatic choice, the cost rule saying a helper pays: after the first run here, a process forked
    from this one takes runs too; every result is delivered in run order and equals the serial one bit
    for bit; the helper has ended when the batch returns."""
    files = [str(_runs_file(tmp_path / f"f{j}.h5", ["r0", "r1", "r2"], n=4096)) for j in range(3)]
    jobs = expand_runs(files)
    serial = batch.run_batch(jobs, {"nfft": 256}, workers=0)
    monkeypatch.setattr(batch, "_helpers_pay", lambda *args: 1)
    monkeypatch.setattr(batch, "_forkable", lambda: True)      # whatever threads earlier tests left
    log = tmp_path / "pids.txt"
    _spy_processes(monkeypatch, log)
    written = []
    mask = os.sched_getaffinity(0)
    auto = batch.run_batch(jobs, {"nfft": 256}, on_done=lambda p, r, res: written.append((p, r)))
    assert os.sched_getaffinity(0) == mask      # pinned while sharing the runs (2 CPUs), then restored
    pids = [int(line.split()[0]) for line in log.read_text().splitlines()]
    assert len(pids) == len(jobs) and pids[0] == os.getpid() and len(set(pids)) == 2
    assert written == [(p, r) for p, r in jobs]
    for a, b in zip(serial, auto, strict=True):
        assert np.array_equal(a.H, b.H) and np.array_equal(a.coherence, b.coherence)
        assert a.provenance == b.provenance
    assert _helpers_ended(log)


def test_a_helper_failure_is_raised_in_run_order_and_ctrl_c_ends_the_helper(tmp_path, monkeypatch):
    """A run that fails (here: shorter than one segment) raises its own error once every run before it
    has been delivered (into ``out``: at once), whichever process computed it; a KeyboardInterrupt in
    the caller (raised from its callback) ends the helper before it propagates."""
    path = tmp_path / "f.h5"
    _runs_file(path, ["r0", "r1", "r2", "r3"], n=4096)
    _runs_file(path, ["r4"], n=1024)
    _runs_file(path, ["r5", "r6"], n=4096)
    jobs = expand_runs([path])
    monkeypatch.setattr(batch, "_helpers_pay", lambda *args: 1)
    monkeypatch.setattr(batch, "_forkable", lambda: True)      # whatever threads earlier tests left
    _spy_processes(monkeypatch, tmp_path / "pids.txt")
    got = []
    with pytest.raises(ModalError, match=r"r4.*record of 1024 samples is shorter than one segment"):
        batch.run_batch(jobs, {"nfft": 2048}, on_done=lambda p, r, res: got.append(r),
                        out=str(tmp_path / "out.h5"))
    assert got == ["r0", "r1", "r2", "r3"] and _helpers_ended(tmp_path / "pids.txt")
    _spy_processes(monkeypatch, tmp_path / "pids2.txt")

    def interrupt(p, r, res):             # the third run delivered: the helper has been forked
        got.append(r)
        if len(got) > 6:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        batch.run_batch(jobs[:4] * 3, {"nfft": 256}, on_done=interrupt, out=str(tmp_path / "out.h5"))
    assert _helpers_ended(tmp_path / "pids2.txt")
    _spy_processes(monkeypatch, tmp_path / "pids3.txt")
    got.clear()                           # keep_going (`frf`): the bad run is delivered as its error
    results = batch.run_batch(jobs, {"nfft": 2048}, on_done=lambda p, r, res: got.append((r, type(res))),
                              out=str(tmp_path / "out.h5"), keep_going=True)
    assert got == [(f"r{k}", ModalError if k == 4 else FrfResult) for k in range(7)]
    assert [type(r) for r in results] == [t for _, t in got] and _helpers_ended(tmp_path / "pids3.txt")


def _start(args: list[str], log: Path) -> subprocess.Popen:
    """A `dask` CLI process logging into ``log``, working in a folder of its own."""
    (log.parent / "elsewhere").mkdir(exist_ok=True)
    return subprocess.Popen([sys.executable, "-m", "dask", *args], stdout=log.open("w"),
                            stderr=subprocess.STDOUT, cwd=log.parent / "elsewhere")


@pytest.mark.slow
def test_hundred_runs_on_a_dask_cli_scheduler_and_two_workers(tmp_path, capsys, monkeypatch):
    """`dask scheduler` and `dask worker --nworkers 2` as their own processes on 127.0.0.1, without
    dashboards; `flexmodal frf --scheduler` on 100 runs (ten files, named relative to this process's
    folder, not the workers') read by the workers from their shared paths and written by the calling
    process: FRFs identical to the serial path."""
    monkeypatch.chdir(tmp_path)
    files = [_runs_file(Path(f"f{j}.h5"), [f"r{k}" for k in range(10)], n=1024).name for j in range(10)]
    serial = batch.run_batch(expand_runs(files), {"nfft": 256}, workers=0)
    sched_file = tmp_path / "scheduler.json"
    procs = []
    try:
        procs.append(_start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                             "--scheduler-file", str(sched_file)], tmp_path / "scheduler.log"))
        deadline = time.monotonic() + 60
        while not sched_file.exists() or not sched_file.read_text().strip():
            assert time.monotonic() < deadline and procs[0].poll() is None, \
                (tmp_path / "scheduler.log").read_text()
            time.sleep(0.2)
        import json

        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(_start(["worker", "--scheduler-file", str(sched_file), "--nworkers", "2", "--nthreads",
                             "1", "--host", "127.0.0.1", "--no-dashboard", "--local-directory",
                             str(tmp_path / "dask-worker")], tmp_path / "worker.log"))
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        assert main(["--quiet", "frf", *files, "--scheduler", address, "--nfft", "256"]) == 0
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=5)
    written = capsys.readouterr().out.split()
    assert written == [f"{p}:r{k}" for p in files for k in range(10)]
    stored = [read_frf(p, f"r{k}") for p in files for k in range(10)]
    assert len(stored) == 100
    for a, b in zip(serial, stored, strict=True):
        assert np.array_equal(a.H, b.H) and np.array_equal(a.coherence, b.coherence)


def test_scheduler_without_dask_installed_is_a_one_line_hint(tmp_path, monkeypatch, capsys):
    """dask is the optional extra flexmodal[cluster]: without it, --scheduler exits 2 with one line
    naming the extra (``sys.modules[...] = None`` makes the import fail as if it were not installed)."""
    path = _runs_file(tmp_path / "runs.h5", ["r0"])
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert main(["--quiet", "frf", str(path), "--scheduler", "127.0.0.1:1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "pip install 'flexmodal[cluster]'" in err and "127.0.0.1:1" in err
