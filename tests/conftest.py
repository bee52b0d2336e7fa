"""Shared test fixtures: paths to the repository, the committed test data and the example rigs."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data"
RIGS = REPO / "examples" / "rigs"


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
