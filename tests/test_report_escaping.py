"""Every name a user writes reaches the HTML report as text, never as markup: configuration names (tables,
figure captions, the animated shape cells and their aria-labels), a model's source name, the title.

The check is independent of how the report escapes: the same report is written twice, once with plain
names and once with hostile ones (``<script>``, ``<img onerror>``, quotes, ``&``, accents); parsed
(html.parser), both pages must hold the same elements and attributes in the same numbers, and the hostile
page's text must hold each hostile name as written.

The two slow tests draw every figure (7 s and 23 s); the default one renders the same page layer with
the figures replaced by a stand-in image (their captions, the animated SVG shapes and every table are the
real ones), and adds the names a report shows besides: a stored run's id and its channels' names, units
and locations, a pose variable, the configurations of a diagnosis and the rig file's name.
"""

from __future__ import annotations

import collections
import json
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flexmodal import api
from flexmodal.checked_io.text import name_fault
from flexmodal.contract.table import ModalTable
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig

POSES = (0.0, 60.0)
REPO = Path(__file__).resolve().parents[1]
HOSTILE = ("<script>alert(1)</script>\"'&é", "<img src=x onerror=alert(2)>")


class _Page(HTMLParser):
    """Elements and attribute names of a page (counted), and its text."""

    def __init__(self, page: str) -> None:
        super().__init__(convert_charrefs=True)
        self.markup: collections.Counter = collections.Counter()
        self.text: list[str] = []
        self.feed(page)

    def handle_starttag(self, tag, attrs) -> None:
        self.markup[tag] += 1
        self.markup.update(f"{tag}[{name}]" for name, _ in attrs)
        self.text += [value for name, value in attrs if name in ("alt", "aria-label") and value]

    def handle_data(self, data) -> None:
        self.text.append(data)


def _report(tmp: Path, rig, names: tuple[str, str], source: str, title: str) -> _Page:
    measured, predicted = [], []
    for name, theta in zip(names, POSES, strict=True):
        fe = frame_modes(rig, {"theta_deg": theta}, 3)
        for k, f in enumerate(fe.freq_hz):
            shape = {f"shape.{s}": float(fe.sensor_shapes[i, k]) for i, s in enumerate(fe.sensor_names)}
            row = {"config": name, "mode": k + 1, "pose.theta_deg": theta, **shape}
            measured.append({**row, "freq_hz": 0.9 * float(f), "damping_ratio": 0.01})
            predicted.append({**row, "freq_hz": float(f), "source": source})
    out = tmp / "report.html"
    api.report(out, measured=ModalTable.from_frame(pd.DataFrame(measured), "modes.csv"),
               predictions=[ModalTable.from_frame(pd.DataFrame(predicted), "fe.csv")], rig=rig, title=title,
               shapes_at=list(names))
    return _Page(out.read_text(encoding="utf-8"))


def _same_markup(tmp: Path, rig, names: tuple[str, str], source: str, title: str) -> None:
    plain = _report(tmp, rig, ("theta0", "theta60"), "fe", "report")
    hostile = _report(tmp, rig, names, source, title)
    assert hostile.markup == plain.markup
    text = "".join(hostile.text)
    for name in (*names, source, title):
        assert name.strip() in text


@pytest.fixture(scope="module")
def rig(rigs_dir):
    return load_rig(rigs_dir / "demo_arm.toml")


@pytest.mark.slow   # 2 reports with shape figures and animations: 7 s
def test_hostile_names_reach_the_report_as_text(rig, tmp_path) -> None:
    _same_markup(tmp_path, rig, HOSTILE, "fe<b>x</b>&\"", "<svg onload=alert(3)>")


NAMES = st.text(st.sampled_from("<>&\"'/=é ⟨a1 script"), min_size=1, max_size=12).filter(
    lambda s: name_fault(s) is None and s.strip() == s)


@pytest.mark.slow   # 4 reports of ~2 s each
@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(first=NAMES, second=NAMES, source=NAMES, title=NAMES)
def test_any_names_reach_the_report_as_text(rig, tmp_path, first, second, source, title) -> None:
    if first == second:
        second += "2"
    _same_markup(tmp_path, rig, (first, second), source, title)


