"""The commands of the CLI: their registry and the one shape of a sub-command.

``COMMANDS`` holds, by name, the functions ``add(subparsers)`` that add sub-commands to the parser (a
built-in entry names a command module's ``register``, imported when the parser is built); app.py adds
them in registration order.  An ``add`` calls :func:`command` with the command's name and its handler;
the handler's docstring is the command's text: its first line the one-line ``help`` listed by
``flexmodal --help``, the paragraph after it the ``description`` of ``flexmodal NAME --help``.  The
module imports only argparse and the registry, so building the parser stays cheap.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any, Protocol

from flexmodal.checked_io.errors import FlexmodalError
from flexmodal.checked_io.registry import Registry


class Subcommands(Protocol):
    """What ``ArgumentParser.add_subparsers()`` returns, as an entry's ``add`` uses it (argparse names
    that class only privately)."""

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser: ...


Handler = Callable[[argparse.Namespace], int]
Adder = Callable[[Subcommands], None]

COMMANDS: Registry[Adder] = Registry("command", FlexmodalError, {
    "demo-sim": "flexmodal.cli.simulate:register", "acquire": "flexmodal.cli.acquire:register",
    "frf-identify": "flexmodal.cli.modal:register", "predict": "flexmodal.cli.predict:register",
    "compare": "flexmodal.cli.compare:register", "diagnose": "flexmodal.cli.diagnose:register",
    "report": "flexmodal.cli.report:register",
})


def register_command(name: str, add: Adder) -> Adder:
    """Add (or replace) the entry ``name``: ``add(subparsers)`` adds its sub-command(s) with
    :func:`command`."""
    return COMMANDS.register(name, add)


def unregister_command(name: str) -> None:
    """Remove the entry ``name`` (its sub-commands are no longer offered)."""
    COMMANDS.unregister(name)


def registered_commands() -> tuple[str, ...]:
    """Names of the command entries, in the order their sub-commands are listed."""
    return COMMANDS.names()


def command(sub: Subcommands, name: str, run: Handler) -> argparse.ArgumentParser:
    """Add the sub-command ``name`` to ``sub``, described by ``run``'s docstring and dispatched to
    ``run`` (``args.func``); returns its parser for the options."""
    summary, _, body = (run.__doc__ or "").strip().partition("\n")
    parser = sub.add_parser(name, help=summary.strip(), description=" ".join(body.split()) or None)
    parser.set_defaults(func=run)
    return parser
