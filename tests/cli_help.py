"""The CLI's help as a user reads it, through the public parser only (no argparse internals): the text
of ``flexmodal PATH --help``, the sub-commands it lists with their help lines, and the choices an
option offers (from the one-line error a wrong value gets)."""

from __future__ import annotations

import contextlib
import io
import os
import re
from unittest import mock

import pytest

from flexmodal.app import UsageError, build_parser

ENTRY = re.compile(r"^    (\S+)(?:\s+(\S.*))?$")   # a sub-command's line under COMMAND / CMD


def help_text(*path: str) -> str:
    """``flexmodal PATH --help`` as printed, one line per entry (a wide terminal: no wrapping)."""
    out = io.StringIO()
    with mock.patch.dict(os.environ, {"COLUMNS": "1000"}), contextlib.redirect_stdout(out), \
            pytest.raises(SystemExit):
        build_parser().parse_args([*path, "--help"])
    return out.getvalue()


def subcommands(*path: str) -> dict[str, str]:
    """{name: help line} of the sub-commands ``flexmodal PATH --help`` lists, in its order."""
    lines = help_text(*path).splitlines()
    start = next((k for k, line in enumerate(lines) if line == "positional arguments:"), None)
    found: dict[str, str] = {}
    for line in lines[start + 2:] if start is not None else ():
        if not line.startswith("    "):
            break
        if m := ENTRY.match(line):
            found[m.group(1)] = m.group(2) or ""
    return found


def command_paths() -> list[tuple[str, ...]]:
    """Every command and nested command, e.g. ``("frf",)``, ``("sim",)``, ``("sim", "serve")``."""
    paths, stack = [], [()]
    while stack:
        path = stack.pop()
        for name in subcommands(*path):
            paths.append((*path, name))
            stack.append((*path, name))
    return paths


def choices(path: tuple[str, ...], option: str) -> tuple[str, ...]:
    """The values ``flexmodal PATH OPTION`` accepts, in order, as the error for a wrong one lists them."""
    with pytest.raises(UsageError) as info:
        build_parser().parse_args([*path, option, "no-such-entry"])
    listed = str(info.value).partition("choose from ")[2].rstrip(")")
    return tuple(v.strip().strip("'") for v in listed.split(","))