def _renamed(doc: object, names: dict[str, str]) -> object:
    """``doc`` (parsed JSON) with every key and string value equal to a key of ``names`` renamed."""
    if isinstance(doc, dict):
        return {names.get(k, k): _renamed(v, names) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_renamed(v, names) for v in doc]
    return names.get(doc, doc) if isinstance(doc, str) else doc


def _page_layer(tmp: Path, rigs_dir: Path, names: tuple[str, str], extra: dict[str, str],
                monkeypatch) -> _Page:
    """api.report on a stored run (no FRF: nothing identified), measured and predicted tables with two
    varying pose variables, the demo's diagnosis and the demo rig (FE shapes animated), every matplotlib
    figure replaced by a stand-in (its caption is built as always)."""
    from flexmodal.daq.store import Channel, RunWriter
    from flexmodal.reports import plots

    for name in [n for n in dir(plots) if n.startswith("plot_")]:
        monkeypatch.setattr(plots, name, lambda *args, **kwargs: object())
    monkeypatch.setattr(plots, "figure_png", lambda fig: b"\x89PNG stand-in")
    tmp.mkdir()
    rig_path = tmp / f"{extra['rig']}.toml"
    rig_path.write_text((rigs_dir / "demo_arm.toml").read_text(encoding="utf-8"), encoding="utf-8")
    chans = [Channel("F", "force", "N"),
             Channel(extra["channel"], "acceleration", extra["unit"], location=extra["location"])]
    with RunWriter(tmp / "runs.h5", extra["run"], sample_rate_hz=512.0, channels=chans, excitation="impact",
                   pose={extra["payload"]: 0.5}) as w:
        w.append(np.linspace(-1.0, 1.0, 64)[:, None] * np.array([1.0, 2.0]))
    sensors = ("a1", "a2", "a3", "a4", "a5")
    measured, predicted = [], []
    for k, (name, theta) in enumerate(zip(names, POSES, strict=True)):
        for m in range(3):
            shape = {f"shape.{s}": float(np.sin((m + 1) * (i + 1) * np.pi / 6))
                     for i, s in enumerate(sensors)}
            row = {"config": name, "mode": m + 1, "pose.theta_deg": theta,
                   f"pose.{extra['payload']}": 0.5 * k, **shape}
            measured.append({**row, "freq_hz": 30.0 * (m + 1) ** 2, "damping_ratio": 0.01})
            predicted.append({**row, "freq_hz": 33.0 * (m + 1) ** 2, "source": extra["source"]})
    rename = dict(zip(("theta0", "theta60"), names, strict=True))
    demo = (REPO / "tests" / "data" / "diagnosis" / "demo.json").read_text(encoding="utf-8")
    diagnosis = _renamed(json.loads(demo), rename)
    out = tmp / "report.html"
    api.report(out, runs=[tmp / "runs.h5"], measured=ModalTable.from_records(measured, str(tmp / "m.csv")),
               predictions=[ModalTable.from_records(predicted, str(tmp / "fe.csv"))], rig=rig_path,
               diagnosis=diagnosis, title=extra["title"], shapes_at=list(names))
    return _Page(out.read_text(encoding="utf-8"))


PLAIN = {"title": "report", "source": "fe", "rig": "arm", "run": "r1", "channel": "a9", "unit": "m/s^2",
         "location": "tip", "payload": "payload_kg"}
NASTY = {"title": "<svg onload=alert(3)>", "source": "fe<b>x</b>&\"", "rig": "<i>arm&é",
         "run": "<b onmouseover='x'>r1&amp;", "channel": "<img src=y onerror=z>", "unit": "<s>m</s>",
         "location": "<a href=x>tip", "payload": "pay<u>load\"&_kg"}


def test_hostile_names_reach_the_page_layer_as_text(tmp_path, rigs_dir, monkeypatch) -> None:
    """Every place a name reaches the page, without drawing a figure: same markup, names as written."""
    plain = _page_layer(tmp_path / "plain", rigs_dir, ("theta0", "theta60"), PLAIN, monkeypatch)
    hostile = _page_layer(tmp_path / "hostile", rigs_dir, HOSTILE, NASTY, monkeypatch)
    assert hostile.markup == plain.markup
    assert plain.markup["img"] >= 4 and plain.markup["svg"] >= 2     # figures and animated shapes were there
    text = "".join(hostile.text)
    for name in (*HOSTILE, *NASTY.values()):
        assert name in text, name
