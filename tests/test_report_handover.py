"""The demo's report is one a reviewer accepts: readable figures, a page to hand over, a PDF.

The demo (api.demo: simulated impact, random and operational tests of the demo arm) runs
in this process with ``reports.plots.figure_png`` observed, so every ``Figure`` the report embeds is
kept and checked (tests/figure_lint.py): no tick label in mathtext markup, no text outside the canvas.
Importing and drawing flexmodal's figures changes no global matplotlib state (backend, rcParams).
The page is opened in headless Chromium (tests/browser.py): contents whose links land, numbered
figures and tables, collapsed run blocks, no network request, open time; in print media at the A4
text width no table is wider than the page; ``report --pdf`` prints it.  Chromium missing is a failure.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from figure_lint import problems

from flexmodal.reports import plots

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def demo_figures(demo_run):
    """(report path, [(caption-less figure, kind)]) of the session's demo (tests/conftest.py
    ``demo_run``: run in this process with every embedded figure kept)."""
    out, _, _, figures, _ = demo_run
    return out / "report.html", figures


def test_every_figure_of_the_demo_report_has_plain_ticks_and_stays_on_the_canvas(demo_figures):
    report, figures = demo_figures
    pages = [report, report.parent / "diagnosis.html"]
    assert len(figures) == sum(p.read_text().count("data:image/png;base64,") for p in pages) >= 20
    # every kind of report figure is among them: FRF, stabilisation (pLSCF and SSI), synthesis, MAC,
    # frequency against pose, mode shapes on the arm, FDD, gap per mode
    ylabels = {ax.get_ylabel().split(" [")[0] for fig in figures for ax in fig.axes}
    assert {"|H|", "phase (wrapped)", "coherence", "model order", "CMIF", "FDD singular values",
            "natural frequency", "y", "RMS frequency error", "singular values of G_yy"} <= ylabels
    found = {i: p for i, fig in enumerate(figures) if (p := problems(fig))}
    assert found == {}


def test_log_ticks_are_plain_text_and_frf_units_follow_the_channels(demo_figures):
    _, figures = demo_figures
    frf = next(fig for fig in figures if fig.axes[0].get_ylabel().startswith("|H|"))
    assert frf.axes[0].get_ylabel() == "|H| [(m/s²)/N]"       # the demo's channels: m/s^2 per N
    labels = [t.get_text() for t in frf.axes[0].yaxis.get_ticklabels() if t.get_text()]
    assert labels and all("$" not in t and "mathdefault" not in t for t in labels)
    # one notation per axis: the FRF's 10⁻³ .. 100 read '10⁻³, 0.01, 0.1, 1, 10, 100' (two notations)
    assert len({any(c in t for c in "⁰¹²³⁴⁵⁶⁷⁸⁹") for t in labels}) == 1, labels
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
    from flexmodal.contract.table import ModalTable

    rows = [{"config": f"t{t}p{p}", "mode": m, "freq_hz": 10.0 * m / (1 + p) + t / 90,
             "pose.theta_deg": t, "pose.payload_kg": p}
            for t in (0, 90) for p in (0.0, 0.5, 1.0) for m in (1, 2, 3, 4)]
    fig = plots.plot_trends(ModalTable.from_records(rows, "fe"), "payload_kg", "theta_deg", "kg", "deg",
                            title="cost in $ per mode")
    assert problems(fig) == []


def test_the_lint_catches_what_the_issue_reported():
    """The check is not vacuous: raw mathtext ticks, a label pushed off the canvas and a legend too small
    to read where the report shows a 1020 px figure 700 px wide are found."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4, 3))
    ax = fig.subplots()
    ax.semilogy([1, 2, 3], [1, 100, 1e4])
    ax.set_ylabel("a very long label with a unit [(m/s²)/N]", fontsize=30)
    found = problems(fig)
    assert any("mathtext" in p for p in found) and any("leaves the" in p for p in found)
    wide = Figure(figsize=(10.2, 3), layout="constrained")
    wide.subplots().plot([0, 1], [0, 1], label="measured")
    wide.legend(loc="outside lower center", fontsize=7)
    assert "text 'measured' is 6.7 px high where the figure is shown 700 px wide" in problems(wide)


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
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                         cwd=REPO.parent)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_stabilisation_diagrams_select_the_modes_of_the_table_of_the_same_run(demo_figures):
    """Each impact run's diagram (crosses), its caption and the demo's modal table (modes.csv, identified
    from those runs) give the same modes."""
    from flexmodal.contract.table import ModalTable

    report, figures = demo_figures
    table = ModalTable.read_csv(report.parent / "modes.csv")
    html = report.read_text()
    captions = [re.sub(r"<[^>]+>", "", c)
                for c in re.findall(r'<img src="data:image/png[^>]*><figcaption>(.*?)</figcaption>', html)]
    report_figures = figures[len(figures) - len(captions):]          # diagnosis.html's figure came first
    checked = 0
    for fig, caption in zip(report_figures, captions, strict=True):
        m = re.match(r"(?:Figure \d+\. )?runs\.h5::(\w+-impact): stabilisation diagram of the pLSCF "
                     r"identification.*selected modes?, at ([\d., and]+) Hz", caption)
        if not m:
            continue
        expected = table.freq_hz(m.group(1))
        np.testing.assert_allclose([float(x) for x in re.split(r", | and ", m.group(2))], expected, rtol=5e-4)
        crosses = next(line for line in fig.axes[0].get_lines() if line.get_marker() == "x")
        x = np.asarray(crosses.get_xdata(), float)
        nearest = np.abs(x[:, None] - expected[None, :]).min(axis=1) / x
        assert np.all(nearest < 0.02)                          # every cross sits on a mode of the table
        assert {int(np.argmin(np.abs(expected - v))) for v in x} == set(range(expected.size))
        checked += 1
    assert checked == len([c for c in table.configs if c.endswith("-impact")])


