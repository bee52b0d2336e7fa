"""OMA report figures (reports/oma.py), drawn from the results ``modal.oma.output_only_results``
computes, and their place in the HTML report of an operational run (``api.report``)."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest
import scipy.signal

from flexmodal import api
from flexmodal.daq.store import Channel, RunWriter
from flexmodal.fixtures.shear_frame import shear_frame_record
from flexmodal.modal.fdd import cross_spectra, fdd
from flexmodal.modal.oma import output_only_results
from flexmodal.modal.ssi import ssi_cov
from flexmodal.reports.errors import ReportError
from flexmodal.reports.oma import oma_figures, plot_fdd, plot_ssi_stabilisation

MASS = [3000.0, 2800.0, 2600.0, 2400.0, 2000.0]
STIFF = [9.6e7, 8.8e7, 8.0e7, 7.2e7, 6.4e7]
NAMES = [f"s{k + 1}" for k in range(5)]
KINDS = ["acceleration"] * 5


@pytest.fixture(scope="module")
def frame():
    return shear_frame_record(MASS, STIFF, 0.01, duration_s=120.0, seed=5)


@pytest.fixture(scope="module")
def oma(frame):
    return output_only_results(frame.samples, 256.0, NAMES, KINDS, where="frame")


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


def test_ssi_stabilisation_figure_draws_every_pole_over_the_given_spectrum(frame):
    res = ssi_cov(frame.samples, 256.0, max_order=40)
    f, G = cross_spectra(frame.samples, 256.0, range(5), 1024)
    fig = plot_ssi_stabilisation(res, f[1:], G[1:])
    pts = np.concatenate([ln.get_xdata() for ln in fig.axes[0].get_lines()])
    assert pts.size == res.stabilisation.freq_hz.size
    first = fig.axes[1].get_lines()[0]
    assert np.allclose(first.get_ydata(), np.linalg.svd(G[1:], compute_uv=False)[:, 0])
    assert fig.axes[0].get_ylabel() == "model order [-]" and "FDD" in fig.axes[1].get_ylabel()


def test_output_only_results_find_the_frame_and_its_spectrum(frame, oma):
    assert oma.outputs == tuple(NAMES)
    for res in (oma.fdd, oma.ssi):   # every mode of the frame, within 1 % (closed-form eigenvalues)
        found = np.sort(res.modes.freq_hz)
        assert found.size == frame.freq_hz.size
        assert np.allclose(found, np.sort(frame.freq_hz), rtol=0.01)
    # the spectrum under the diagram: FDD's own (one Welch spectrum for both), scipy's Welch
    # cross-spectral densities, band up to 1.1 x top pole
    nfft = 4096   # the one nfft policy: 120 s at 256 Hz / 4 -> 7680 samples -> the power of two below
    f_fdd = oma.fdd.freq_hz
    assert f_fdd.size == nfft // 2 + 1
    assert np.array_equal(oma.spectrum, oma.fdd.spectrum[(f_fdd > 0) & (f_fdd <= oma.spectrum_hz[-1])])
    top = oma.ssi.stabilisation.freq_hz.max()
    assert oma.spectrum_hz[0] == pytest.approx(256.0 / nfft)
    last_line = min(np.floor(1.1 * top * nfft / 256.0), nfft // 2) * 256.0 / nfft   # Nyquist at most
    assert oma.spectrum_hz[-1] == pytest.approx(last_line)
    y = frame.samples.T   # G_jk = E[Y_j Y_k*] = csd(y_k, y_j)
    f, ref = scipy.signal.csd(y[None, :, :], y[:, None, :], fs=256.0, window="hann", nperseg=nfft,
                              noverlap=nfft // 2)
    band = (f > 0) & (f <= 1.1 * top)
    assert np.allclose(oma.spectrum, np.moveaxis(ref, -1, 0)[band], rtol=1e-9, atol=0)


def test_report_of_an_operational_run_shows_fdd_and_ssi(tmp_path, frame, oma):
    channels = [Channel(name, "acceleration", "m/s^2", location=f"floor{k + 1}")
                for k, name in enumerate(NAMES)]
    with RunWriter(tmp_path / "op.h5", "op", sample_rate_hz=256.0, channels=channels,
                   excitation="operational", pose={}) as w:
        w.append(frame.samples)
    html = api.report(tmp_path / "r.html", runs=[tmp_path / "op.h5"]).read_text()
    assert "FDD, singular values of the output cross-spectral matrix (s1, s2, s3, s4, s5)" in html
    assert "SSI-cov stabilisation diagram" in html and html.count("data:image/png;base64") >= 2
    listed = ", ".join(f"{f:.4g} Hz" for f in oma.ssi.modes.freq_hz)
    assert f"modes {listed} (unscaled shapes)" in html


def test_a_record_without_modes_gives_captions_not_figures():
    rng = np.random.default_rng(0)
    y = rng.standard_normal((4096, 2))   # white noise: no peak, no stable pole
    oma = output_only_results(y, 256.0, ["a", "b"], ["acceleration"] * 2, where="noise")
    assert isinstance(oma.fdd, str) and isinstance(oma.ssi, str) and oma.spectrum is None
    figs = oma_figures(oma, "noise")
    assert [fig for fig, _ in figs] == [None, None]
    assert "no FDD" in figs[0][1] and "no SSI" in figs[1][1]


def _operational_file(path, samples) -> None:
    channels = [Channel(name, "acceleration", "m/s^2", location=f"floor{k + 1}")
                for k, name in enumerate(NAMES)]
    with RunWriter(path, "op", sample_rate_hz=256.0, channels=channels, excitation="operational",
                   pose={}) as w:
        w.append(samples)


def test_report_identifies_output_only_runs_in_the_band_it_is_given(tmp_path, frame):
    """oma_fmin/oma_fmax reach both methods: the frame's three modes inside 15-49 Hz, no others."""
    _operational_file(tmp_path / "op.h5", frame.samples)
    html = api.report(tmp_path / "r.html", runs=[tmp_path / "op.h5"], oma_fmin=15.0,
                      oma_fmax=49.0).read_text()
    inside = frame.freq_hz[(frame.freq_hz > 15.0) & (frame.freq_hz < 49.0)]   # 23.2, 36.1, 46.1 Hz
    for caption in (r"SSI-cov stabilisation diagram, orders \d+-\d+ .*?; modes ([^(]*) \(unscaled",
                    r"FDD, singular values of the output cross-spectral matrix [^;]*; peaks ([^\"<]*)"):
        listed = [float(f) for f in re.findall(r"([\d.]+) Hz", re.search(caption, html).group(1))]
        assert np.allclose(listed, inside, rtol=0.01), (caption, listed)


