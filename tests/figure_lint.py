"""What a reader of a figure sees: tick labels as plain text and every text artist inside the canvas.

``problems(fig)`` draws a ``matplotlib.figure.Figure`` on an Agg canvas at the report's resolution and
lists, one line each, a drawn tick label holding ``$`` or ``mathdefault`` (mathtext shown raw when
parsing is off, and mathtext markup is not what the report promises) and any visible, non-empty text
artist whose window extent leaves the canvas (a label cut at the edge).
"""

from __future__ import annotations

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

SLACK_PX = 1.0


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
    """One line per unreadable tick label or text artist outside the canvas (empty: the figure is fine)."""
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
    return found
