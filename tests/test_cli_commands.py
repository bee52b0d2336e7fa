"""flexmodal.cli.commands: a sub-command is registered from its handler, whose docstring is its help."""

from __future__ import annotations

import argparse
import re

from cli_help import command_paths, help_text, subcommands

from flexmodal.cli.commands import command


def _toy(args: argparse.Namespace) -> int:
    """count the toys

    Count every toy in the
    box, twice.
    """
    return 7


def _bare(args: argparse.Namespace) -> int:
    return 0


def test_help_and_description_come_from_the_handler_docstring() -> None:
    parser = argparse.ArgumentParser(prog="flexmodal")
    sub = parser.add_subparsers(dest="command")
    toy = command(sub, "toy", _toy)
    toy.add_argument("--n", type=int, default=1)
    bare = command(sub, "bare", _bare)
    listed = parser.format_help()
    assert re.search(r"^    toy +count the toys$", listed, re.M) and re.search(r"^    bare$", listed, re.M)
    assert toy.description == "Count every toy in the box, twice."
    args = parser.parse_args(["toy", "--n", "3"])
    assert args.func is _toy and args.n == 3 and args.func(args) == 7
    assert bare.description is None and parser.parse_args(["bare"]).func is _bare


def _description(path: tuple[str, ...]) -> str:
    """The paragraph between the usage and the argument lists of ``flexmodal PATH --help``."""
    second = help_text(*path).split("\n\n")[1]
    return "" if second.startswith(("positional arguments:", "options:")) else second


def test_every_command_has_a_help_line_and_a_description() -> None:
    """Read from the --help a user sees: `flexmodal --help` lists each command with a one-line help,
    and each `flexmodal CMD --help` (nested ones included) starts with its description paragraph."""
    paths = command_paths()
    assert {p[-1] for p in paths} >= {"demo", "sim", "serve", "acquire", "frf", "identify", "predict",
                                      "compare", "diagnose", "report"}
    for path in paths:
        help_line = subcommands(*path[:-1])[path[-1]]
        assert help_line and "\n" not in help_line, path
        if path != ("sim",):  # a group: its own help line only
            description = _description(path)
            assert description and "  " not in description and "\n" not in description, path


def test_sim_serve_says_on_stderr_what_it_streams_and_how_to_stop_it(capsys) -> None:
    """A user's ``sim serve`` printed its endpoint and nothing else: stdout still holds the endpoint
    alone (sessions and scripts read it), stderr one line naming it, the test streamed and how it ends
    (``--quiet`` and a session's own simulator, ``--exit-with-parent``, say nothing there)."""
    from flexmodal.app import main

    assert main(["sim", "serve", "--protocol", "modbus", "--duration", "0.2", "--pose", "theta_deg=60"]) == 0
    out, err = capsys.readouterr()
    endpoint = out.strip()
    assert re.fullmatch(r"127\.0\.0\.1:\d+", endpoint), out
    assert err == (f"sim serve: {endpoint}: a Modbus TCP server streaming the demo arm's impact test at 2048 "
                   "Hz (theta_deg=60); record it with a session whose device names this endpoint "
                   "(docs/acquisition.md); it stops after 0.2 s\n")
