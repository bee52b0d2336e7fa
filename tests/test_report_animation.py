"""Animated mode shapes in the report (inline SVG + script) and as a GIF, checked in headless Chromium.

Two structures: the planar demo arm (rig geometry at each pose; its frame FE modes stand in for the
measured ones, at the rig's sensors) and a Universal File with test geometry, tests/data/uff/
massif_geometry.uff (six nodes and the trace line of pyuff's Testlab sample, local z pointing down,
FRFs synthesised from two known modes; make_massif_geometry.py).  In Chromium: the page fetches
nothing and logs no error, two frames of a shape differ, and every node moves along its shape vector,
which is checked against geometry the test knows (the arm's link normals; the known global-z shapes
of the UFF seen through the report's view).
"""

from __future__ import annotations

import base64
import io
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from browser import Browser, open_page
from conftest import REPO
from matplotlib import image as mpimg

import flexmodal as fm
from flexmodal.reports import animate

UFF = REPO / "tests" / "data" / "uff" / "massif_geometry.uff"
POSES = {"theta0": {"theta_deg": 0.0}, "theta60": {"theta_deg": 60.0}, "theta120": {"theta_deg": 120.0}}

SHAPES_JS = """(() => {
  const svgs = [...document.querySelectorAll('svg.fm-shape')];
  const nodes = () => svgs.map(s => [...s.querySelectorAll('.fm-node')].map(
      c => [parseFloat(c.getAttribute('cx')), parseFloat(c.getAttribute('cy'))]));
  const lines = () => svgs.map(s => [...s.querySelectorAll('.fm-moving')].map(l => l.getAttribute('points')));
  return {count: svgs.length, labels: svgs.map(s => s.getAttribute('aria-label')), nodes: nodes(),
          lines: lines(), boxes: svgs.map(s => { const r = s.getBoundingClientRect();
            return {x: r.left + scrollX, y: r.top + scrollY, width: r.width, height: r.height}; })};
})()"""


def _open(exe: str, page: Path, profile: Path) -> dict:
    """Load ``page``; sample the shapes as they run (until they moved, at most 120 s), then paused at phase 0,
    pi/2 and pi, with a screenshot of the first shape at phase 0 and pi/2."""
    import time

    browser = Browser(exe, profile)
    try:
        session = open_page(browser, page)

        def js(expression: str):
            return browser.send("Runtime.evaluate", {"returnByValue": True, "expression": expression},
                                session)["result"].get("value")

        running = [js(SHAPES_JS)]
        deadline = time.monotonic() + 120  # a starved browser draws its next frame late, never not at all
        while True:
            time.sleep(0.1)
            running[1:] = [js(SHAPES_JS)]
            if running[1]["lines"] != running[0]["lines"] or time.monotonic() > deadline:
                break
        js("flexmodalShapes.pause()")
        phases, shots = {}, {}
        for name, phase in (("0", 0.0), ("half", math.pi / 2), ("pi", math.pi)):
            js(f"flexmodalShapes.draw({phase})")
            phases[name] = js(SHAPES_JS)
            if name != "pi":
                shot = browser.send("Page.captureScreenshot", {
                    "format": "png", "captureBeyondViewport": True,
                    "clip": {**phases[name]["boxes"][0], "scale": 1}}, session)
                shots[name] = mpimg.imread(io.BytesIO(base64.b64decode(shot["data"])), format="png")
        data = js("[...document.querySelectorAll('svg.fm-shape')].map(s => JSON.parse(s.dataset.shape))")
    finally:
        browser.close()
    return {"running": running, "phases": phases, "shots": shots, "data": data, "events": browser.events}


def _clean(events: list[dict]) -> None:
    requests = [e["params"]["request"]["url"] for e in events
                if e.get("method") == "Network.requestWillBeSent"]
    assert requests and all(u.startswith(("file:", "data:")) for u in requests), requests
    errors = [e for e in events if e.get("method") == "Runtime.exceptionThrown"
              or (e.get("method") == "Runtime.consoleAPICalled"
                  and e["params"]["type"] in ("error", "assert"))
              or (e.get("method") == "Log.entryAdded" and e["params"]["entry"]["level"] == "error")]
    assert errors == []


