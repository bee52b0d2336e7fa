"""CLI commands of the `daq` package (registered by app.py)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Add this package's sub-commands to the flexmodal parser."""
