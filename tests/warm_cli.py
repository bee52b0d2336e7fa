"""The ``flexmodal`` console script run as a real process per call, started warm: forked from a server that
has imported the heavy third-party libraries once (numpy, scipy, pandas, h5py).

A cold start of the console script spends 0.3-1 s of CPU importing those libraries before it looks at
its input (tests/test_cli_table.py runs hundreds of malformed inputs: most of its time went there).
:class:`WarmCli` starts this file as a server once; each :meth:`WarmCli.run` forks it, and the child
becomes the console script: standard input ``/dev/null``, standard output and error files, the row's
folder as working directory, ``sys.argv`` as the script gets it, then the script's own body
``sys.exit(flexmodal.app.main())`` at module level. So each call is a process of its own: its exit
status comes from the operating system, everything written to file descriptor 2 (C libraries included)
is in its stderr, and it ends through the interpreter's normal exit (atexit handlers, non-daemon threads
joined, files closed), signals and children as in a cold start.  What differs from a cold start: the
libraries of :data:`PRELOAD` (and nothing of flexmodal) are already imported when ``main`` starts, and
their objects are frozen out of the garbage collector (``gc.freeze``: a cold process's collections,
the ones at its exit included, walk all of them; that took 0.2-0.3 s of CPU per run).
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
from pathlib import Path

PRELOAD = ("numpy", "scipy.fft", "scipy.linalg", "scipy.optimize", "scipy.signal", "scipy.stats", "pandas",
           "h5py", "matplotlib.figure")


class WarmCli:
    """A fork server for runs of the console script ``exe`` (one request at a time: use one per thread).

    Examples
    --------
    >>> with WarmCli(exe) as cli:                                           # doctest: +SKIP
    ...     code = cli.run(["compare", "a.csv", "b.csv"], cwd, out_path, err_path, timeout_s=300.0)
    """

    def __init__(self, exe: str) -> None:
        self.exe = exe
        self._requests_r, self._requests = os.pipe()
        self._replies, self._replies_w = os.pipe()
        self._server = subprocess.Popen(
            [sys.executable, __file__, str(self._requests_r), str(self._replies_w), exe],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            pass_fds=(self._requests_r, self._replies_w))
        os.close(self._requests_r)
        os.close(self._replies_w)
        self._reader = os.fdopen(self._replies, "r", encoding="utf-8")

    def run(self, args: list[str], cwd: Path, stdout: Path, stderr: Path,
            timeout_s: float) -> tuple[int | None, float]:
        """Exit code of ``exe args`` (negative: ended by that signal; None: killed after ``timeout_s``) and
        the CPU seconds the process used."""
        request = {"argv": [self.exe, *args], "cwd": str(cwd), "stdout": str(stdout), "stderr": str(stderr),
                   "timeout_s": timeout_s}
        os.write(self._requests, (json.dumps(request) + "\n").encode())
        reply = self._reader.readline()
        assert reply, f"the warm-start server ended (exit {self._server.wait()})"
        reply = json.loads(reply)
        return reply["code"], reply["cpu_s"]

    def close(self) -> None:
        os.close(self._requests)      # end of requests: the server exits
        self._server.wait(timeout=60)
        self._reader.close()

    def __enter__(self) -> WarmCli:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _serve(requests_fd: int, replies_fd: int) -> dict:
    """The server: import :data:`PRELOAD`, then fork one child per request line and reply its exit code.
    Returns (in the child only) the child's request."""
    import gc
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    gc.freeze()   # the libraries' objects: never traversed by a child's collections (nor copied on write)
    requests = os.fdopen(requests_fd, "rb", buffering=0)
    pending = b""
    while True:
        while b"\n" not in pending:
            chunk = requests.read(65536)
            if not chunk:
                sys.exit(0)
            pending += chunk
        line, pending = pending.split(b"\n", 1)
        request = json.loads(line)
        pid = os.fork()
        if pid == 0:
            requests.close()
            os.close(replies_fd)
            return request
        code, cpu_s = _wait(pid, request["timeout_s"])
        os.write(replies_fd, (json.dumps({"code": code, "cpu_s": cpu_s}) + "\n").encode())


def _wait(pid: int, timeout_s: float) -> tuple[int | None, float]:
    pidfd = os.pidfd_open(pid)
    try:
        ready, _, _ = select.select([pidfd], [], [], timeout_s)
        if not ready:               # a hang: killed, as subprocess.run(timeout=...) does
            os.kill(pid, signal.SIGKILL)
        _, status, usage = os.wait4(pid, 0)
    finally:
        os.close(pidfd)
    return (os.waitstatus_to_exitcode(status) if ready else None), usage.ru_utime + usage.ru_stime


def _become(request: dict) -> None:
    """This forked child becomes the console script's process for ``request``."""
    os.chdir(request["cwd"])
    for fd, path, flags in ((0, os.devnull, os.O_RDONLY),
                            (1, request["stdout"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC),
                            (2, request["stderr"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC)):
        opened = os.open(path, flags, 0o644)
        os.dup2(opened, fd)
        os.close(opened)
    sys.argv = list(request["argv"])


if __name__ == "__main__":
    sys.path[0] = os.path.dirname(sys.argv[3])   # the console script's folder, as for the script itself
    _become(_serve(int(sys.argv[1]), int(sys.argv[2])))
    from flexmodal.app import main  # the console script's body (pip's entry-point wrapper)

    sys.exit(main())
