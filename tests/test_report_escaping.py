"""Every name a user writes reaches the HTML report as text, never as markup: configuration names (tables,
figure captions, the animated shape cells and their aria-labels), a model's source name, the title.

The check is independent of how the report escapes: the same report is written twice, once with plain
names and once with hostile ones (``<script>``, ``<img onerror>``, quotes, ``&``, accents); parsed
(html.parser), both pages must hold the same elements and attributes in the same numbers, and the hostile
page's text must hold each hostile name as written.
"""

from __future__ import annotations

import collections
from html.parser import HTMLParser
from pathlib import Path

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
