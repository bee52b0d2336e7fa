"""The sections of the validation report: a registry of :class:`Section` entries, each drawing its
figures from what the report is written from (:class:`ReportInputs`).  The built-in ones are entries too
(reports/figure_sections.py draws ``modes`` and ``gap``; the tables are blocks of the template).  A new
section is one ``register_section(name, Section(title, figures))`` call; reports.html renders every
registered section in registration order, numbered and listed in the contents.
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
    shows (a None figure: the caption alone, as a note; none at all: the section is left out of that
    report); ``anchor`` its id in the page (default ``section-<name>``).  The built-in sections that are
    tables rather than figures name the ``block`` of the template that renders them (reports/templates/
    report.html) and have no ``figures``.  ``needs`` says what a figure section is drawn from, for the
    report's progress line when it is left out (``"a diagnosis (--diagnosis)"``)."""

    title: str
    figures: Callable[[ReportInputs], Sequence[tuple[Any, str]]] | None = None
    anchor: str = ""
    block: str = ""
    needs: str = ""


# the built-in sections in the order of the page; those added with register_section follow them
SECTIONS: Registry[Section] = Registry("report section", ReportError, {
    "comparison": Section("Measured and predicted modes", anchor="comparison", block="comparison"),
    "diagnosis": Section("Sim-to-real gap diagnosis", anchor="diagnosis", block="diagnosis"),
    "modes": "flexmodal.reports.figure_sections:MODES",
    "animations": Section("Animated mode shapes", anchor="animations", block="animations"),
    "identified": Section("Identified modes", anchor="identified", block="identified"),
    "runs": Section("Stored runs", anchor="runs", block="runs"),
    "gap": "flexmodal.reports.figure_sections:GAP",
})


def register_section(name: str, section: Section) -> Section:
    """Add (or replace) the report section ``name`` (its anchor in the page is ``section-<name>``)."""
    return SECTIONS.register(name, section)


def unregister_section(name: str) -> None:
    """Remove the report section ``name``."""
    SECTIONS.unregister(name)


def registered_sections() -> tuple[str, ...]:
    """Names of the report sections, in registration order (the built-in ones first)."""
    return SECTIONS.names()