@pytest.fixture(scope="module")
def arm_page(tmp_path_factory, chromium):
    tmp = tmp_path_factory.mktemp("arm_animation")
    rig = fm.load_rig(REPO / "examples" / "rigs" / "demo_arm.toml")
    measured = fm.predict(rig, POSES, "fe", n_modes=3, source="fe-as-measured")
    predicted = fm.predict(rig, POSES, "fe", n_modes=4)
    page = fm.report(tmp / "report.html", measured=measured, predictions=[predicted], rig=rig)
    return page, _open(chromium, page, tmp / "profile")


@pytest.fixture(scope="module")
def uff_page(tmp_path_factory, chromium):
    tmp = tmp_path_factory.mktemp("uff_animation")
    table = fm.identify(UFF, fmin=2.0, fmax=50.0).table
    page = fm.report(tmp / "report.html", measured=table, geometry=UFF)
    return page, table, _open(chromium, page, tmp / "profile")


def test_arm_report_animates_test_beside_model_for_each_pose(arm_page):
    page, seen = arm_page
    _clean(seen["events"])
    html = page.read_text()
    body = html.split("<body>")[1]
    assert "<script src" not in html and "http" not in body
    # first and last pose drawn; per pose 3 measured modes beside their FE modes, and FE mode 4 alone
    assert seen["phases"]["0"]["count"] == 2 * (3 * 2 + 1)
    labels = seen["phases"]["0"]["labels"]
    assert re.match(r"mode 1: [\d.]+ Hz \(MAC 1\.00 with FE mode 1\)", labels[0]), labels[0]
    assert re.match(r"FE mode 1: [\d.]+ Hz", labels[1]), labels[1]
    assert sum(label.startswith("FE mode 4") for label in labels) == 2


def test_arm_shapes_move_while_the_page_is_open_and_frames_differ(arm_page):
    _, seen = arm_page
    assert seen["running"][0]["lines"] != seen["running"][1]["lines"]          # the script runs
    a, b = seen["shots"]["0"], seen["shots"]["half"]
    assert a.shape == b.shape and np.abs(a - b).max() > 0.3                     # the pixels move
    assert np.abs(a - b).mean() > 1e-3


def test_arm_sensors_move_normal_to_their_link(arm_page):
    """theta0: both links along x, so every sensor moves vertically; theta120: the sensors beyond the
    elbow move at right angles to the elbow-tip line (the link drawn undeformed)."""
    _, seen = arm_page
    zero, pi = seen["phases"]["0"], seen["phases"]["pi"]
    tests = [k for k, label in enumerate(zero["labels"]) if not label.startswith("FE")]
    assert len(tests) == 6
    for n, k in enumerate(tests):
        move = np.array(zero["nodes"][k]) - np.array(pi["nodes"][k])            # 2 Re(d) per node [svg]
        rest = np.array(seen["data"][k]["p"])[1:]                                # sensors, base to tip
        assert np.abs(move).max() > 0
        if n < 3:                                                                # theta0
            np.testing.assert_allclose(move[:, 0], 0.0, atol=1e-6 * np.abs(move).max())
        else:                                                                    # theta120, link 2
            link = rest[-1] - rest[1]
            link /= np.linalg.norm(link)
            np.testing.assert_allclose(move[2:] @ link, 0.0, atol=1e-3 * np.abs(move).max())


def test_uff_geometry_modes_move_along_the_known_shapes(uff_page):
    sys.path.insert(0, str(UFF.parent))
    from make_massif_geometry import MODES_HZ, XYZ, global_z_shapes

    page, table, seen = uff_page
    _clean(seen["events"])
    np.testing.assert_allclose(table.freq_hz(table.configs[0]), MODES_HZ, rtol=1e-4)
    truth = global_z_shapes()
    zero, pi = seen["phases"]["0"], seen["phases"]["pi"]
    assert zero["count"] == 2
    rest = animate.view(XYZ) * [1, -1]                                            # svg y points down
    for k in range(2):
        move = np.array(zero["nodes"][k]) - np.array(pi["nodes"][k])
        np.testing.assert_allclose(np.array(seen["data"][k]["p"]), rest, atol=1e-5)
        expected = animate.view(np.outer(truth[:, k], [0.0, 0.0, 1.0])) * [1, -1]   # global z, viewed
        scale = (move * expected).sum() / (expected * expected).sum()
        np.testing.assert_allclose(move, scale * expected, atol=1e-3 * np.abs(move).max())
    a, b = seen["shots"]["0"], seen["shots"]["half"]
    assert np.abs(a - b).max() > 0.3


