"""Report figures: the plotted data equal known values, and every axis carries a unit."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from figure_lint import problems
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from flexmodal.compare.result import Baseline, Diagnosis, Predictions, Verdict, Where
from flexmodal.contract.table import ModalTable
from flexmodal.models.arm_shapes import arm_modes
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig
from flexmodal.reports import plots


def has_unit(label: str) -> bool:
    return "[" in label and label.endswith("]")


def assert_units(fig):
    """Every visible axes has y and x labels with units (x: or shares its x axis with one that has),
    and the figure passes tests/figure_lint.py (plain ticks, on the canvas, readable log axes)."""
    for ax in fig.axes:
        if ax.get_visible():
            assert has_unit(ax.get_ylabel()), ax.get_ylabel()
            xlabels = [a.get_xlabel() for a in ax.get_shared_x_axes().get_siblings(ax)]
            assert any(has_unit(x) for x in xlabels), xlabels
    assert problems(fig) == []


def table(rows, source="t"):
    return ModalTable.from_records(rows, source)


def test_freq_vs_pose_error_bars_are_mean_and_sample_sd_of_repeats():
    repeats = [table([{"config": "a", "mode": 1, "freq_hz": f1, "pose.theta_deg": 0},
                      {"config": "b", "mode": 1, "freq_hz": f2, "pose.theta_deg": 90}])
               for f1, f2 in ((9.0, 20.0), (10.0, 22.0), (11.0, 24.0))]
    pred = table([{"config": "a", "mode": 1, "freq_hz": 10.5, "pose.theta_deg": 0},
                  {"config": "b", "mode": 1, "freq_hz": 21.0, "pose.theta_deg": 90}], "fe")
    fig = plots.plot_freq_vs_pose(repeats, [("fe", pred)], "theta_deg", "deg")
    ax = fig.axes[0]
    line = ax.get_lines()[0]
    np.testing.assert_array_equal(line.get_xdata(), [0, 90])
    np.testing.assert_array_equal(line.get_ydata(), [10.5, 21.0])
    container = ax.containers[0]
    x, y = container.lines[0].get_data()
    np.testing.assert_allclose(y, [10.0, 22.0])
    segments = container.lines[2][0].get_segments()
    np.testing.assert_allclose([s[:, 1] for s in segments], [[9.0, 11.0], [20.0, 24.0]], atol=1e-12)
    assert_units(fig)


def test_freq_vs_pose_uses_a_stored_standard_deviation(data_dir):
    import pandas as pd

    rep = pd.read_csv(data_dir / "seeds/seed003_table4_repeatability.csv")
    t = table([{"config": f"theta{r.theta_deg}", "mode": r.mode, "freq_hz": r.mean_hz, "freq_sd_hz": r.sd_hz,
                "pose.theta_deg": r.theta_deg} for r in rep.itertuples()])
    fig = plots.plot_freq_vs_pose([t], [], "theta_deg")
    segments = fig.axes[0].containers[0].lines[2][0].get_segments()
    half = sorted(round((s[1, 1] - s[0, 1]) / 2, 6) for s in segments)
    assert half == sorted(rep["sd_hz"].round(6))




def test_a_log_frequency_axis_of_about_one_decade_is_labelled_near_both_ends():
    # the demo's modes span 29-390 Hz: labels at 50, 100, 200 alone left modes 1 and 3 unreadable
    rows = [{"config": f"q{q}", "mode": m, "freq_hz": f * (1 + 0.001 * q), "pose.theta_deg": q}
            for q in (0, 60, 120) for m, f in ((1, 29.0), (2, 100.0), (3, 390.0))]
    fig = plots.plot_freq_vs_pose([table(rows)], [], "theta_deg")
    assert_units(fig)
    fig.canvas.draw()
    labels = [t.get_text() for t in fig.axes[0].yaxis.get_ticklabels() if t.get_text()]
    assert {"30", "50", "100", "200", "300"} <= set(labels)


def test_figure_lint_names_an_axis_without_a_unit_and_a_sparsely_labelled_log_axis():
    fig = Figure()
    ax = fig.subplots()
    ax.semilogy([0.0, 1.0], [20.0, 1000.0])
    ax.set_yticks([100.0], ["100"])
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("time")
    ax.set_ylabel("frequency [Hz]")
    found = problems(fig)
    assert len(found) == 2
    assert "x axis label 'time' names no [unit]" in found[0] and "labelled only at" in found[1]
    ax.set_xlabel("time [s]")
    plots.log_axis(ax.yaxis)
    assert problems(fig) == []


def test_payload_trends_plot_the_frame_model_and_fall_with_payload():
    rig = load_rig(Path(__file__).parent / "data" / "payload_arm.toml")
    rows = []
    for theta in (0.0, 90.0):
        for payload in (0.0, 0.5, 1.0, 2.0):
            pose = {"theta_deg": theta, "payload_kg": payload}
            fm = frame_modes(rig, pose, 3)
            rows += [{"config": f"t{theta:g}p{payload:g}", "mode": k + 1, "freq_hz": f,
                      "pose.theta_deg": theta, "pose.payload_kg": payload} for k, f in enumerate(fm.freq_hz)]
    t = table(rows, "fe")
    fig = plots.plot_trends(t, "payload_kg", "theta_deg", "kg", "deg")
    assert_units(fig)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == 3 and all(len(ax.get_lines()) == 2 for ax in axes)
    for k, ax in enumerate(axes):
        for line, theta in zip(ax.get_lines(), (0.0, 90.0), strict=True):
            df = t.frame[(t.frame["mode"] == k + 1) & (t.frame["pose.theta_deg"] == theta)]
            np.testing.assert_array_equal(line.get_xdata(), df["pose.payload_kg"])
            np.testing.assert_array_equal(line.get_ydata(), df["freq_hz"])
    first = axes[0].get_lines()[0].get_ydata()
    assert np.all(np.diff(first) < 0)  # mode 1 falls as the payload grows (seed 001's trend)


def _gap_diagnosis(best_heldout_hz: dict, best_fit_hz: dict) -> Diagnosis:
    measured = {"a": (10.0, 20.0, 30.0), "b": (10.0, 40.0, 30.0)}
    return Diagnosis(
        baseline=Baseline(rms_rel_error=0.3, max_rel_error=0.57, per_mode={"1": 0.09, "2": 0.57, "10": 0.2},
                          per_config={"a": 0.3, "b": 0.3}),
        where=Where(modes=(2,), configs=("a",), region="joint:elbow"), ranking=(),
        verdict=Verdict(effect="joint_stiffness", location="elbow", heldout_rms_rel_error_before=0.597,
                        heldout_rms_rel_error_after=0.051, explained=True),
        predictions=Predictions(measured_hz=measured, baseline_hz={"a": (11.0, 30.0, 33.0),
                                                                   "b": (10.0, 40.0, 36.0)},
                                best_fit_hz=best_fit_hz, best_heldout_hz=best_heldout_hz))


def test_gap_bars_are_the_diagnosis_errors_in_percent():
    """Like for like: the RMS over configurations, per mode, of the nominal model's and of the best
    candidate's held-out predictions against the measured frequencies, over the same configurations and
    modes (None, never held out, is left out of both; the nominal bars were over every configuration)."""
    d = _gap_diagnosis({"a": (11.0, 20.0, None), "b": (9.0, 44.0, None)},
                       {"a": (10.0, 20.0, 30.0), "b": (10.0, 40.0, 30.0)})
    modes, before, after = plots.gap_per_mode(d)
    assert modes == ["1", "2", "10"]
    np.testing.assert_allclose(before[:2], [np.sqrt(0.01 / 2), np.sqrt(0.25 / 2)], rtol=1e-12)
    np.testing.assert_allclose(after[:2], [0.1, np.sqrt(0.01 / 2)], rtol=1e-12)
    assert np.isnan(after[2]) and np.isnan(before[2])         # no mode 10 in the predictions
    fig = plots.plot_gap(d)
    heights = [p.get_height() for p in fig.axes[0].patches]
    np.testing.assert_allclose(heights[:2] + heights[3:5], [100 * np.sqrt(0.005), 100 * np.sqrt(0.125), 10.0,
                                                            100 * np.sqrt(0.005)], rtol=1e-12)
    np.testing.assert_allclose([p.get_height() for p in fig.axes[1].patches], [59.7, 5.1])
    assert fig.axes[0].get_ylabel().endswith("[%]") and fig.axes[1].get_ylabel().endswith("[%]")
    assert [t.get_text() for t in fig.legends[0].get_texts()] == [
        "nominal model (on the held-out configurations)", "with joint_stiffness (held out)"]
    # nothing held out: the fit to all configurations, and the nominal model on all of them
    fit = _gap_diagnosis({"a": (None,) * 3, "b": (None,) * 3},
                         {"a": (11.0, 22.0, 30.0), "b": (9.0, 44.0, 30.0)})
    np.testing.assert_allclose(plots.gap_per_mode(fit)[2][:2], [0.1, 0.1], rtol=1e-12)
    np.testing.assert_allclose(plots.gap_per_mode(fit)[1][:2], [np.sqrt(0.005), np.sqrt(0.125)], rtol=1e-12)
    assert fig.legends[0].get_texts()[0].get_text().startswith("nominal model")
    legend = plots.plot_gap(fit).legends[0]
    assert legend.get_texts()[0].get_text() == "nominal model (on every configuration)"
    # no best candidate (a "none" verdict): the nominal model's bars only, over every configuration
    none = replace(d, predictions=replace(d.predictions, best_fit_hz=None, best_heldout_hz=None))
    assert plots.gap_per_mode(none)[2] is None
    np.testing.assert_array_equal(plots.gap_per_mode(none)[1], [0.09, 0.57, 0.2])
    assert len(plots.plot_gap(none).axes[0].patches) == 3


def test_mode_shapes_measured_points_sit_on_the_model_curve(rigs_dir):
    rig = load_rig(rigs_dir / "demo_arm.toml")
    pose = {"theta_deg": 60.0}
    fm = frame_modes(rig, pose, 3)
    rows = [{"config": "c", "mode": k + 1, "freq_hz": fm.freq_hz[k], "pose.theta_deg": 60.0,
             **{f"shape.{s}": -2.5 * fm.sensor_shapes[i, k] for i, s in enumerate(fm.sensor_names)}}
            for k in range(3)]
    arm = arm_modes(rig, pose, fm.sensor_names)
    np.testing.assert_allclose(arm.sensor_disp[:, :3], fm.sensor_shapes, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(arm.freq_hz[:3], fm.freq_hz, rtol=1e-9)
    fig = plots.plot_mode_shapes(arm, table(rows), "c")
    assert_units(fig)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == 3
    for ax in axes:
        assert "MAC 1.00" in ax.get_title()
        undeformed, link1, link2, points = ax.get_lines()
        measured = points.get_xydata()
        # sensors a1 (link1@0.5), a2 (link1@1.0), a5 (link2@1.0) are nodes of the 25-point link curves
        for sensor, curve, index in ((0, link1, 12), (1, link1, 24), (4, link2, 24)):
            np.testing.assert_allclose(measured[sensor], curve.get_xydata()[index], atol=1e-12)
        model = np.concatenate([link1.get_xydata(), link2.get_xydata()])
        assert np.abs(model - undeformed.get_xydata()).max() > 0.05  # visibly deformed


def test_frf_plot_shows_magnitude_and_phase_of_h():
    f = np.linspace(1.0, 100.0, 50)
    H = (1.0 / (40.0**2 - f**2 + 2j * 0.02 * 40.0 * f))[None, None, :] * np.array([[[1.0]], [[-2.0]]])
    coh = np.full((2, 50), 0.9)
    fig = plots.plot_frf(f, H, coh, ["a", "b"], "m/N")
    mag, phase, coh_ax = fig.axes
    np.testing.assert_allclose(mag.get_lines()[1].get_ydata(), np.abs(H[1, 0]))
    np.testing.assert_allclose(phase.get_lines()[0].get_ydata(), np.degrees(np.angle(H[0, 0])))
    np.testing.assert_array_equal(coh_ax.get_lines()[0].get_ydata(), coh[0])
    assert mag.get_ylabel() == "|H| [m/N]"
    assert_units(fig)


def _identified():
    from flexmodal.fixtures.modal_sim import modal_frf
    from flexmodal.modal.identify import identify

    f = np.arange(1.0, 100.0, 0.05)
    H = modal_frf(f, [20.0, 45.0, 70.0], [0.01, 0.02, 0.01], [[1.0, 0.6, 0.3], [0.5, -0.8, 0.9],
                                                            [0.2, 0.4, -1.0]], [[1.0, 0.6, 0.3]])
    return f, H, identify(f, H, fmin=5.0, fmax=90.0)


def test_stabilisation_plot_marks_the_selected_poles_and_the_band():
    f, H, modes = _identified()
    fig = plots.plot_stabilisation(f, H, modes.stabilisation, selected=modes.selected,
                                   band_hz=(5.0, 90.0), modes_hz=modes.freq_hz)
    ax = fig.axes[0]
    crosses = next(line for line in ax.get_lines() if line.get_label() == "pole of a selected mode")
    st = modes.stabilisation
    np.testing.assert_array_equal(crosses.get_xdata(), st.freq_hz[modes.selected])
    np.testing.assert_array_equal(crosses.get_ydata(), st.order[modes.selected])
    near = np.min(np.abs(crosses.get_xdata()[:, None] - np.array([20.0, 45.0, 70.0])[None]), axis=1)
    assert np.all(near < 0.1)          # every selected pole belongs to one of the three modes
    span = ax.patches[0]
    assert np.isclose(span.get_x(), 5.0) and np.isclose(span.get_x() + span.get_width(), 90.0)
    dotted = [line.get_xdata()[0] for line in ax.get_lines() if line.get_linestyle() == ":"]
    assert dotted == list(modes.freq_hz)
    assert_units(fig)
    with pytest.raises(Exception, match="selected-pole mask differs"):
        plots.plot_stabilisation(f, H, st, selected=modes.selected[:-1])


def test_synthesis_plot_draws_measured_and_synthesised_frfs():
    f, H, modes = _identified()
    band = (f >= 5.0) & (f <= 90.0)
    fig = plots.plot_synthesis(f[band], H[..., band], modes.synthesis, ["a", "b", "c"],
                               modes.frf_synthesis_corr)
    lines = fig.axes[0].get_lines()
    np.testing.assert_allclose(lines[0].get_ydata(), np.abs(H[0, 0, band]))
    np.testing.assert_allclose(lines[1].get_ydata(), np.abs(modes.synthesis[0, 0]))
    assert "FRAC 1.000" in lines[0].get_label()
    assert_units(fig)
    with pytest.raises(Exception, match="synthesis: FRFs"):
        plots.plot_synthesis(f, H, modes.synthesis)


def test_mac_plot_writes_the_mac_values():
    phi = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    fig = plots.plot_mac(phi)
    values = [float(t.get_text()) for t in fig.axes[0].texts]
    assert values == [1.0, 0.25, 0.25, 1.0]   # |phi1 . phi2|^2 / (2 * 2)
    image = fig.axes[0].get_images()[0].get_array()
    np.testing.assert_allclose(image, [[1.0, 0.25], [0.25, 1.0]])
    with pytest.raises(Exception, match="cannot be compared"):
        plots.plot_mac(phi, phi[:2])


def test_gap_against_pose_plots_each_configurations_error_per_mode():
    """f_model / f_measured - 1 [%] per configuration at its pose: the nominal model's (baseline_hz) and
    the held-out predictions' (None: no point), one panel per mode; None without poses."""
    d = _gap_diagnosis({"a": (11.0, 20.0, None), "b": (9.0, 44.0, None)},
                       {"a": (10.0, 20.0, 30.0), "b": (10.0, 40.0, 30.0)})
    fig = plots.plot_gap_vs_pose(d, {"a": 0.0, "b": 60.0}, "theta_deg [deg]")
    panels = fig.axes
    assert [ax.get_title() for ax in panels] == ["mode 1", "mode 2", "mode 3"]
    nominal, held = panels[0].get_lines()[1:]          # after the zero line
    np.testing.assert_allclose(nominal.get_xydata(), [[0.0, 10.0], [60.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(held.get_xydata(), [[0.0, 10.0], [60.0, -10.0]], atol=1e-12)
    np.testing.assert_allclose(panels[2].get_lines()[1].get_xydata(), [[0.0, 10.0], [60.0, 20.0]], atol=1e-12)
    assert panels[2].get_lines()[2].get_xydata().size == 0   # mode 3 never held out
    assert panels[0].get_ylabel() == "relative frequency error [%]"
    assert panels[1].get_xlabel() == "theta_deg [deg]"
    assert plots.plot_gap_vs_pose(d, {}, "theta_deg [deg]") is None
