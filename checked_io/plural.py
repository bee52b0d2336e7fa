"""The one way flexmodal writes a count with its noun in text people read: the singular for one, the
plural otherwise (``1 mode``, ``3 modes``, ``0 windows``), never a hand-made ``mode(s)``."""

from __future__ import annotations


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, in its plural (``plural``, else ``noun + "s"``) unless ``n`` is one.

    Examples
    --------
    >>> counted(1, "mode"), counted(3, "mode"), counted(0, "window"), counted(2, "peak", "peaks")
    ('1 mode', '3 modes', '0 windows', '2 peaks')
    """
    return f"{n} {noun if n == 1 else plural or noun + 's'}"