def test_uff_geometry_reads_coordinate_systems_and_trace_lines():
    from flexmodal.reports.geometry import read_uff_geometry

    g = read_uff_geometry(UFF)
    assert g.nodes == (1, 2, 3, 4, 5, 6) and g.lines == ((1, 4, 5, 2, 3, 0, 1, 2),)
    k, unit = g.direction("5+z")
    assert k == 4
    np.testing.assert_allclose(unit, [0, 0, -1], atol=1e-12)                    # local z points down
    np.testing.assert_allclose(g.direction("2-x")[1], [1, 0, 0], atol=1e-12)    # local x is global -x


def test_animated_gif_for_slides(tmp_path):
    from PIL import Image

    table = fm.identify(UFF, fmin=2.0, fmax=50.0).table
    gif = fm.animate_mode(tmp_path / "roll.gif", table, table.configs[0], 2, geometry=UFF, frames=12)
    with Image.open(gif) as im:
        assert im.format == "GIF" and im.n_frames == 12
        im.seek(0)
        first = np.asarray(im.convert("L"), float)
        im.seek(3)                                                                 # a quarter cycle on
        quarter = np.asarray(im.convert("L"), float)
    assert np.abs(first - quarter).max() > 100
    rig = fm.load_rig(REPO / "examples" / "rigs" / "demo_arm.toml")
    measured = fm.predict(rig, {"theta60": {"theta_deg": 60.0}}, "fe", n_modes=2)
    both = fm.animate_mode(tmp_path / "arm.gif", measured, "theta60", 2, rig=rig, frames=8)
    with Image.open(both) as im:
        assert im.n_frames == 8 and im.size[0] > 1.8 * im.size[1]                  # test beside model


def test_uff_geometry_from_double_precision_nodes_and_2420_systems(tmp_path):
    """Dataset 2411 nodes and a 2420 system rotated 90° about z (local x = global y) placed at
    (1, 0, 0): a node defined at local (1, 0, 0) sits at global (1, 1, 0) and measures local +x
    along global +y."""
    import pyuff

    from flexmodal.reports.geometry import read_uff_geometry

    rot = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    path = tmp_path / "g.uff"
    uff = pyuff.UFF(str(path))
    for s in (pyuff.prepare_2420(Part_UID=1, Part_Name="frame", CS_sys_labels=[7], CS_types=[0],
                                 CS_colors=[8], CS_names=["rotated"], CS_matrices=[rot]),
              pyuff.prepare_2411(node_nums=[10, 11], def_cs=[0, 7], disp_cs=[0, 7], color=[1, 1],
                                 x=[0.0, 1.0], y=[0.0, 0.0], z=[0.0, 0.0]),
              pyuff.prepare_82(trace_num=1, n_nodes=2, color=8, id="bar", nodes=np.array([10, 11]))):
        uff.write_sets(s, mode="add")
    g = read_uff_geometry(path)
    np.testing.assert_allclose(g.xyz, [[0, 0, 0], [1, 1, 0]], atol=1e-12)
    np.testing.assert_allclose(g.direction("11+x")[1], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(g.direction("10-y")[1], [0, -1, 0], atol=1e-12)
    assert g.lines == ((0, 1),)
    with pytest.raises(ValueError, match="no node 12"):
        g.direction("12+z")


def test_uff_geometry_reader_turns_any_broken_file_into_one_error(tmp_path):
    """Fuzz: a valid geometry file cut short, or with a field replaced by junk, gives a Geometry or a
    ReportError naming the file, never another exception."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    from flexmodal.reports.errors import ReportError
    from flexmodal.reports.geometry import read_uff_geometry

    good = UFF.read_text().split("    58")[0]              # the geometry part: datasets 18, 15, 82
    path = tmp_path / "fuzz.uff"

    @settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                 HealthCheck.too_slow])
    @given(cut=st.integers(0, len(good)), at=st.integers(0, len(good)),
           junk=st.text(alphabet="0123456789-+.eE xyz\n", max_size=12))
    def check(cut, at, junk):
        path.write_text(good[:at] + junk + good[at:cut] if at < cut else good[:cut])
        try:
            g = read_uff_geometry(path)
        except ReportError as exc:
            assert str(path) in str(exc) and "\n" not in str(exc)
        else:
            assert g.xyz.shape[1] == 3 and all(max(line) < len(g.nodes) for line in g.lines)

    check()
