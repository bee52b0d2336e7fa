"""docs/python-api.ipynb runs in a Jupyter kernel (nbconvert) and shows what it promises.

Its code cells hold every block of docs/python-api.md verbatim (the worked example), each figure cell
comes out as an inline image/png, each result cell (Identification, ModalTable, Comparison, Diagnosis)
as a short text repr and an HTML table with units, and a user's own pyplot figure with a ``$\\zeta$``
label drawn after flexmodal's renders the mathtext (the label is one glyph, narrower than ``zeta``).
"""

from __future__ import annotations

import base64
import io
import re

import pytest
from conftest import REPO

NOTEBOOK = REPO / "docs" / "python-api.ipynb"
DOC = REPO / "docs" / "python-api.md"


def _tagged(nb, tag: str) -> list:
    return [c for c in nb.cells if c.cell_type == "code" and tag in c.metadata.get("tags", [])]


@pytest.fixture(scope="module")
def executed(tmp_path_factory):
    import nbformat
    from nbconvert.preprocessors import ExecutePreprocessor

    nb = nbformat.read(NOTEBOOK, as_version=4)
    where = tmp_path_factory.mktemp("notebook")
    ExecutePreprocessor(timeout=900, kernel_name="python3").preprocess(nb, {"metadata": {"path": str(where)}})
    return nb


def test_notebook_holds_the_worked_example_of_the_python_api_doc():
    import nbformat

    nb = nbformat.read(NOTEBOOK, as_version=4)
    text = DOC.read_text(encoding="utf-8")
    blocks = [b.rstrip("\n") for b in re.findall(r"```python\n(.*?)```", text, re.S)]
    assert [c.source for c in _tagged(nb, "python-api.md")] == blocks
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")   # committed unexecuted


def test_every_figure_shows_inline_as_png(executed):
    from matplotlib import image as mpimg

    errors = [o for c in executed.cells if c.cell_type == "code" for o in c.outputs
              if o.output_type == "error"]
    assert errors == []
    figures = _tagged(executed, "figure")
    assert len(figures) == 6
    for cell in figures:
        pngs = [o.data["image/png"] for o in cell.outputs if "image/png" in o.get("data", {})]
        assert len(pngs) == 1, cell.source
        pixels = mpimg.imread(io.BytesIO(base64.b64decode(pngs[0])), format="png")
        assert pixels.shape[0] > 200 and pixels.std() > 0.05, cell.source


def test_results_display_as_short_reprs_and_tables_with_units(executed):
    shown = {c.source: c.outputs[0].data for c in _tagged(executed, "result")}
    assert set(shown) == {"ident", "measured", "comparison", "diagnosis"}
    for name, data in shown.items():
        assert len(data["text/plain"]) < 300, (name, data["text/plain"])
        assert "<table" in data["text/html"] and len(data["text/html"]) < 20_000, name
    assert data["text/plain"].startswith("Diagnosis(")
    assert "f [Hz]" in shown["measured"]["text/html"] and "ζ [%]" in shown["measured"]["text/html"]
    assert "fe Δf [%]" in shown["comparison"]["text/html"] and "MAC [-]" in shown["comparison"]["text/html"]
    assert "held-out RMS error [%]" in shown["diagnosis"]["text/html"]
    for cell in _tagged(executed, "frame"):
        assert "<table" in cell.outputs[0].data["text/html"]


def test_a_user_figure_after_flexmodals_renders_its_mathtext(executed):
    (cell,) = _tagged(executed, "user-figure")
    text = "".join(o.text for o in cell.outputs if o.output_type == "stream")
    math_px, plain_px = map(float, re.search(r"mathtext ([\d.]+) px, plain ([\d.]+) px", text).groups())
    assert math_px < 0.8 * plain_px          # "$\zeta$" drawn as one glyph, not as seven characters
    assert any("image/png" in o.get("data", {}) for o in cell.outputs)
