"""Command-line option values: argparse ``type=`` callables that accept only sensible numbers.

``float("inf")``, ``float("nan")`` and out-of-range integers pass argparse's plain ``type=float`` /
``type=int``; these callables reject them with an :class:`argparse.ArgumentTypeError`, which the CLI
prints as one line naming the option and the value (exit 2).  A subnormal number (``5e-324``: nonzero
but below the smallest normal double, 2.2e-308) is refused too: no quantity of flexmodal is that small,
and it turns into 0 or infinity at the first product or quotient (a bin count, a chi-square).  ``-0``
is 0.  Imports only the standard library (and checked_io.text, which does too), so registering the
commands stays cheap.
"""

from __future__ import annotations

import argparse
import math
import numbers
import sys
from collections.abc import Callable

from flexmodal.checked_io.text import name_fault


def _bounds_text(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    parts = []
    if lo is not None:
        parts.append(f"{'>' if lo_open else '>='} {lo:g}")
    if hi is not None:
        parts.append(f"{'<' if hi_open else '<='} {hi:g}")
    return " and ".join(parts)


def real(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
         hi_open: bool = False, name: str = "number") -> Callable[[str], float]:
    """A finite float within [lo, hi] (an open end with ``lo_open``/``hi_open``)."""
    bounds = _bounds_text(lo, hi, lo_open, hi_open)
    expected = f"a finite {name}" + (f" {bounds}" if bounds else "")

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        value += 0.0   # -0 is 0
        if value and abs(value) < sys.float_info.min:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}, a subnormal number "
                                             f"(nonzero, below {sys.float_info.min:.3g})")
        bad = (not math.isfinite(value)
               or (lo is not None and (value < lo or (lo_open and value == lo)))
               or (hi is not None and (value > hi or (hi_open and value == hi))))
        if bad:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value

    parse.__name__ = name
    return parse


def integer(lo: int | None = None, hi: int | None = None, *, name: str = "whole number"
            ) -> Callable[[str], int]:
    """A whole number within [lo, hi]."""
    bounds = _bounds_text(lo, hi, False, False)
    expected = f"a {name}" + (f" {bounds}" if bounds else "")

    def parse(text: str) -> int:
        try:
            value = int(text.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value

    parse.__name__ = name
    return parse


def names(text: str) -> list[str]:
    """A comma-separated list of one or more names (channels, configurations), blanks around each
    stripped; an empty list or an empty item (``""``, ``a,,b``) is refused: it was taken as "all"
    or as a name nothing has."""
    items = [t.strip() for t in text.split(",")]
    if not text.strip() or not all(items):
        raise argparse.ArgumentTypeError(f"expected NAME[,NAME...] with no empty name, got {text!r}")
    return items


def nonempty(text: str) -> str:
    """A text option that holds a visible character: ``--source ""`` or ``--rig ""`` (a script's unset
    variable) was taken as the option left out, and its default used in silence.

    Parameters
    ----------
    text : str
        The option's value as given on the command line.

    Returns
    -------
    str
        ``text`` unchanged.

    Raises
    ------
    argparse.ArgumentTypeError
        When ``text`` is empty or blank (argparse names the option).

    Examples
    --------
    >>> nonempty("rig.toml")
    'rig.toml'
    >>> nonempty("  ")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected a non-empty value, got '  ' (leave the option out for its default)
    """
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a non-empty value, got {text!r} (leave the option out "
                                         "for its default)")
    return text


def text_line(text: str) -> str:
    """A free-text option printed inside a title, a caption or a table (``--title``, ``--caption``): a
    visible character and no control character, line break or bidirectional control
    (:func:`flexmodal.checked_io.text.name_fault`): a newline in ``--caption`` split the Markdown
    table's caption line, an escape sequence in it reached the terminal, both with exit 0.

    Examples
    --------
    >>> text_line("Seed 003: f1 and f2")
    'Seed 003: f1 and f2'
    >>> text_line("a\\nb")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: expected one line of text, got 'a\\nb': it holds the control character '\\n'
    """
    fault = name_fault(text)
    if fault:
        raise argparse.ArgumentTypeError(f"expected one line of text, got {text!r}: it {fault}")
    return text


def given(value: object, kind: Callable[[str], float], what: str, error: type[Exception]) -> float:
    """``value`` passed from Python (the public API) checked by the option ``kind`` the command line
    uses for it, so both paths accept the same numbers: a bool, a string or another object is not a
    number, and NaN, infinity or a value out of range is refused as on the command line (``error``
    names ``what`` and the value; the API had crashed inside, or run, on what the CLI refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise error(f"{what} = {value!r} is not a number")
    try:
        return kind(str(value))
    except argparse.ArgumentTypeError as exc:
        raise error(f"{what} = {value!r}: {exc}") from None


# The option kinds the commands share.
seconds = real(0.0, 1e9, lo_open=True, name="duration in seconds")   # 1e9 s: 31.7 years
hertz = real(0.0, name="frequency in Hz")
rate_hz = real(0.0, 1e7, lo_open=True, name="sample rate in Hz")
fraction = real(0.0, 1.0, name="fraction")
overlap = real(0.0, 63 / 64, name="overlap fraction")  # modal.spectra.MIN_STEP_FRACTION: steps >= nfft/64
tcp_port = integer(0, 65535, name="TCP port")
workers = integer(0, 256, name="number of worker processes")
seed = integer(0, 2**32 - 1, name="seed")
instant = real(0.0, name="time in seconds")
probability = real(0.0, 1.0, hi_open=True, name="fraction")
finite = real()
nonnegative = real(0.0)
positive = real(0.0, lo_open=True)
count = integer(1, name="whole number")
positive_hz = real(0.0, lo_open=True, name="frequency in Hz")
model_order = integer(2, 400, name="model order")
MAX_NFFT = 1 << 24   # FRF segment length [samples] of frf --nfft (stored groups: runs_io.WHOLE_NUMBERS)
segment_length = integer(8, MAX_NFFT, name="segment length")
