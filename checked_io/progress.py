"""A transient progress bar on stderr for long work over many items (runs, configurations)."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager


@contextmanager
def progress_bar(total: int, label: str, quiet: bool = False) -> Iterator[Callable[[], None]]:
    """A transient progress bar of ``total`` items on stderr (rich, imported only when shown); yields
    its advance (call it once per item done).

    It is redrawn at each advance, not by a thread of its own, so that helper processes can be forked
    while it shows (modal.batch).  Shown only on a terminal and with more than one item: on a log or a
    pipe rich leaves an empty line, which put a blank line above an error's one line; ``quiet``: none.

    Examples
    --------
    Not on a terminal (as under a test): the advance does nothing and nothing is printed.

    >>> with progress_bar(3, "FRFs") as advance:
    ...     for _ in range(3):
    ...         advance()
    """
    if quiet or total < 2 or not sys.stderr.isatty():
        yield lambda: None
        return
    from rich.console import Console
    from rich.progress import Progress

    with Progress(transient=True, console=Console(file=sys.stderr), auto_refresh=False) as bar:
        task = bar.add_task(label, total=total)
        bar.refresh()
        yield lambda: bar.update(task, advance=1, refresh=True)
