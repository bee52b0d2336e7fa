"""Modal map: tracking modes across poses against exact two-DOF eigen-solutions (veering and crossing)."""

from __future__ import annotations

import doctest
import io

import numpy as np
import pytest
from figure_lint import problems
from scipy.linalg import eigh

from flexmodal.compare import modal_map as mm
from flexmodal.compare.errors import CompareError
from flexmodal.contract.table import ModalTable
from flexmodal.reports import modal_map_plot


def _two_dof(q: np.ndarray, coupling: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Exact modes of K(q) = [[1 + q, c], [c, 2 - q]] (unit masses) at each q: f [Hz], shapes [2, 2]."""
    freqs, shapes = [], []
    for x in q:
        lam, vec = eigh(np.array([[1.0 + x, coupling], [coupling, 2.0 - x]]))
        freqs.append(np.sqrt(lam) / (2 * np.pi))
        shapes.append(vec)
    return freqs, shapes


def test_doctests() -> None:
    for module in (mm, modal_map_plot):
        assert doctest.testmod(module).failed == 0


def test_veering_followed_by_shape() -> None:
    """Weak coupling, coarse pose steps: the frequencies veer (repel) and the shapes exchange; each
    branch keeps its shape character (DOF 1 dominant in branch 1 at every pose) and one order swap is
    reported where they pass."""
    q = np.linspace(0.0, 1.0, 6)
    freqs, shapes = _two_dof(q, 0.01)
    m = mm.track_modes(q, freqs, shapes)
    assert m.n_branches == 2
    order = np.argsort(m.freq_hz[0])
    first = order[0]                             # the branch that starts as the lower mode (DOF 1)
    for k, x in enumerate(q):
        f = np.sqrt(1.0 + x) / (2 * np.pi)       # DOF 1 alone; coupling moves it < 0.5 % off the veer
        assert m.freq_hz[k, first] == pytest.approx(f, rel=5e-3)
    assert [e[0] for e in m.events] == [3]       # between q = 0.4 and q = 0.6 (the veer at 0.5)
    assert np.all(m.mac_link[1:, first] > 0.99)


def test_strong_veering_with_fine_steps_keeps_frequency_order() -> None:
    """Strong coupling sampled finely: shapes rotate gradually, every link's MAC is high, the branches
    stay in frequency order (no swap), and frequencies equal the exact eigenvalues."""
    q = np.linspace(0.0, 1.0, 41)
    freqs, shapes = _two_dof(q, 0.2)
    m = mm.track_modes(q, freqs, shapes)
    assert m.n_branches == 2 and m.events == ()
    np.testing.assert_allclose(np.sort(m.freq_hz, axis=1), np.array(freqs), rtol=1e-12)
    assert np.nanmin(m.mac_link) > 0.9


def test_crossing_without_shapes_follows_the_trend() -> None:
    q = np.linspace(0.0, 1.0, 6)
    freqs, _ = _two_dof(q, 0.0)                  # uncoupled: a true crossing at q = 0.5
    m = mm.track_modes(q, [np.sort(f) for f in freqs])
    up = np.sqrt(1.0 + q) / (2 * np.pi)
    np.testing.assert_allclose(m.freq_hz[:, int(np.argmin(m.freq_hz[0]))], up, rtol=1e-12)
    assert len(m.events) == 1


def test_repeats_merge_to_mean_and_standard_error() -> None:
    q = [0.0, 0.0, 0.0, 1.0]
    f = [np.array([10.0, 30.0]), np.array([10.2, 30.3]), np.array([9.8, 29.7]), np.array([11.0, 31.0])]
    m = mm.track_modes(q, f, freq_std_hz=[np.ones(2)] * 4)
    assert m.n_repeats.tolist() == [3, 1]
    np.testing.assert_allclose(m.freq_hz[0], [10.0, 30.0])
    np.testing.assert_allclose(m.freq_std_hz[0], [np.std([10, 10.2, 9.8], ddof=1) / np.sqrt(3),
                                                  np.std([30, 30.3, 29.7], ddof=1) / np.sqrt(3)])
    np.testing.assert_allclose(m.freq_std_hz[1], [1.0, 1.0])      # single observation: the given std
    frame = m.to_frame()
    assert list(frame["mode_number"]) == [1, 2, 1, 2] and len(frame) == 4


def test_modal_map_from_table_and_errors() -> None:
    rec = [{"config": f"c{i}", "mode": k + 1, "freq_hz": f, "freq_std_hz": 0.01 * f, "pose.theta_deg": 30 * i}
           for i in range(4) for k, f in enumerate((10 + i, 20 - i))]
    m = mm.modal_map(ModalTable.from_records(rec, "<t>"))
    np.testing.assert_allclose(m.pose, [0, 30, 60, 90])
    np.testing.assert_allclose(m.freq_std_hz[:, 0], 0.01 * m.freq_hz[:, 0])
    with pytest.raises(CompareError, match="pose.phi_deg"):
        mm.modal_map(ModalTable.from_records(rec, "<t>"), "phi_deg")
    with pytest.raises(CompareError, match="2 frequency sets for 3"):
        mm.track_modes([0, 1, 2], [np.ones(1)] * 2)


def test_figure_draws_points_bars_and_band() -> None:
    q = np.linspace(0.0, 1.0, 6)
    freqs, shapes = _two_dof(q, 0.01)
    m = mm.track_modes(q, freqs, shapes, [0.01 * f for f in freqs])
    grid = np.linspace(0, 1, 11)
    f = np.array(_two_dof(grid, 0.01)[0])
    band = mm.PredictionBand(grid, f, 0.98 * f, 1.02 * f, "fitted model")
    fig = modal_map_plot.plot_modal_map(m, band, pose_label="q [-]")
    ax = fig.axes[0]
    assert len(ax.collections) >= 2 + 2                 # two bands + error-bar collections
    labels = [t.get_text() for t in fig.legends[0].get_texts()]   # below the axes, off the points
    assert "fitted model: 95 % prediction interval" in labels and "branch 1" in labels
    assert problems(fig) == []                                    # tests/figure_lint.py
    bare = modal_map_plot.plot_modal_map(m, mm.PredictionBand(grid, f, f, f, "fe"), pose_label="q [-]")
    names = [t.get_text() for t in bare.legends[0].get_texts()]
    assert "fe" in names and not any("prediction interval" in n for n in names)   # no band to show
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    assert buf.getvalue()[:4] == b"\x89PNG"
