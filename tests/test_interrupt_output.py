"""Issue 13, "nothing half-written": outputs go through checked_io.output.atomic_path (whole or not at all),
in-place HDF5 updates hold Ctrl-C until they are whole, and the frame eigen-solve that runs in a worker
process (so that Ctrl-C stays prompt) gives exactly the numbers of the in-process solve."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from flexmodal.checked_io.output import atomic_path, signals_deferred, write_text
from flexmodal.models.eigen_worker import FrameSolver
from flexmodal.models.errors import ModelError
from flexmodal.models.frame import assemble_many, solve_modes
from flexmodal.models.rig import load_rig


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".part"))


def test_atomic_path_replaces_the_target_only_when_the_block_completes(tmp_path):
    target = tmp_path / "table.csv"
    target.write_text("old\n")
    with atomic_path(target) as tmp:
        assert tmp.parent == tmp_path and tmp != target
        tmp.write_text("new\n")
        assert target.read_text() == "old\n"  # readers see the old file until the end
    assert target.read_text() == "new\n" and _leftovers(tmp_path) == []


@pytest.mark.parametrize("stop", [KeyboardInterrupt, ValueError])
def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path, stop):
    target, fresh = tmp_path / "table.csv", tmp_path / "new.csv"
    target.write_text("old\n")
    for path in (target, fresh):
        with pytest.raises(stop), atomic_path(path) as tmp:
            tmp.write_text("half a ")
            raise stop
    assert target.read_text() == "old\n" and not fresh.exists() and _leftovers(tmp_path) == []


def test_written_files_get_the_umask_permissions(tmp_path):
    old = os.umask(0o027)
    try:
        path = write_text(tmp_path / "a.txt", "µ\n")
    finally:
        os.umask(old)
    assert path.read_text(encoding="utf-8") == "µ\n"
    assert path.stat().st_mode & 0o777 == 0o640


@pytest.fixture
def python_sigint():
    """SIGINT raising KeyboardInterrupt, as in an interactive Python, even where this test process
    was started with SIGINT ignored (a shell's background job): the tests below send themselves one."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_signals_deferred_holds_sigint_until_the_block_is_whole(python_sigint):
    done = []
    with pytest.raises(KeyboardInterrupt):
        with signals_deferred():
            os.kill(os.getpid(), signal.SIGINT)
            done.append("first half")
            done.append("second half")
    assert done == ["first half", "second half"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_frf_group_interrupted_while_written_is_whole(tmp_path, python_sigint):
    """Ctrl-C arriving while write_frf writes: the group is completed, then KeyboardInterrupt."""
    import h5py

    from flexmodal.modal.frf import FrfResult
    from flexmodal.modal.runs_io import read_frf, write_frf

    H = np.ones((2, 1, 5), complex)
    result = FrfResult(np.arange(5.0), H, np.ones((2, 5)), "H1", "hann", 8, 3, 64.0, "accelerance",
                       ("a1", "a2"), ("F",), 0.0, {})
    path = tmp_path / "f.h5"
    real_create = h5py.Group.create_dataset

    def create_then_interrupt(self, name, *args, **kw):
        if name == "H":
            os.kill(os.getpid(), signal.SIGINT)
        return real_create(self, name, *args, **kw)

    with pytest.MonkeyPatch.context() as mp, pytest.raises(KeyboardInterrupt):
        mp.setattr(h5py.Group, "create_dataset", create_then_interrupt)
        write_frf(path, "r1", result)
    back = read_frf(path, "r1")
    assert back is not None and np.array_equal(back.H, H) and back.estimator == "H1"


def test_the_worker_process_solves_exactly_like_this_process(rigs_dir):
    rig = load_rig(rigs_dir / "demo_arm.toml")
    system = next(iter(assemble_many(rig, [{"theta_deg": 40.0}], 30, False)))
    with threadpool_limits(limits=1, user_api="blas"):  # as models.predict solves
        here = solve_modes(system, 6)
    with FrameSolver(offload_dof=0) as solve:
        there = solve(system, 6)
        assert solve.proc is not None  # it really went to the worker
        with pytest.raises(ModelError, match="asked for 100000 modes"):  # errors come back typed
            solve(system, 100000)
        again = solve(system, 6)
    assert solve.proc.returncode == 0
    for a, b in ((here, there), (here, again)):
        assert np.array_equal(a.freq_hz, b.freq_hz) and np.array_equal(a.phi, b.phi)
        assert np.array_equal(a.sensor_shapes, b.sensor_shapes)


def test_a_killed_worker_is_a_model_error_naming_its_exit_code(rigs_dir):
    """A worker gone before answering (the out-of-memory killer, a kill) is one line of the error family
    with its exit code, not a RuntimeError or BrokenPipeError traceback."""
    rig = load_rig(rigs_dir / "demo_arm.toml")
    system = next(iter(assemble_many(rig, [{"theta_deg": 40.0}], 10, False)))
    with FrameSolver(offload_dof=0) as solve:
        solve(system, 4)
        solve.proc.kill()
        solve.proc.wait()
        with pytest.raises(ModelError, match=rf"frame of {system.n_dof} DOF: .* code -9 before answering"):
            solve(system, 4)


def test_small_frames_stay_in_this_process(rigs_dir):
    rig = load_rig(rigs_dir / "demo_arm.toml")
    system = next(iter(assemble_many(rig, [{"theta_deg": 40.0}], 10, False)))
    with FrameSolver() as solve:
        solve(system, 4)
    assert solve.proc is None


def test_signal_handlers_are_put_back_after_an_error_and_left_alone_outside_the_main_thread():
    """checked_io.signals.signal_handlers, which the deferral above, acquire's stop signals, the
    simulators' stop watch and the demo's Ctrl-C use: the handlers found come back however the block
    ends, and a thread other than the main one (where Python sets no handlers) changes nothing."""
    import threading

    from flexmodal.checked_io.signals import signal_handlers

    before = signal.getsignal(signal.SIGUSR2)
    got: list[int] = []
    with pytest.raises(ZeroDivisionError), signal_handlers(lambda s, _f: got.append(s), [signal.SIGUSR2]):
        signal.raise_signal(signal.SIGUSR2)
        raise ZeroDivisionError
    assert got == [signal.SIGUSR2] and signal.getsignal(signal.SIGUSR2) is before
    seen = []

    def elsewhere():
        with signal_handlers(lambda s, _f: None, [signal.SIGUSR2]) as found:
            seen.append((found, signal.getsignal(signal.SIGUSR2)))

    thread = threading.Thread(target=elsewhere)
    thread.start()
    thread.join(60)
    assert seen == [({}, before)]
