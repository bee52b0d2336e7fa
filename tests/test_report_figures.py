"""Every figure of the demo's report is readable wherever it is drawn.

The demo (api.demo: simulated impact, random and operational tests of the demo arm) runs
in this process with ``reports.plots.figure_png`` observed, so every ``Figure`` the report embeds is
kept and checked (tests/figure_lint.py): no tick label in mathtext markup, no text outside the canvas.
Importing and drawing flexmodal's figures changes no global matplotlib state (backend, rcParams).
"""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from figure_lint import problems

from flexmodal.reports import plots

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def demo_figures(tmp_path_factory):
    """(report path, [(caption-less figure, kind)]) of one in-process demo run."""
    from flexmodal.api import demo

    out = tmp_path_factory.mktemp("demo_figures")
    seen = []
    original = plots.figure_png

    def keep(fig, dpi=100):
        seen.append(fig)
        return original(fig, dpi)

    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(io.StringIO()):
        mp.setattr(plots, "figure_png", keep)
        report = demo(out, quiet=True)
    return report, seen


def test_every_figure_of_the_demo_report_has_plain_ticks_and_stays_on_the_canvas(demo_figures):
    report, figures = demo_figures
    pages = [report, report.parent / "diagnosis.html"]
    assert len(figures) == sum(p.read_text().count("data:image/png;base64,") for p in pages) >= 20
    # every kind of report figure is among them: FRF, stabilisation (pLSCF and SSI), synthesis, MAC,
    # frequency against pose, mode shapes on the arm, FDD, gap per mode
    ylabels = {ax.get_ylabel().split(" [")[0] for fig in figures for ax in fig.axes}
    assert {"|H|", "phase (wrapped)", "coherence", "model order", "CMIF", "FDD singular values",
            "natural frequency", "y", "relative frequency error", "singular values of G_yy"} <= ylabels
    found = {i: p for i, fig in enumerate(figures) if (p := problems(fig))}
    assert found == {}


def test_log_ticks_are_plain_text_and_frf_units_follow_the_channels(demo_figures):
    _, figures = demo_figures
    frf = next(fig for fig in figures if fig.axes[0].get_ylabel().startswith("|H|"))
    assert frf.axes[0].get_ylabel() == "|H| [(m/s²)/N]"       # the demo's channels: m/s^2 per N
    labels = [t.get_text() for t in frf.axes[0].yaxis.get_ticklabels() if t.get_text()]
    assert labels and all("$" not in t and "mathdefault" not in t for t in labels)
    assert [plots.tick_text(v) for v in (1e-3, 0.02, 5.0, 300.0, 2e4, 1e6)] == \
        ["10⁻³", "0.02", "5", "300", "2×10⁴", "10⁶"]
    assert plots.ratio_unit(["g", "g"], "N") == "g/N" and plots.ratio_unit(["m/s^2"], "N") == "(m/s²)/N"


def test_shapes_are_drawn_with_equal_aspect(demo_figures):
    _, figures = demo_figures
    shapes = [ax for fig in figures for ax in fig.axes if ax.get_ylabel() == "y [m]" and ax.get_visible()]
    assert shapes
    for ax in shapes:
        (x0, y0), (x1, y1) = ax.transData.transform([(0.0, 0.0), (1.0, 1.0)])
        assert abs((x1 - x0) - (y1 - y0)) < 1e-6 * abs(x1 - x0)   # 1 m is as long across as up


def test_wrapped_phase_breaks_the_line_instead_of_jumping():
    f = np.linspace(1, 100, 400)
    H = 1.0 / (1 - (f / 50) ** 2 + 0.02j * f / 50) * np.exp(-1j * f / 10)   # several wraps
    deg = plots.wrapped_phase_deg(H)
    finite = np.isfinite(deg)
    raw = np.degrees(np.angle(H))
    assert (~finite).sum() == np.sum(np.abs(np.diff(raw)) > 180) >= 2     # one gap per wrap
    steps = np.abs(np.diff(deg))
    assert np.nanmax(steps) < 30                                 # nowhere a jump across the axis
    np.testing.assert_allclose(deg[finite], raw[finite])


def test_trends_figure_is_readable():
    from flexmodal.modal.table import ModalTable

    rows = [{"config": f"t{t}p{p}", "mode": m, "freq_hz": 10.0 * m / (1 + p) + t / 90,
             "pose.theta_deg": t, "pose.payload_kg": p}
            for t in (0, 90) for p in (0.0, 0.5, 1.0) for m in (1, 2, 3, 4)]
    fig = plots.plot_trends(ModalTable.from_records(rows, "fe"), "payload_kg", "theta_deg", "kg", "deg",
                            title="cost in $ per mode")
    assert problems(fig) == []


def test_the_lint_catches_what_the_issue_reported():
    """The check is not vacuous: raw mathtext ticks and a label pushed off the canvas are found."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4, 3))
    ax = fig.subplots()
    ax.semilogy([1, 2, 3], [1, 100, 1e4])
    ax.set_ylabel("a very long label with a unit [(m/s²)/N]", fontsize=30)
    found = problems(fig)
    assert any("mathtext" in p for p in found) and any("leaves the" in p for p in found)


def test_flexmodal_changes_no_global_matplotlib_state():
    """Importing the plots and drawing a figure leave backend and rcParams as they were, so a notebook's
    inline backend and a user's own ``$\\zeta$`` labels keep working."""
    code = """
import matplotlib
before = dict(matplotlib.rcParams)
backend = matplotlib.get_backend()
from flexmodal.reports import plots, oma, html
import numpy as np
fig = plots.plot_frf(np.linspace(1, 100, 50), np.ones((2, 50)) * (1 + 1j), np.ones((2, 50)), ["a$", "b"])
plots.figure_png(fig)
after = dict(matplotlib.rcParams)
changed = {k for k in before if before[k] != after[k] and k != "backend"}
assert not changed, changed
assert matplotlib.get_backend() == backend
assert matplotlib.rcParams["text.parse_math"] is True
print("ok")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=REPO.parent)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_stabilisation_diagrams_select_the_modes_of_the_table_of_the_same_run(demo_figures):
    """Each impact run's diagram (crosses), its caption and the demo's modal table (modes.csv, identified
    from those runs) give the same modes."""
    import re

    from flexmodal.modal.table import ModalTable

    report, figures = demo_figures
    table = ModalTable.read_csv(report.parent / "modes.csv")
    html = report.read_text()
    captions = re.findall(r"<figcaption>(.*?)</figcaption>", html)
    report_figures = figures[len(figures) - len(captions):]          # diagnosis.html's figure came first
    checked = 0
    for fig, caption in zip(report_figures, captions, strict=True):
        m = re.match(r"(?:Figure \d+\. )?runs\.h5::(\w+)-impact: pLSCF stabilisation diagram"
                     r".*selected modes at ([\d., ]+) Hz", caption)
        if not m:
            continue
        expected = table.freq_hz(m.group(1))
        np.testing.assert_allclose([float(x) for x in m.group(2).split(",")], expected, rtol=5e-4)
        crosses = next(line for line in fig.axes[0].get_lines() if line.get_marker() == "x")
        x = np.asarray(crosses.get_xdata(), float)
        nearest = np.abs(x[:, None] - expected[None, :]).min(axis=1) / x
        assert np.all(nearest < 0.02)                          # every cross sits on a mode of the table
        assert {int(np.argmin(np.abs(expected - v))) for v in x} == set(range(expected.size))
        checked += 1
    assert checked == len(table.configs)
