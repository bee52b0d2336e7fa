"""The one way flexmodal writes a fraction as a percentage in text people read (CLI output, reports,
verdicts): three significant digits, a space, ``%`` (``43.1 %``; SI writes a space before ``%``)."""

from __future__ import annotations


def percent(fraction: float, signed: bool = False) -> str:
    """``fraction`` (0.01 = 1 %) as percent text with three significant digits; ``signed``: with its
    sign (``+5.4 %``).

    Examples
    --------
    >>> percent(0.4308), percent(0.0328), percent(0.005), percent(0.054, signed=True), percent(1.0)
    ('43.1 %', '3.28 %', '0.5 %', '+5.4 %', '100 %')
    """
    return f"{100 * fraction:{'+' if signed else ''}.3g} %"