# -- the page in Chromium ---------------------------------------------------------------------------

A4_TEXT_WIDTH_PX = round((210 - 2 * 12) / 25.4 * 96)      # @page margins 12 mm: 703 CSS px

PAGE_JS = """(() => {
  const links = [...document.querySelectorAll('nav.contents a')].map(a => a.getAttribute('href'));
  const caps = [...document.querySelectorAll('figcaption .num-label')].map(e => e.textContent);
  const tabs = [...document.querySelectorAll('caption')].map(e => e.textContent);
  const details = [...document.querySelectorAll('details')];
  const nav = document.querySelector('nav.contents').getBoundingClientRect();
  return {links, missing: links.filter(h => !document.getElementById(h.slice(1))), caps, tabs,
          details: details.length, open: details.filter(d => d.open).length,
          figures_in_details: details.reduce((n, d) => n + d.querySelectorAll('figure').length, 0),
          nav: {x: nav.left, y: nav.top + scrollY, width: nav.width, height: nav.height},
          text: document.body.innerText, height: document.documentElement.scrollHeight};
})()"""

PRINT_JS = """(() => {
  document.querySelectorAll('details').forEach(d => { d.open = true; });
  const width = document.documentElement.clientWidth;
  const wide = [...document.querySelectorAll('table')].map(t => {
    const r = t.getBoundingClientRect();
    const cells = [...t.querySelectorAll('td, th')].filter(c => c.scrollWidth > c.clientWidth + 1);
    return {caption: (t.caption || {}).textContent, left: r.left, right: r.right, scroll: t.scrollWidth,
            overflowing_cells: cells.length};
  });
  const heads = [...document.querySelectorAll('thead')].map(h => getComputedStyle(h).display);
  const rows = [...document.querySelectorAll('tr')].map(r => getComputedStyle(r).breakInside);
  return {width, tables: wide, page: document.documentElement.scrollWidth, heads, rows};
})()"""


NARROW_PX = 400
NARROW_JS = """(() => ({width: document.documentElement.clientWidth,
  page: document.documentElement.scrollWidth,
  scrolling: [...document.querySelectorAll('table')]
    .filter(t => t.scrollWidth > t.clientWidth + 1).length}))()"""


def _session(browser):
    target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
    session = browser.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
    for domain in ("Runtime", "Log", "Page", "Network"):
        browser.send(f"{domain}.enable", {}, session)
    return session


def _evaluate(browser, session, js):
    reply = browser.send("Runtime.evaluate", {"returnByValue": True, "expression": js}, session)
    return reply["result"]["value"]


