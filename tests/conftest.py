"""Shared test fixtures: paths to the repository, the committed test data and the example rigs."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# One Hypothesis profile for every run, the same as the "ci" profile Hypothesis loads by itself where CI
# is set: fixed examples (a failure found on one machine is found on every machine), no per-example
# deadline and no too-slow health check (both on the wall clock: a loaded machine fails them), no
# example database (a clean clone has none).  @settings of a test override only what they name.
settings.register_profile("flexmodal", derandomize=True, deadline=None, database=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("flexmodal")

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"
RIGS = REPO / "examples" / "rigs"


def one_line(capsys, code: int, *words: str) -> str:
    """The one-line refusal a bad input must give: exit ``code`` 2, a single stderr line starting
    ``flexmodal`` and holding every one of ``words``; returns that line."""
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("flexmodal"), (code, err)
    assert all(w in err[0] for w in words), err[0]
    return err[0]


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """tests/data: the seed papers' tables (``seeds/``), a real impact record (``real/``) and others."""
    return DATA


@pytest.fixture(scope="session")
def rigs_dir() -> Path:
    return RIGS


@pytest.fixture(scope="session")
def chromium() -> str:
    """Path of Debian's headless Chromium; installed with apt-get on a fresh machine (root) if missing."""
    import os
    import shutil
    import subprocess

    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None and os.geteuid() == 0 and shutil.which("apt-get"):
        env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
        subprocess.run(["apt-get", "update", "-qq"], check=False, env=env, capture_output=True)
        subprocess.run(["apt-get", "install", "-y", "-qq", "chromium"], check=False, env=env,
                       capture_output=True)
        exe = shutil.which("chromium")
    assert exe, "Debian's chromium is required for the report tests (apt-get install -y chromium)"
    return exe


@pytest.fixture(scope="session")
def warm_cli():
    """The installed ``flexmodal`` console script, each call a process of its own started warm (forked
    from a server that has imported numpy, scipy, pandas, h5py and matplotlib: tests/warm_cli.py), for
    tests of what a command does with its input (exit code, stderr, files) rather than of its start-up.
    ``warm_cli.run(args, cwd, timeout_s)`` -> (exit code or None if killed as hung, stderr)."""
    import sys

    from warm_cli import WarmCli

    exe = Path(sys.executable).with_name("flexmodal")
    assert exe.exists(), "the flexmodal console script is not installed (pip install -e .)"
    with WarmCli(str(exe)) as cli:
        yield cli


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory):
    """One run of ``flexmodal demo --out DIR`` for the whole session (it takes 20-60 s: tests/test_demo.py
    and tests/test_report_handover.py share it and only read its outputs): through the CLI's ``main``
    in this process, with every figure the reports embed kept (``reports.plots.figure_png`` observed).
    Returns (DIR, elapsed seconds not counting the time spent waiting for a CPU (tests/cpu_wait.py),
    stdout, [figures], stderr); the console script itself runs the demo in tests/test_cli_interrupt.py and
    tests/test_foundation_cli.py."""
    import contextlib
    import io
    import os
    import time

    from cpu_wait import CpuWait

    from flexmodal.app import main
    from flexmodal.reports import plots

    out = tmp_path_factory.mktemp("demo")
    figures = []
    original = plots.figure_png

    def keep(fig, dpi=100):
        figures.append(fig)
        return original(fig, dpi)

    stdout, stderr = io.StringIO(), io.StringIO()
    with CpuWait(os.getpid(), step_s=0.1) as waits, pytest.MonkeyPatch.context() as mp, \
            contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        start = time.monotonic()
        mp.setattr(plots, "figure_png", keep)
        code = main(["demo", "--out", str(out)])
        end = time.monotonic()
    elapsed = waits.unloaded(start, end)  # the time spent waiting for a CPU (load) not counted
    assert code == 0, stderr.getvalue()
    return out, elapsed, stdout.getvalue(), figures, stderr.getvalue()
