"""The ``flexmodal`` console script run as a real process per call, started warm: forked from a server that
has imported the heavy third-party libraries once (numpy, scipy, pandas, h5py, matplotlib).

A cold start of the console script spends 0.3-1 s of CPU importing those libraries before it looks at
its input (tests/test_cli_table.py runs hundreds of malformed inputs: most of its time went there).
:class:`WarmCli` starts this file as a server once; each :meth:`WarmCli.run` forks it, and the child
becomes the console script: standard input ``/dev/null``, standard output and error pipes, the given
working directory, ``sys.argv`` as the script gets it, then the script's own body
``sys.exit(flexmodal.app.main())`` at module level.  So each call is a process of its own: its exit
status comes from the operating system, everything written to file descriptor 2 (C libraries included)
is in its stderr, it ends through the interpreter's normal exit (atexit handlers, non-daemon threads
joined, files closed), and, as with ``subprocess.run(capture_output=True, timeout=...)``, a call ends
when both pipes are closed (a child process left holding them is a hang) and the process has exited.
What differs from a cold start: the libraries of :data:`PRELOAD` (nothing of flexmodal) are imported
before ``main`` starts, and their objects are frozen out of the garbage collector (``gc.freeze``: the
collections of a process, the ones at its exit included, walked all of them: 0.2-0.3 s of CPU a run).
"""

from __future__ import annotations

import json
import os
import selectors
import signal
import subprocess
import sys
import time
from pathlib import Path

PRELOAD = ("numpy", "scipy.fft", "scipy.linalg", "scipy.optimize", "scipy.signal", "scipy.stats", "pandas",
           "h5py", "matplotlib.figure")


class WarmCli:
    """A fork server for runs of the console script ``exe`` (one call at a time: use one per thread).

    Examples
    --------
    >>> with WarmCli(exe) as cli:                                           # doctest: +SKIP
    ...     code, stderr = cli.run(["compare", "a.csv", "b.csv"], cwd, timeout_s=300.0)
    """

    def __init__(self, exe: str) -> None:
        self.exe = exe
        requests_r, self._requests = os.pipe()
        self._replies, replies_w = os.pipe()
        self._server = subprocess.Popen([sys.executable, __file__, str(requests_r), str(replies_w), exe],
                                        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                        pass_fds=(requests_r, replies_w))
        os.close(requests_r)
        os.close(replies_w)
        self._reader = os.fdopen(self._replies, "r", encoding="utf-8")

    def run(self, args: list[str], cwd: Path, timeout_s: float) -> tuple[int | None, str]:
        """Exit code of ``exe args`` run in ``cwd`` (negative: ended by that signal; None: killed after
        ``timeout_s`` without both its pipes closed and its exit) and its stderr."""
        request = {"argv": [self.exe, *args], "cwd": str(cwd), "timeout_s": timeout_s}
        os.write(self._requests, (json.dumps(request) + "\n").encode())
        reply = self._reader.readline()
        assert reply, f"the warm-start server ended (exit {self._server.wait()})"
        reply = json.loads(reply)
        return reply["code"], reply["stderr"].encode("latin-1").decode()

    def close(self) -> None:
        os.close(self._requests)      # end of requests: the server exits
        self._server.wait(timeout=60)
        self._reader.close()

    def __enter__(self) -> WarmCli:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _serve(requests_fd: int, replies_fd: int) -> dict:
    """The server: import :data:`PRELOAD`, then fork one child per request line and reply its exit code
    and stderr.  Returns (in the child only) the child's request."""
    import gc
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    gc.freeze()
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
        (out_r, out_w), (err_r, err_w) = os.pipe(), os.pipe()
        pid = os.fork()
        if pid == 0:
            requests.close()
            for fd in (replies_fd, out_r, err_r):
                os.close(fd)
            _become(request, out_w, err_w)
            return request
        os.close(out_w)
        os.close(err_w)
        code, stderr = _outcome(pid, out_r, err_r, request["timeout_s"])
        os.write(replies_fd, (json.dumps({"code": code, "stderr": stderr.decode("latin-1")}) + "\n").encode())


def _outcome(pid: int, out_r: int, err_r: int, timeout_s: float) -> tuple[int | None, bytes]:
    """Read both pipes to their end, then wait for the process (subprocess.run's order); past
    ``timeout_s`` the process is killed and its code is None."""
    deadline = time.monotonic() + timeout_s
    stderr = []
    with selectors.DefaultSelector() as pipes:
        pipes.register(out_r, selectors.EVENT_READ)
        pipes.register(err_r, selectors.EVENT_READ)
        while pipes.get_map() and time.monotonic() < deadline:
            for key, _ in pipes.select(deadline - time.monotonic()):
                data = os.read(key.fd, 65536)
                if not data:
                    pipes.unregister(key.fd)
                elif key.fd == err_r:
                    stderr.append(data)
    os.close(out_r)
    os.close(err_r)
    while time.monotonic() < deadline:     # the pipes closed: the process is ending (or has ended)
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status), b"".join(stderr)
        time.sleep(0.005)
    os.kill(pid, signal.SIGKILL)           # a hang, ended as subprocess.run(timeout=...) does
    os.waitpid(pid, 0)
    return None, b"".join(stderr)


def _become(request: dict, out_w: int, err_w: int) -> None:
    """This forked child becomes the console script's process for ``request``."""
    os.chdir(request["cwd"])
    null = os.open(os.devnull, os.O_RDONLY)
    for fd, target in ((0, null), (1, out_w), (2, err_w)):
        os.dup2(target, fd)
        os.close(target)
    sys.argv = list(request["argv"])


if __name__ == "__main__":
    sys.path[0] = os.path.dirname(sys.argv[3])   # the console script's folder, as for the script itself
    _serve(int(sys.argv[1]), int(sys.argv[2]))
    from flexmodal.app import main  # the console script's body (pip's entry-point wrapper)

    sys.exit(main())
