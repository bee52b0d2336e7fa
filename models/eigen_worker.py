"""Large frame eigen-solves in a worker process, so that Ctrl-C stays prompt (issue 13).

``scipy.linalg.eigh`` holds the GIL for the whole LAPACK call: a frame of a few thousand DOF keeps the
interpreter deaf to SIGINT for seconds, and a thread cannot help.  :class:`FrameSolver` hands systems of
``OFFLOAD_DOF`` DOF or more to one child process (``python -m flexmodal.models.eigen_worker``, started on
first need and kept for the rest of the call) and waits on its pipe, which a signal interrupts at once;
on any exception, KeyboardInterrupt included, the child is killed and abandoned.  The child runs the
same ``models.frame.solve_modes`` with BLAS at one thread, as ``models.predict`` does here, so both paths
give the same numbers.  Smaller systems (under 0.1 s each) are solved in this process.
"""

from __future__ import annotations

import pickle
import subprocess
import sys
from typing import BinaryIO

from flexmodal.checked_io.children import ctrl_c_blocked, leave_ctrl_c_to_parent
from flexmodal.models import frame
from flexmodal.models.errors import ModelError
from flexmodal.models.frame import FrameModes, FrameSystem

OFFLOAD_DOF = 1200  # eigh of 1200 DOF: about 0.2 s at one BLAS thread; 2400 DOF: 1.4 s (measured)


class FrameSolver:
    """``solve_modes(system, n_modes)`` that a signal interrupts within milliseconds (a context manager:
    leaving it ends the worker; an exception inside it kills the worker)."""

    def __init__(self, offload_dof: int = OFFLOAD_DOF) -> None:
        self.offload_dof = offload_dof
        self.proc: subprocess.Popen | None = None

    def __call__(self, system: FrameSystem, n_modes: int) -> FrameModes:
        if system.n_dof < self.offload_dof:
            return frame.solve_modes(system, n_modes)
        if self.proc is None:   # started deaf to a terminal's Ctrl-C (its imports included): ours to answer
            with ctrl_c_blocked():
                self.proc = subprocess.Popen([sys.executable, "-m", "flexmodal.models.eigen_worker"],
                                             stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        try:
            pickle.dump((system, n_modes), self.proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
            self.proc.stdin.flush()
            ok, value = pickle.load(self.proc.stdout)
        except (EOFError, BrokenPipeError):  # the worker was killed (out of memory, a signal)
            raise ModelError(f"frame of {system.n_dof} DOF: the eigen-solve worker process ended with exit "
                             f"code {self.proc.wait()} before answering") from None
        if not ok:
            raise value
        return value

    def __enter__(self) -> FrameSolver:
        return self

    def __exit__(self, exc_type, *_exc) -> None:
        if self.proc is None:
            return
        if exc_type is None:
            self.proc.stdin.close()  # the worker ends at end of input
        else:
            self.proc.kill()
        self.proc.wait()
        self.proc.stdout.close()


def serve(source: BinaryIO, sink: BinaryIO) -> None:
    """Answer ``(system, n_modes)`` pickles from ``source`` with ``(True, modes)`` or ``(False, error)``
    pickles on ``sink`` until end of input."""
    from threadpoolctl import threadpool_limits

    while True:
        try:
            system, n_modes = pickle.load(source)
        except EOFError:
            return
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                answer = (True, frame.solve_modes(system, n_modes))
        except Exception as exc:  # noqa: BLE001 - handed back to the caller, which raises it
            answer = (False, exc)
        pickle.dump(answer, sink, protocol=pickle.HIGHEST_PROTOCOL)
        sink.flush()


if __name__ == "__main__":
    leave_ctrl_c_to_parent()  # a terminal's Ctrl-C is the parent's to handle
    serve(sys.stdin.buffer, sys.stdout.buffer)
