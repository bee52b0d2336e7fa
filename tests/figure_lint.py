"""What a reader of a figure sees: tick labels as plain text, every text artist inside the canvas,
a unit on every numeric axis and a log axis one can read values off.

``problems(fig)`` draws a ``matplotlib.figure.Figure`` on an Agg canvas at the report's resolution and
lists, one line each, a drawn tick label holding ``$`` or ``mathdefault`` (mathtext shown raw when
parsing is off, and mathtext markup is not what the report promises), any visible, non-empty text
artist whose window extent leaves the canvas (a label cut at the edge), an axis with numeric tick
labels under a label without a ``[unit]`` (``[-]`` for a ratio), and a log axis whose labelled ticks
leave more than a quarter of its span unlabelled at an end (at least 0.45 decade) or between two labels
(at least 0.4 decade): a 20-1000 Hz axis labelled only at 100 Hz, where no mode can be read off; and
any text under ``READ_PX`` high where the figure is shown ``SHOWN_PX`` wide (the report in an 800 px
window shrinks a wider figure to fit: a 1020 px figure's 7 pt legend came out 6.7 px high).
"""

from __future__ import annotations

import math
import re

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

SLACK_PX = 1.0
SHOWN_PX = 700.0   # a figure's width in the report in an 800 px window (body margins, a run's box)
READ_PX = 8.0      # the least height [px] a text is read at
UNIT = re.compile(r"\[[^\]]+\]")
NUMBER = re.compile(r"^[-−+]?(\d[\d.,]*|\.\d+)(e[-+]?\d+)?(×10[⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+)?$|^10[⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+$")


def _axis_problems(fig: Figure, drawn: list[Text]) -> list[str]:
    """A numeric axis without a unit in its label; a log axis with too long a stretch unlabelled."""
    found, drawn_ids = [], {id(t) for t in drawn}
    for ax in (a for a in fig.axes if a.get_visible()):
        for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            major = zip(axis.get_major_ticks(), axis.get_majorticklocs(), strict=False)
            labels = [(loc, t.get_text()) for tick, loc in major
                      for t in (tick.label1, tick.label2) if id(t) in drawn_ids]
            if not labels or not all(NUMBER.match(text.strip()) for _, text in labels):
                continue
            where = f"{ax.get_title() or ax.get_ylabel() or 'axes'!r} {name} axis"
            if not UNIT.search(axis.get_label_text()):
                found.append(f"{where} label {axis.get_label_text()!r} names no [unit]")
            lo, hi = sorted(axis.get_view_interval())
            if axis.get_scale() == "log" and lo > 0:
                marks = sorted(math.log10(loc) for loc, _ in labels)
                span = math.log10(hi / lo)
                inner = max((b - a for a, b in zip(marks, marks[1:], strict=False)), default=0.0)
                ends = max(marks[0] - math.log10(lo), math.log10(hi) - marks[-1])
                if inner > max(0.25 * span, 0.4) or ends > max(0.25 * span, 0.45):
                    found.append(f"{where}: log axis {lo:.3g}..{hi:.3g} labelled only at "
                                 f"{[t for _, t in labels]} (a value near an end cannot be read off)")
    return found


def _drawn_tick_labels(fig: Figure) -> tuple[list[Text], set[int]]:
    """Tick labels drawn (tick inside the view interval), and the ids of every tick label artist."""
    drawn, every = [], set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            span = (hi - lo) or 1.0
            for ticks, locs in ((axis.get_major_ticks(), axis.get_majorticklocs()),
                                (axis.get_minor_ticks(), axis.get_minorticklocs())):
                for tick in ticks:
                    every.update({id(tick.label1), id(tick.label2)})
                for tick, loc in zip(ticks, locs, strict=False):
                    if lo - 1e-9 * span <= loc <= hi + 1e-9 * span and ax.get_visible():
                        drawn += [t for t in (tick.label1, tick.label2) if t.get_visible() and t.get_text()]
    return drawn, every


def problems(fig: Figure, dpi: float = 100.0) -> list[str]:
    """One line per unreadable tick label, text artist outside the canvas or too small to read at 800 px,
    numeric axis without a unit or log axis too sparsely labelled (empty: the figure is fine)."""
    fig.set_dpi(dpi)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    width, height = canvas.get_width_height()
    drawn, ticks = _drawn_tick_labels(fig)
    found = [f"tick label {t.get_text()!r} is mathtext markup" for t in drawn
             if "$" in t.get_text() or "mathdefault" in t.get_text()]
    others = [t for t in fig.findobj(Text) if id(t) not in ticks and t.get_visible() and t.get_text()
              and (t.axes is None or t.axes.get_visible())]
    for t in [*drawn, *others]:
        box = t.get_window_extent(renderer)
        if min(box.x0, box.y0) < -SLACK_PX or box.x1 > width + SLACK_PX or box.y1 > height + SLACK_PX:
            found.append(f"text {t.get_text()!r} at x {box.x0:.0f}..{box.x1:.0f}, "
                         f"y {box.y0:.0f}..{box.y1:.0f} leaves the {width}x{height} px canvas")
    shown = min(1.0, SHOWN_PX / width)
    found += [f"text {t.get_text()!r} is {px:.1f} px high where the figure is shown {SHOWN_PX:g} px wide"
              for t in [*drawn, *others] if (px := t.get_fontsize() * dpi / 72 * shown) < READ_PX - 1e-9]
    return found + _axis_problems(fig, drawn)