@pytest.fixture(scope="module")
def page(demo_figures, chromium, tmp_path_factory):
    """The demo report in Chromium at 1280 px: what the page holds, a screenshot of the top and of the
    contents, the times of three loads [s] (tests/cpu_wait.py clock), every DevTools event; then the
    same page in print media at the A4 text width."""
    import base64
    import time

    from browser import Browser
    from cpu_wait import CpuWait

    report, _ = demo_figures
    tmp = tmp_path_factory.mktemp("chromium")
    browser = Browser(chromium, tmp / "profile")
    try:
        session = _session(browser)
        browser.send("Emulation.setDeviceMetricsOverride",
                     {"width": 1280, "height": 900, "deviceScaleFactor": 1, "mobile": False}, session)
        loads = []
        for _ in range(3):  # a load's seconds not counting the time Chromium's processes (or this test)
            browser.events.clear()  # were runnable but waiting for a CPU (tests/cpu_wait.py): the
            with CpuWait(browser.proc.pid) as waits:  # wall time on a quiet machine, whatever the load
                start = time.monotonic()
                browser.navigate(session, report.resolve().as_uri())
                end = time.monotonic()
            loads.append(waits.unloaded(start, end))
        events = list(browser.events)
        info = _evaluate(browser, session, PAGE_JS)
        shots = {}
        top = {"x": 0, "y": 0, "width": 1280, "height": 900}
        for name, clip in (("top", top), ("contents", info["nav"])):
            shot = browser.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True,
                                                           "clip": {**clip, "scale": 1}}, session)
            shots[name] = tmp / f"{name}.png"
            shots[name].write_bytes(base64.b64decode(shot["data"]))
        browser.send("Emulation.setDeviceMetricsOverride",   # a phone held upright
                     {"width": NARROW_PX, "height": 900, "deviceScaleFactor": 1, "mobile": False}, session)
        narrow = _evaluate(browser, session, NARROW_JS)
        browser.send("Emulation.setEmulatedMedia", {"media": "print"}, session)
        browser.send("Emulation.setScrollbarsHidden", {"hidden": True}, session)
        browser.send("Emulation.setDeviceMetricsOverride",
                     {"width": A4_TEXT_WIDTH_PX, "height": 1100, "deviceScaleFactor": 1, "mobile": False},
                     session)
        printed = _evaluate(browser, session, PRINT_JS)
    finally:
        browser.close()
    return {"info": info, "shots": shots, "loads": loads, "events": events, "print": printed,
            "narrow": narrow}


def test_report_has_contents_whose_links_land_and_numbered_figures_and_tables(page, demo_figures):
    from matplotlib import image as mpimg

    info = page["info"]
    assert info["missing"] == [] and len(info["links"]) >= 6 + 11      # sections and the 11 runs
    n = len(info["caps"])
    assert info["caps"] == [f"Figure {k}." for k in range(1, n + 1)] and n == 47 + 2   # 2 animated poses
    assert [t.split(".")[0] for t in info["tabs"]] == [f"Table {k}" for k in range(1, len(info["tabs"]) + 1)]
    # one collapsed block per run, and the verdict paragraph
    assert info["details"] == 11 + 1 and info["open"] == 0
    assert info["figures_in_details"] == 10 * 4 + 2     # FRF, diagram, synthesis, AutoMAC; FDD and SSI
    for name in ("top", "contents"):
        pixels = mpimg.imread(page["shots"][name])
        assert pixels.std() > 0.05, name                                # text on it, not a blank box
    assert info["height"] < 10000      # was ~30 000 px with every run open (the diagnosis of 10 runs: ~9100)


def test_report_names_inputs_relative_to_it_and_the_versions(page, demo_figures):
    report, _ = demo_figures
    text = page["info"]["text"]
    assert "Inputs: runs.h5, operational.h5, " in text and str(report.parent) not in text
    assert re.search(r"Versions: flexmodal \S+, Python 3\.\d+\.\d+, numpy \d", text)
    diagnosis_page = (report.parent / "diagnosis.html").read_text()
    named = re.search(r"Inputs: ([^<]*)\.</p>", diagnosis_page).group(1).split(", ")
    assert len(named) == 2 and named[1] == "modes.csv" and named[0].endswith(".toml")   # rig, modes
    # configurations in natural order wherever they are listed
    for listing in re.findall(r"configurations ([\w, ]+);", text):
        names = listing.split(", ")
        assert names == sorted(names, key=lambda c: int(re.sub(r"\D", "", c) or 0)), names


