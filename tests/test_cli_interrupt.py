"""Issue 13: Ctrl-C (SIGINT) stops `flexmodal demo` promptly with exit 130 and leaves no output behind.

The demo runs as the real console script; SIGINT is sent once a given output file exists.  Measured
before issue 13's last fixes (load average about 2): 0.03-0.06 s while identifying or diagnosing,
0.2-0.6 s during the serial acquisition, 1.6 s when SIGINT landed while the acquisition's simulator
child was still starting; that wait is now interruptible (fixtures.sim_serve, 0.05-0.07 s, and
tests/test_interrupt_commands.py), so the limit is the issue's 1 s, counted without the time the
command waited for a CPU (tests/cpu_wait.py: the wall time on a quiet machine; under load the wall
time is several times longer).
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from interrupt_support import interrupt

from flexmodal.fixtures.demo import OUTPUTS

EXIT_LIMIT_S = 1.0  # issue 13


def _interrupt_demo(out: Path, when_exists: str, after_s: float) -> tuple[int, float, str]:
    """SIGINT ``after_s`` seconds after ``out/when_exists`` appeared."""
    seen: list[float] = []

    def ready(_pid: int) -> bool:
        if not seen and (out / when_exists).exists():
            seen.append(time.monotonic())
        return bool(seen) and time.monotonic() - seen[0] >= after_s

    return interrupt(["demo", "--out", str(out)], out.parent, ready, ready_within_s=600.0)  # a hang guard


def _check(out: Path, code: int, seconds: float, err: str) -> None:
    assert code == 130, err[-2000:]
    # Python reports (and drops) a KeyboardInterrupt that lands inside a garbage-collector callback as
    # "Exception ignored in: ..."; the console script delivers it again (test at the end of this file),
    # so only an error raised from it inside such a callback could still print that report.
    ours = err.split("Exception ignored in:")[0] if "Exception ignored in:" in err else err
    assert "flexmodal: interrupted" in err.strip().splitlines(), err[-2000:]
    assert "Traceback" not in ours, err[-2000:]
    assert seconds < EXIT_LIMIT_S, f"exit took {seconds:.2f} s"
    print(f"exit 130 {seconds:.3f} s after SIGINT")  # shown with pytest -s
    left = [name for name in OUTPUTS if (out / name).exists()]
    assert not left, f"half-written outputs left behind: {left}"


def test_ctrl_c_while_storing_runs(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    _check(out, *_interrupt_demo(out, "runs.h5", 0.0))


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize(("when_exists", "after_s"), [("runs.h5", 5.0), ("modes.csv", 1.0),
                                                      ("diagnosis.json", 0.5)])
def test_ctrl_c_in_later_steps(tmp_path: Path, when_exists: str, after_s: float) -> None:
    out = tmp_path / "demo"
    _check(out, *_interrupt_demo(out, when_exists, after_s))


def test_a_library_error_raised_from_ctrl_c_is_an_interruption(monkeypatch, capsys):
    """Ctrl-C met while a library sets up a class during an import reaches the CLI as RuntimeError
    ("Error calling __set_name__") caused by the KeyboardInterrupt: still exit 130 and one line; an
    error not caused by Ctrl-C stays a bug (raised)."""
    import argparse

    from flexmodal import app

    def handler(raised: BaseException):
        def run(_args):
            raise raised
        return run

    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as interrupt:
        wrapped = RuntimeError("Error calling __set_name__")
        wrapped.__cause__ = interrupt
    parser = argparse.ArgumentParser()
    monkeypatch.setattr(app, "build_parser", lambda: parser)
    monkeypatch.setattr(parser, "parse_args", lambda _argv: argparse.Namespace(func=handler(wrapped)))
    assert app.main([]) == 130
    assert capsys.readouterr().err == "flexmodal: interrupted\n"
    bug = argparse.Namespace(func=handler(ValueError("bug")))
    monkeypatch.setattr(parser, "parse_args", lambda _argv: bug)
    with pytest.raises(ValueError, match="bug"):
        app.main([])


LOST_IN_A_CALLBACK = """
import argparse, os, signal, sys, time, weakref
from flexmodal import app

class Thing:
    pass

def dropped(_ref):  # Ctrl-C arrives while Python runs a weakref callback (as in garbage collection)
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(30)

def work(_args):
    thing = Thing()
    ref = weakref.ref(thing, dropped)
    del thing
    time.sleep(30)
    print("finished", ref, flush=True)
    return 0

parser = argparse.ArgumentParser()
parser.parse_args = lambda _argv: argparse.Namespace(func=work)
app.build_parser = lambda: parser
sys.exit(app.main())
"""


def test_ctrl_c_that_lands_in_a_weakref_callback_still_stops_the_command():
    """Python reports and drops a KeyboardInterrupt raised inside a garbage-collector or weakref callback
    ("Exception ignored in: ..."); the console script delivers it again, so the command stops with exit
    130 and one line instead of running on to its end (seen under load: `frf` over 128 runs finished
    with exit 0 after SIGINT)."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", LOST_IN_A_CALLBACK], capture_output=True, text=True,
                          timeout=600)
    assert (done.returncode, done.stderr, done.stdout) == (130, "flexmodal: interrupted\n", "")
