"""Report sections added to the validation report: a registry of :class:`Section` entries, each drawing
its figures from what the report is written from (:class:`ReportInputs`).  A new section is one
``register_section(name, Section(title, figures))`` call; reports.html renders every registered section
after the built-in ones, numbered and listed in the contents like them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from flexmodal.checked_io.registry import Registry
from flexmodal.reports.errors import ReportError


@dataclass(frozen=True)
class ReportInputs:
    """What a report is written from (the arguments of reports.html.write_report): ``runs``
    (reports.runs.RunSummary), ``comparison``, ``measured``, ``repeats``, ``predictions`` ((name, modal
    table) pairs), ``shapes``, ``diagnosis`` and ``rig_name``."""

    runs: Sequence[Any] = ()
    comparison: Any = None
    measured: Any = None
    repeats: Sequence[Any] = ()
    predictions: Sequence[tuple[str, Any]] = ()
    shapes: Mapping[str, object] | None = None
    diagnosis: Any = None
    rig_name: str = ""


@dataclass(frozen=True)
class Section:
    """A report section: its ``title`` and ``figures(inputs)``, the (matplotlib Figure, caption) pairs it
    shows (none: the section is left out of that report)."""

    title: str
    figures: Callable[[ReportInputs], Sequence[tuple[Any, str]]]


SECTIONS: Registry[Section] = Registry("report section", ReportError)


def register_section(name: str, section: Section) -> Section:
    """Add (or replace) the report section ``name`` (its anchor in the page is ``section-<name>``)."""
    return SECTIONS.register(name, section)


def unregister_section(name: str) -> None:
    """Remove the report section ``name``."""
    SECTIONS.unregister(name)


def registered_sections() -> tuple[str, ...]:
    """Names of the added report sections, in registration order."""
    return SECTIONS.names()
