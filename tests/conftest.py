"""Shared test fixtures: paths to the repository, ../shared and the example rigs."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
RIGS = REPO / "examples" / "rigs"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """../shared beside the repository (seeds, tables, CONTRACT, real data)."""
    assert SHARED.is_dir(), f"expected ../shared beside the repository at {SHARED}"
    return SHARED


@pytest.fixture(scope="session")
def rigs_dir() -> Path:
    return RIGS