@pytest.mark.parametrize("band,why", [((30.0, 20.0), "must be below"), ((-1.0, None), "positive number"),
                                      ((None, float("nan")), "positive number")])
def test_report_refuses_a_bad_output_only_band(tmp_path, band, why):
    _operational_file(tmp_path / "op.h5", np.zeros((16, 5)))
    with pytest.raises(ReportError, match=why):
        api.report(tmp_path / "r.html", runs=[tmp_path / "op.h5"], oma_fmin=band[0], oma_fmax=band[1])
    assert not (tmp_path / "r.html").exists()


def test_report_cli_passes_the_band_and_refuses_a_bad_one(tmp_path):
    _operational_file(tmp_path / "op.h5", np.zeros((16, 5)))
    done = subprocess.run([sys.executable, "-m", "flexmodal", "report", str(tmp_path / "op.h5"), "--oma-fmin",
                           "50", "--oma-fmax", "40", "--out", str(tmp_path / "r.html")], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "oma_fmin = 50 Hz must be below oma_fmax = 40 Hz" in done.stderr


def test_output_only_results_compute_one_welch_spectrum(frame, oma, monkeypatch):
    """FDD, the lowest peak that sizes SSI and the spectrum under SSI's diagram all come from one run of
    the Welch engine over the whole record (there were three: FDD twice and a display spectrum; FDD's
    sigma adds its own over each run of segments, modal/fdd.py); the modes are unchanged."""
    from flexmodal.modal import fdd as fdd_module

    calls = []
    real = fdd_module.welch_spectra

    def counted(*args, **kwargs):
        calls.append((args[0].shape[0], args[4]))
        return real(*args, **kwargs)

    monkeypatch.setattr(fdd_module, "welch_spectra", counted)
    again = output_only_results(frame.samples, 256.0, NAMES, KINDS, where="frame")
    assert [c for c in calls if c[0] == frame.samples.shape[0]] == [(frame.samples.shape[0], 4096)]
    assert np.array_equal(again.fdd.modes.freq_hz, oma.fdd.modes.freq_hz)
    assert np.array_equal(again.ssi.modes.freq_hz, oma.ssi.modes.freq_hz)


@pytest.mark.parametrize("peaks_hz", [None, [8.68, 23.2, 23.6, 36.0, 36.2, 36.4, 46.2, 52.5, 52.7, 127.5]],
                         ids=["sparse", "dense"])
def test_fdd_peak_labels_sit_above_the_plot_clear_of_each_other_the_title_and_legend(frame, peaks_hz):
    """Each mode's label is written above the axes (never over a peak), labels do not overlap each
    other however close the modes, the title sits above them and the legend beside the plot; and the
    figure passes the figure lint (every text on the canvas, units on the axes)."""
    import dataclasses

    from figure_lint import problems
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    res = fdd(frame.samples, 256.0)
    if peaks_hz is not None:
        res = dataclasses.replace(res, modes=dataclasses.replace(res.modes, freq_hz=np.array(peaks_hz)))
    fig = plot_fdd(res, title="frame")
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    ax = fig.axes[0]
    frame_box = ax.get_window_extent(renderer)
    boxes = sorted((Text.get_window_extent(t, renderer) for t in ax.texts), key=lambda b: b.x0)  # no leader
    assert [t.get_text() for t in sorted(ax.texts, key=lambda t: t.xyann[0])] == \
        [f"{f:.4g} Hz" for f in np.sort(res.modes.freq_hz)]
    assert all(b.y0 >= frame_box.y1 for b in boxes)                          # above the plot
    assert all(a.x1 <= b.x0 for a, b in zip(boxes, boxes[1:], strict=False))  # apart from each other
    assert ax.title.get_window_extent(renderer).y0 >= max(b.y1 for b in boxes)
    assert ax.get_legend().get_window_extent(renderer).x0 >= frame_box.x1
    assert problems(fig) == []


def test_ssi_caption_judges_shape_only_with_two_or_more_channels(frame, oma):
    """With one channel a MAC is always 1 (modal.lscf._flags leaves shape out): the caption says so."""
    one = output_only_results(frame.samples[:, :1], 256.0, NAMES[:1], KINDS[:1], where="floor 1")
    assert one.ssi.shapes.shape[0] == 1
    caption = oma_figures(one, "floor 1")[1][1]
    assert " %; one output: shape not judged), open grey dots" in caption
    assert "shape MAC" not in caption
    assert " %, shape MAC ≥ 0.98), open grey dots" in oma_figures(oma, "frame")[1][1]
