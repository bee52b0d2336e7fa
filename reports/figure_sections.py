"""The built-in figure sections of the validation report, entries of the section registry
(reports/sections.py) as a plug-in's are: ``modes`` (frequencies across poses, trends, the test-model MAC
and the mode shapes on the arm) and ``gap`` (the error per mode before and after the diagnosed effect).
Each draws matplotlib figures from what the report is given (:class:`~reports.sections.ReportInputs`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from flexmodal.compare.tables import ordered_configs, table_name
from flexmodal.reports import plots
from flexmodal.reports.html import pose_text, pose_unit, varying_pose_vars
from flexmodal.reports.sections import ReportInputs, Section

Figures = list[tuple[Any, str]]   # (matplotlib Figure or None for a note in its place, caption)


def mode_figures(inputs: ReportInputs) -> Figures:
    """Frequency against the first varying pose variable (experiment mean ± 1 standard deviation over
    the measured table and its repeats, a line per model and mode), trends over a second one, the
    test-model MAC and the measured shapes on the arm (``inputs.shapes``)."""
    measured, repeats, predictions = inputs.measured, inputs.repeats, inputs.predictions
    figs: Figures = []
    ref = measured if measured is not None else (predictions[0][1] if predictions else None)
    if ref is None:
        return figs
    varying = varying_pose_vars(ref)
    meas = ([measured] if measured is not None else []) + list(repeats)
    if varying:
        var = varying[0]
        figs.append((plots.plot_freq_vs_pose(meas, list(predictions), var, pose_unit(var)),
                     f"Natural frequency against {var}: a line per model and mode, "
                     f"{plots.experiment_words(meas, var)}" if meas else
                     f"Natural frequency against {var}: a line per model and mode"))
    if len(varying) >= 2:
        x = next((v for v in varying if "payload" in v), varying[1])
        group = next(v for v in varying if v != x)
        figs.append((plots.plot_trends(ref, x, group, pose_unit(x), pose_unit(group)),
                     f"Trends of each mode's frequency with {x}, a line per {group} "
                     f"({table_name(ref, 'modes')})"))
    figs += _test_model_mac(measured, predictions)
    for config, arm in (inputs.shapes or {}).items() if measured is not None else ():
        if isinstance(arm, str):   # the reason no shape is drawn for this configuration
            figs.append((None, arm))
            continue
        figs.append((plots.plot_mode_shapes(arm, measured, config),
                     f"Measured mode shapes at {config} ({pose_text(measured.pose(config))}) on the "
                     f"arm, with the frame FE model's best-matching mode (by MAC) as a curve; both drawn "
                     f"normal to each link, so at a bent joint the two links' curves need not meet"))
    return figs


def _test_model_mac(measured, predictions: Sequence[tuple[str, Any]]) -> Figures:
    """MAC matrix of the measured shapes against the first prediction's at the sensors both give, for
    the first configuration both hold (two or more shared sensors)."""
    if measured is None or not predictions:
        return []
    name, pred = predictions[0]
    sensors = [s for s in measured.sensors if s in pred.sensors]
    configs = [c for c in ordered_configs(measured) if c in pred.configs]
    if len(sensors) < 2 or not configs:
        return []
    c = configs[0]
    a, b = measured.shapes(c, sensors), pred.shapes(c, sensors)
    fig = plots.plot_mac(a, b, [f"{x:.4g} Hz" for x in measured.freq_hz(c)],
                         [f"{x:.4g} Hz" for x in pred.freq_hz(c)], "measured mode", f"{name} mode",
                         title=f"{c}: test-model MAC")
    return [(fig, f"{c}: MAC of the measured shapes against {name}'s at the {len(sensors)} sensors both "
                  "give (values near 1 pair a measured mode with a predicted one)")]


def gap_figures(inputs: ReportInputs) -> Figures:
    """The relative frequency error per mode of the nominal model and with the diagnosed effect, as bars
    and then, when the measured table gives the configurations a varying pose, against that pose."""
    if inputs.diagnosis is None:
        return []
    return [(plots.plot_gap(inputs.diagnosis),
             "Left: each mode's relative frequency error, RMS over configurations, of the nominal model "
             "and with the diagnosed effect, both over the configurations the effect is judged on (held "
             "out, or all of them: the legend says which); right: the held-out RMS error over all modes, "
             "before and after"), *_gap_vs_pose(inputs)]


def _gap_vs_pose(inputs: ReportInputs) -> Figures:
    """The error of each mode against the measured table's first varying pose variable (none without
    one): the figure a reviewer reads instead of the natural-frequency table."""
    measured, d = inputs.measured, inputs.diagnosis
    varying = varying_pose_vars(measured) if measured is not None else []
    if not varying:
        return []
    var = varying[0]
    pose = {c: measured.pose(c)[var] for c in measured.configs if var in measured.pose(c)}
    fig = plots.plot_gap_vs_pose(d, pose, f"{var} [{pose_unit(var)}]")
    if fig is None:
        return []
    return [(fig, f"Each mode's relative frequency error f_model / f_measured − 1 against {var}, per "
                  f"configuration: the nominal model and with the diagnosed effect ({d.verdict.effect}; "
                  "held out or fitted to all, as the legend says); points on the zero line are explained, "
                  "what is left off it is the gap the effect does not account for")]


MODES = Section("Modes across poses", mode_figures, anchor="modes",
                needs="modes at poses that vary (--measured, --pred) or shapes (--pred, --rig)")
GAP = Section("Gap before and after the diagnosed effect", gap_figures, anchor="gap",
              needs="a diagnosis (--diagnosis)")
