"""flexmodal.cli.commands: a sub-command is registered from its handler, whose docstring is its help."""

from __future__ import annotations

import argparse

from flexmodal.app import build_parser
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
    command(sub, "bare", _bare)
    assert sub._choices_actions[0].help == "count the toys"
    assert toy.description == "Count every toy in the box, twice."
    args = parser.parse_args(["toy", "--n", "3"])
    assert args.func is _toy and args.n == 3 and args.func(args) == 7
    assert sub.choices["bare"].description is None and sub._choices_actions[1].help == ""


def test_every_command_has_a_help_line_and_a_description() -> None:
    stack, seen = [build_parser()], {}
    while stack:
        parser = stack.pop()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                helps = {a.dest: a.help for a in action._choices_actions}
                for name, sub in action.choices.items():
                    seen[name] = (helps[name], sub.description, sub._defaults.get("func"))
                    stack.append(sub)
    assert set(seen) >= {"demo", "sim", "serve", "acquire", "frf", "identify", "predict", "compare",
                         "diagnose", "report"}
    for name, (help_line, description, func) in seen.items():
        assert help_line and "\n" not in help_line, name
        if name != "sim":  # a group: its own help line only
            assert description and "  " not in description and func is not None, name
