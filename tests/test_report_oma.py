"""OMA report figures (reports/oma.py) and their place in the HTML report of an operational run."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.daq.store import Channel, RunWriter
from flexmodal.fixtures.shear_frame import shear_frame_record
from flexmodal.modal.fdd import fdd
from flexmodal.modal.ssi import ssi_cov
from flexmodal.reports.html import write_report
from flexmodal.reports.oma import oma_figures, plot_fdd, plot_ssi_stabilisation

MASS = [3000.0, 2800.0, 2600.0, 2400.0, 2000.0]
STIFF = [9.6e7, 8.8e7, 8.0e7, 7.2e7, 6.4e7]


@pytest.fixture(scope="module")
def frame():
    return shear_frame_record(MASS, STIFF, 0.01, duration_s=120.0, seed=5)


def test_fdd_figure_draws_every_singular_value_and_marks_the_modes(frame):
    res = fdd(frame.samples, 256.0)
    fig = plot_fdd(res)
    ax = fig.axes[0]
    lines = [ln for ln in ax.get_lines() if ln.get_label().startswith("s")]
    assert len(lines) == 5
    assert np.allclose(lines[0].get_ydata(), res.singular_values[0, 1:])
    marked = sorted(ln.get_xdata()[0] for ln in ax.get_lines() if ln.get_linestyle() == "--")
    assert np.allclose(marked, res.modes.freq_hz)
    assert ax.get_xlabel() == "frequency [Hz]" and "(m/s²)²/Hz" in ax.get_ylabel()


def test_ssi_stabilisation_figure_draws_every_pole(frame):
    res = ssi_cov(frame.samples, 256.0, max_order=40)
    fig = plot_ssi_stabilisation(res, frame.samples, 256.0)
    pts = np.concatenate([ln.get_xdata() for ln in fig.axes[0].get_lines()])
    assert pts.size == res.stabilisation.freq_hz.size
    assert fig.axes[0].get_ylabel() == "model order [-]" and "FDD" in fig.axes[1].get_ylabel()


def test_report_of_an_operational_run_shows_fdd_and_ssi(tmp_path, frame):
    channels = [Channel(f"s{k + 1}", "acceleration", "m/s^2", location=f"floor{k + 1}") for k in range(5)]
    with RunWriter(tmp_path / "op.h5", "op", sample_rate_hz=256.0, channels=channels,
                   excitation="operational", pose={}) as w:
        w.append(frame.samples)
    html = write_report(tmp_path / "r.html", runs=[tmp_path / "op.h5"]).read_text()
    assert "FDD, singular values of the output cross-spectral matrix (s1, s2, s3, s4, s5)" in html
    assert "SSI-cov stabilisation diagram" in html and html.count("data:image/png;base64") >= 2


def test_a_record_without_modes_gives_captions_not_figures():
    rng = np.random.default_rng(0)
    y = rng.standard_normal((4096, 2))   # white noise: no peak, no stable pole
    figs = oma_figures(y, 256.0, ["a", "b"], ["acceleration"] * 2, "noise")
    assert [fig for fig, _ in figs] == [None, None]
    assert "no FDD" in figs[0][1] and "no SSI" in figs[1][1]
