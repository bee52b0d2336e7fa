"""Registration of a CLI sub-command from its handler: the one shape every ``*/cli.py`` shares.

A package's ``cli.register(sub)`` calls :func:`command` with the command's name and its handler; the
handler's docstring is the command's text: its first line the one-line ``help`` listed by ``flexmodal
--help``, the paragraph after it the ``description`` of ``flexmodal NAME --help``.  The module imports
only argparse, so building the parser stays cheap.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

Handler = Callable[[argparse.Namespace], int]


def command(sub: argparse._SubParsersAction, name: str, run: Handler) -> argparse.ArgumentParser:
    """Add the sub-command ``name`` to ``sub``, described by ``run``'s docstring and dispatched to
    ``run`` (``args.func``); returns its parser for the options."""
    summary, _, body = (run.__doc__ or "").strip().partition("\n")
    parser = sub.add_parser(name, help=summary.strip(), description=" ".join(body.split()) or None)
    parser.set_defaults(func=run)
    return parser
