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


MATHTEXT_CHECK = """\
fig.canvas.draw()
math_px = ax.yaxis.label.get_window_extent().height      # rotated label: its length is the height
ax.set_ylabel("zeta [%]")
fig.canvas.draw()
print(f"mathtext {math_px:.1f} px, plain {ax.yaxis.label.get_window_extent().height:.1f} px")"""


def _tagged(nb, tag: str) -> list:
    return [c for c in nb.cells if c.cell_type == "code" and tag in c.metadata.get("tags", [])]


@pytest.fixture(scope="module")
def executed(tmp_path_factory):
    import nbformat
    from nbconvert.preprocessors import ExecutePreprocessor

    nb = nbformat.read(NOTEBOOK, as_version=4)
    # the user figure's check runs in the same kernel right after it, in a cell only this test adds (a
    # reader of the notebook sees the figure, not the measurement)
    at = nb.cells.index(_tagged(nb, "user-figure")[0]) + 1
    nb.cells.insert(at, nbformat.v4.new_code_cell(MATHTEXT_CHECK, metadata={"tags": ["check"]}))
    where = tmp_path_factory.mktemp("notebook")
    # nbclient's other waits are wall-clock too: 60 s for the kernel to start, and only 4 s after a cell's
    # reply for its outputs, after which the outputs still on their way are dropped with a warning (a
    # figure missing under load); here generous, and a late output is an error, never a silent loss
    ExecutePreprocessor(timeout=900, startup_timeout=600, iopub_timeout=600, raise_on_iopub_timeout=True,
                        kernel_name="python3").preprocess(nb, {"metadata": {"path": str(where)}})
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
    (check,) = _tagged(executed, "check")
    assert not [o for o in cell.outputs if o.output_type == "stream"]   # nothing printed for the reader
    text = "".join(o.text for o in check.outputs if o.output_type == "stream")
    math_px, plain_px = map(float, re.search(r"mathtext ([\d.]+) px, plain ([\d.]+) px", text).groups())
    assert math_px < 0.8 * plain_px          # "$\zeta$" drawn as one glyph, not as seven characters
    assert any("image/png" in o.get("data", {}) for o in cell.outputs)


# -- the notebook-friendly objects, without a kernel ------------------------------------------------

def _two_mode_frf():
    """FRFs of two outputs of a known two-mode system (accelerance, one input), 0..100 Hz."""
    import numpy as np

    f = np.linspace(0.0, 100.0, 801)
    s = 2j * np.pi * f
    modes = [(23.0, 0.012, np.array([1.0, 0.6])), (61.0, 0.02, np.array([-0.5, 1.0]))]
    H = sum(np.outer(phi, [phi[0]])[:, :, None] / (s**2 + 4 * np.pi * z * fn * s + (2 * np.pi * fn) ** 2)
            for fn, z, phi in modes) * s**2
    return f, H, modes


def test_frf_from_arrays_takes_keywords_and_feeds_identify():
    import numpy as np

    import flexmodal as fm

    f, H, modes = _two_mode_frf()
    frf = fm.frf_from_arrays(f, H, outputs=["tip", "mid"], inputs=["hammer"], quantity="accelerance")
    assert isinstance(frf, fm.FrfResult) and frf.H.shape == (2, 1, f.size) and frf.inputs == ("hammer",)
    table = fm.identify(frf, fmin=5.0, fmax=90.0).table
    np.testing.assert_allclose(table.freq_hz("run"), [m[0] for m in modes], rtol=1e-4)
    np.testing.assert_allclose(table.frame["damping_ratio"], [m[1] for m in modes], rtol=1e-3)
    fig = fm.plot_frf(frf)
    assert fig.axes[0].get_ylabel() == "|H| [(m/s²)/N]"
    with pytest.raises(ValueError, match="frf_from_arrays: H .* n_freq = 801"):
        fm.frf_from_arrays(f, H[..., :-1])
    with pytest.raises(ValueError, match="quantity 'velocity'"):
        fm.frf_from_arrays(f, H, quantity="velocity")
    with pytest.raises(ValueError, match="increasing"):
        fm.frf_from_arrays(f[::-1], H)


def test_reprs_are_short_and_frames_carry_the_numbers(tmp_path):
    import numpy as np
    import pandas as pd

    import flexmodal as fm

    f, H, _ = _two_mode_frf()
    ident = fm.identify(fm.frf_from_arrays(f, H, outputs=["tip", "mid"]), fmin=5.0, fmax=90.0)
    assert re.fullmatch(r"Identification\(1 configurations, 2 modes, \d+ warnings?; \.table, "
                        r"\.modes\[config\], \.warnings, \.warning_summary\(\)\)", repr(ident)), repr(ident)
    assert len(repr(ident.table)) < 200 and "2 modes, 23-61 Hz" in repr(ident.table)
    pd.testing.assert_frame_equal(ident.to_frame(), ident.table.frame)
    predicted = fm.read_table(_shifted(ident.table, tmp_path))
    comparison = fm.compare_modes(ident.table, predicted)
    frame = comparison.to_frame()
    csv = pd.read_csv(io.StringIO(fm.format_comparison(comparison, "csv")))
    np.testing.assert_allclose(frame.select_dtypes("number").to_numpy(float),
                               csv.select_dtypes("number").to_numpy(float), rtol=1e-12)
    assert "shifted Δf [%]" in frame.columns and np.allclose(frame["shifted Δf [%]"], 5.0)
    assert repr(comparison).startswith("Comparison(experiment: 1 configurations, 2 measured modes; shifted: "
                                       "2 paired, RMS Δf 5 %")
    assert "<table" in comparison._repr_html_()


def _shifted(table, folder):
    """The table with every frequency 5 % up, written as a CSV named 'shifted'."""
    frame = table.frame.assign(freq_hz=table.frame["freq_hz"] * 1.05, source="shifted")
    path = folder / "shifted.csv"
    frame.to_csv(path, index=False)
    return path


def test_diagnosis_frame_is_its_ranking():
    import json

    import flexmodal as fm

    diagnosis = fm.read_diagnosis(REPO / "tests" / "data" / "diagnosis" / _a_diagnosis())
    frame = diagnosis.to_frame()
    assert list(frame["effect"]) == [r.effect for r in diagnosis.ranking]
    expected = [100 * r.heldout_rms_rel_error for r in diagnosis.ranking]
    assert list(frame["heldout_rms_rel_error_pct"]) == expected
    assert len(repr(diagnosis)) < 300 and repr(diagnosis).startswith("Diagnosis(")
    assert "held-out RMS error [%]" in diagnosis._repr_html_() and json.loads(diagnosis.to_json())


def _a_diagnosis() -> str:
    return sorted(p.name for p in (REPO / "tests" / "data" / "diagnosis").glob("*.json"))[0]


def test_version_flag(capsys):
    import flexmodal
    from flexmodal.app import main

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out.strip() == f"flexmodal {flexmodal.__version__}"