def test_report_opens_fast_with_no_network_request_and_no_error(page):
    events = page["events"]
    requests = [e["params"]["request"]["url"] for e in events
                if e.get("method") == "Network.requestWillBeSent"]
    assert requests and all(u.startswith(("file:", "data:")) for u in requests), requests
    errors = [e for e in events if e.get("method") == "Runtime.exceptionThrown"
              or (e.get("method") == "Log.entryAdded" and e["params"]["entry"]["level"] == "error")]
    assert errors == []
    assert min(page["loads"]) <= 2.0, page["loads"]                     # best of three loads [s]


def test_printed_report_has_no_table_wider_than_the_page(page):
    printed = page["print"]
    assert printed["width"] == A4_TEXT_WIDTH_PX and printed["page"] <= printed["width"]
    tables = printed["tables"]
    assert len(tables) >= 10
    wide = [t for t in tables if t["right"] > printed["width"] + 0.5 or t["left"] < -0.5
            or t["scroll"] > t["right"] - t["left"] + 1 or t["overflowing_cells"]]
    assert wide == []
    # header rows repeat on every printed page, no row is split across two
    assert printed["heads"] and set(printed["heads"]) == {"table-header-group"}
    assert set(printed["rows"]) == {"avoid"}


def test_on_a_narrow_screen_the_page_does_not_scroll_sideways(page):
    # at 400 px the wide tables (candidates, frequencies) scroll in their own box; the text, figures
    # and animations fit the width, so nothing is cut off at the right edge of a phone
    narrow = page["narrow"]
    assert NARROW_PX - 20 <= narrow["width"] <= NARROW_PX and narrow["page"] <= narrow["width"], narrow
    assert narrow["scrolling"] >= 1


def test_report_pdf_prints_every_page(demo_figures, tmp_path):
    from flexmodal import api

    report, _ = demo_figures
    pdf = api.report_pdf(report, tmp_path / "report.pdf")
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF-") and data.rstrip().endswith(b"%%EOF")
    pages = len(re.findall(rb"/Type\s*/Page\b", data))
    assert 15 <= pages <= 60, pages
    assert report.read_text().count("<details open") == 0                # the report itself is untouched


def test_report_pdf_without_chromium_is_one_line_and_exit_2(demo_figures, tmp_path, capsys, monkeypatch):
    from flexmodal.app import main
    from flexmodal.reports import pdf

    monkeypatch.setattr(pdf, "find_chromium", lambda: None)
    out = tmp_path / "r.html"
    assert main(["report", "--measured", str(demo_figures[0].parent / "modes.csv"), "--out", str(out),
                 "--pdf"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no Chromium found" in err and "Traceback" not in err
    assert not out.exists()


def test_frf_axes_take_the_channels_units(tmp_path, rigs_dir):
    """A session recorded in g: the same FRFs 9.81 times smaller than in m/s², labelled g/N."""
    from dataclasses import replace

    from flexmodal import api
    from flexmodal.daq.store import RunWriter, read_run
    from flexmodal.fixtures.rig_sim import simulate
    from flexmodal.modal.compute import compute_frf
    from flexmodal.modal.runs_io import write_frf
    from flexmodal.models.rig import load_rig

    test = simulate(load_rig(rigs_dir / "demo_arm.toml"), {"theta_deg": 30.0}, excitation="random",
                    duration_s=4.0, sample_rate_hz=1024.0, n_modes=3)
    acc = np.array([c.kind == "acceleration" for c in test.channels])
    channels = [replace(c, unit="g") if c.kind == "acceleration" else c for c in test.channels]
    runs = tmp_path / "g.h5"
    with RunWriter(runs, "in-g", sample_rate_hz=1024.0, channels=channels, excitation="random",
                   pose={"theta_deg": 30.0}) as w:
        w.append(np.where(acc, test.samples / 9.80665, test.samples))
    write_frf(runs, "in-g", compute_frf(read_run(runs, "in-g"), nfft=512))
    seen = []
    original = plots.figure_png
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plots, "figure_png", lambda fig, dpi=100: seen.append(fig) or original(fig, dpi))
        api.report(tmp_path / "r.html", runs=[runs])
    frf_fig = next(f for f in seen if f.axes[0].get_ylabel().startswith("|H|"))
    assert frf_fig.axes[0].get_ylabel() == "|H| [g/N]"
    assert problems(frf_fig) == []
