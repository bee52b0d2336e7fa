"""The self-contained HTML validation report (jinja2 template ``templates/report.html``).

One file: images are embedded as base64 PNG, the style sheet and the few lines of script are inline and
nothing is fetched from a network.  A contents list links every section and each run's collapsed
(``<details>``) block; figures and tables are numbered; the inputs are named relative to the report; a
footer gives the versions of flexmodal and its key libraries; print CSS keeps tables whole with their
header repeated on each page (the script opens the collapsed blocks for printing).  Sections (each only
when its input is given): comparison table of measured vs predicted modes (a compare.tables.Comparison),
diagnosis summary (docs/formats.md, diagnosis JSON), frequency-vs-pose, trend and mode-shape plots, run
metadata, channel list, data quality (trigger/overload/gap/corrupt events, rejected hits, coherence)
with the FRF plot of each run and its identification (stabilisation diagram with the selected poles
and band, measured vs synthesised FRFs, AutoMAC), the test-model MAC matrix where predictions share
sensors with the measured modes, and the gap per mode before and after the diagnosed effect.

This module renders what it is given: the caller (``flexmodal.api.report``) reads the runs, computes
the comparison, each run's identification and the FE shapes on the arm.
"""

from __future__ import annotations

import base64
import numbers
import os
import platform
from collections.abc import Callable, Mapping, Sequence
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import jinja2
import pandas as pd

from flexmodal.checked_io.output import write_text
from flexmodal.checked_io.text import natural_key, read_text
from flexmodal.compare.errors import CompareError
from flexmodal.compare.result import Diagnosis, Predictions
from flexmodal.compare.tables import Comparison, html_fragment, ordered_configs
from flexmodal.compare.verdict_text import (
    SHEAR_UNCALIBRATED,
    advice_words,
    alternatives_words,
    remaining_words,
    scatter_line,
    verdict_words,
)
from flexmodal.contract.table import ModalTable, pose_unit
from flexmodal.reports import animate, plots
from flexmodal.reports.errors import ReportError
from flexmodal.reports.geometry import Geometry
from flexmodal.reports.runs import LOW_COHERENCE, RunSummary
from flexmodal.reports.sections import SECTIONS, ReportInputs
from flexmodal.reports.stabilisation_caption import stabilisation_caption

KEY_LIBRARIES = ("numpy", "scipy", "pandas", "matplotlib", "h5py", "jinja2", "pyuff")


def pose_text(pose: Mapping[str, object]) -> str:
    """A pose as ``theta_deg = 30 deg, payload_kg = 0.5 kg``."""
    return ", ".join(f"{k} = {v:.4g} {pose_unit(k)}" if isinstance(v, numbers.Real) else f"{k} = {v}"
                     for k, v in pose.items())


def _fig(fig, caption: str) -> dict:
    """A figure of the page: the PNG of ``fig`` (None: the caption alone, a note in its place)."""
    png = None if fig is None else base64.b64encode(plots.figure_png(fig)).decode("ascii")
    return {"png": png, "caption": caption}


def varying_pose_vars(table: ModalTable) -> list[str]:
    out = []
    for col in table.pose_columns:
        values = table.frame.groupby("config")[col].first()
        if values.nunique() > 1 and values.dtype.kind in "fi":
            out.append(col[len("pose."):])
    return out


def _animations(measured: ModalTable | None, predictions: Sequence[tuple[str, ModalTable]],
                shapes: Mapping[str, object], geometry: Geometry | None) -> list[dict]:
    """Animated shapes per configuration: on the arm (``shapes``: {config: ArmModes}) the measured
    modes beside the FE model's best-matching ones and the further predicted modes; on a test
    ``geometry`` (UFF) the measured modes of the first and last configuration."""
    if measured is None:
        return []
    out = []
    n_pred = {c: len(t.freq_hz(c)) for c in measured.configs for _, t in predictions[:1] if c in t.configs}
    for config, arm in shapes.items():
        if isinstance(arm, str):
            continue
        pairs = animate.arm_pairs(arm, measured, config, n_pred.get(config, len(measured.freq_hz(config))))
        out.append({"png": None, "rows": [_anim_row(t, m) for t, m in pairs],
                    "heads": ("test (measured at the sensors)", "frame FE model (along the links)"),
                    "caption": f"{config} ({pose_text(measured.pose(config))}): each measured mode "
                               "animated on the arm beside the FE mode it pairs with by MAC, then the "
                               "further predicted modes; displacements exaggerated, undeformed arm dashed"})
    if geometry is not None:
        configs = ordered_configs(measured)
        for config in dict.fromkeys([configs[0], configs[-1]]):
            moving = animate.geometry_shapes(geometry, measured, config)
            out.append({"png": None, "rows": [_anim_row(s, None) for s in moving],
                        "heads": (f"test (on {Path(geometry.source).name})", ""),
                        "caption": f"{config}: each measured mode animated on the test geometry "
                                   f"({len(geometry.nodes)} nodes, {len(geometry.lines)} trace lines; "
                                   "measured nodes marked); displacements exaggerated"})
    return out


def _anim_row(test: animate.Shape | None, model: animate.Shape | None) -> dict:
    return {"test": animate.svg(test) if test else "", "test_title": test.title if test else "",
            "model": animate.svg(model) if model else "", "model_title": model.title if model else ""}


def _run_order(runs: Sequence[RunSummary]) -> list[RunSummary]:
    """Runs grouped by file (in the order given), then by numeric pose values, then naturally by id."""
    files = list(dict.fromkeys(r.run.path for r in runs))

    def key(r: RunSummary) -> tuple:
        pose = tuple((k, float(v)) for k, v in sorted(r.run.pose.items()) if isinstance(v, int | float))
        return files.index(r.run.path), pose, natural_key(r.run.run_id)

    return sorted(runs, key=key)


def _start_time(text: str) -> str:
    """ISO 8601 start time shown to the second, in UTC when it carries an offset."""
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        return text
    if t.tzinfo is not None:
        return t.astimezone(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    return t.strftime("%Y-%m-%d %H:%M:%S")


def _run_rows(runs: Sequence[RunSummary]) -> tuple[list[dict], list[dict], list[dict]]:
    meta, quality, channel_sets = [], [], []
    sets: dict[tuple, dict] = {}
    for r in runs:
        label, run = r.label, r.run
        meta.append({"run": label, "start_time": _start_time(run.start_time),
                     "excitation": run.excitation, "pose": pose_text(run.pose),
                     "fs": f"{run.sample_rate_hz:g}", "duration": f"{r.duration_s:.2f}",
                     "n_samples": r.n_samples, "n_channels": len(run.channels)})
        counts = r.event_counts
        coh = r.coherence_stats()
        frf = r.frf
        quality.append({
            "run": label, "trigger": counts["trigger"], "rejected": r.rejected_hits,
            "hits": f"{len(r.hits) - r.rejected_hits} / {len(r.hits)}" if r.hits else "",
            "reasons": "; ".join(r.rejection_reasons),
            "overload": f"{counts['overload']} / {r.overload_samples}",
            "overload_bad": counts["overload"] > 0,
            "gap": counts["gap"], "corrupt": counts["corrupt"], "reconnect": counts["reconnect"],
            "frf": f"{frf.estimator}, nfft {frf.nfft}, {frf.n_averages} averages" if frf else "not computed",
            "coh_mean": f"{coh[0]:.3f}" if coh else "", "coh_low": f"{coh[1]:.1f}" if coh else ""})
        key = tuple(run.channels)
        if key not in sets:
            sets[key] = {"runs": [], "peaks": [], "channels": [
                {"name": c.name, "kind": c.kind, "unit": plots.unit_text(c.unit),
                 "sensitivity": _sensitivity_text(c.sensitivity, plots.unit_text(c.sensitivity_unit),
                                                  plots.unit_text(c.unit)),
                 "location": c.location, "direction": c.direction} for c in run.channels]}
            channel_sets.append(sets[key])
        sets[key]["runs"].append(label)
        sets[key]["peaks"].append(r.peak_abs)
    for cs in channel_sets:   # runs sharing their channels share one table: the largest peak (NaN-safe)
        for c, *peaks in zip(cs["channels"], *cs.pop("peaks"), strict=True):
            c["peak"] = f"{max((p for p in peaks if p == p), default=float('nan')):.4g} {c['unit']}"
    return meta, quality, channel_sets


def _identification_figures(r: RunSummary, unit: str) -> list[dict]:
    """The run's identification (``r.modes``, computed by the caller): its stabilisation diagram with
    the selected poles and the band, the measured vs synthesised FRFs, and the AutoMAC of the shapes
    (two or more outputs and modes)."""
    if r.modes is None:
        return []
    if isinstance(r.modes, str):
        return [{"png": None, "caption": f"{r.label}: no identification ({r.modes})"}]
    modes = r.modes
    try:
        diagram = plots.plot_identification_diagram(r.frf, modes, unit, title=r.label)
    except ReportError as exc:
        return [{"png": None, "caption": f"{r.label}: {exc}"}]
    f = modes.band_freq_hz
    figs = [_fig(diagram, stabilisation_caption(r.label, modes.freq_hz, (f.min(), f.max()), unit,
                                                len(r.frf.outputs), modes.order_note)),
            _fig(plots.plot_identification_synthesis(r.frf, modes, unit, title=f"{r.label}: synthesis"),
                 f"{r.label}: measured FRFs and the FRFs synthesised from the identified modes and "
                 "residuals (LSFD), with the FRAC of each pair")]
    if modes.freq_hz.size >= 2 and modes.shapes.shape[0] >= 2:
        names = [f"{x:.4g} Hz" for x in modes.freq_hz]
        figs.append(_fig(plots.plot_mac(modes.shapes, labels_a=names, title=f"{r.label}: AutoMAC"),
                         f"{r.label}: AutoMAC of the identified shapes at {modes.shapes.shape[0]} outputs "
                         "(off-diagonal terms near 1: modes the sensors cannot tell apart)"))
    return figs


def _oma_figures(r: RunSummary) -> list[dict]:
    """FDD and SSI figures of an output-only run (reports/oma.py); none for a run given without them."""
    from flexmodal.reports.oma import oma_figures

    if r.oma is None:
        return []
    return [_fig(fig, caption) if fig is not None else {"png": None, "caption": caption}
            for fig, caption in oma_figures(r.oma, r.label)]


def _run_figures(r: RunSummary) -> list[dict]:
    if r.frf is None:
        return _oma_figures(r)
    inputs = ", ".join(r.frf.inputs) or "force"
    unit = r.frf_unit
    return [_fig(plots.plot_frf(r.frf.freq_hz, r.frf.H, r.frf.coherence, r.frf.outputs, unit,
                                title=f"{r.label} ({r.run.excitation})"),
                 f"{r.label}: FRF magnitude, phase and coherence (input {inputs}, "
                 f"pose {pose_text(r.run.pose)})"), *_identification_figures(r, unit)]


def _run_sections(runs: Sequence[RunSummary], step: Callable[[str], None]) -> list[dict]:
    """One collapsible block per run: its anchor, a one-line summary and its figures; ``step`` is told
    each run before it is plotted (ten runs take 40 s)."""
    sections = []
    for k, r in enumerate(runs):
        step(f"plotting run {k + 1}/{len(runs)}: {r.label}")
        figs = _run_figures(r)
        drawn = sum(1 for f in figs if f["png"])
        sections.append({"id": f"run-{k + 1}", "label": r.label, "figures": figs,
                         "summary": f"{r.run.excitation}, {pose_text(r.run.pose) or 'no pose'}; "
                                    f"{drawn} figure{'s' if drawn != 1 else ''}"})
    return sections


def _number(figures: Sequence[dict]) -> None:
    """Number the drawn figures in the order they appear (Figure 1, 2, ...), each with its anchor."""
    drawn = [f for f in figures if f["png"] or f.get("rows")]
    for k, f in enumerate(drawn):
        f["number"], f["id"] = k + 1, f"figure-{k + 1}"


def relative_name(path: str | Path, report_dir: Path) -> str:
    """A file named relative to the report's folder (``runs.h5``, ``../data/modes.csv``), so the report
    holds no absolute local path; a file flexmodal ships in one of its sub-packages (the demo rig) as
    ``flexmodal:fixtures/rigs/demo_arm.toml`` (unless it lies in the report's folder); a name that is
    not a file path (an in-memory table) as it is.  A user's own file inside a clone (``modes.csv`` at
    its root, ``examples/rigs/demo_arm.toml``, the demo's ``flexmodal-demo/runs.h5``) is named relative
    to the report, not as if flexmodal shipped it."""
    p = Path(path)
    if not p.is_absolute() and not p.exists():
        return str(path)
    package = Path(__file__).resolve().parents[1]
    resolved = p.resolve()
    if resolved.is_relative_to(package) and not resolved.is_relative_to(report_dir.resolve()):
        inside = resolved.relative_to(package)
        if len(inside.parts) > 1 and (package / inside.parts[0] / "__init__.py").is_file():
            return f"flexmodal:{inside.as_posix()}"
    try:
        return Path(os.path.relpath(p.resolve(), report_dir.resolve())).as_posix()
    except ValueError:  # another drive (Windows)
        return p.name


def versions() -> list[tuple[str, str]]:
    """(name, version) of flexmodal, Python and the key libraries, for the report's footer."""
    out = [("flexmodal", _version()), ("Python", platform.python_version())]
    for name in KEY_LIBRARIES:
        try:
            out.append((name, version(name)))
        except PackageNotFoundError:
            continue
    return out


def _sensitivity_text(sensitivity: float, sensitivity_unit: str, unit: str) -> str:
    """A channel's sensitivity with its unit; without a unit the samples were stored in ``unit``
    itself (a simulated or already scaled channel), which a bare ``1`` would not say.

    Examples
    --------
    >>> _sensitivity_text(100.0, "mV/g", "m/s^2"), _sensitivity_text(1.0, "", "N")
    ('100 mV/g', '1 (stored in N)')
    """
    if sensitivity_unit:
        return f"{sensitivity:g} {sensitivity_unit}"
    return f"{sensitivity:g} (stored in {unit})" if unit else f"{sensitivity:g}"


def _pct(value: float | None) -> str:
    """A fraction as percent with three significant digits (0.0002 -> 0.02); empty when missing."""
    return f"{100 * value:.3g}" if value is not None else ""


# the SI unit a fitted parameter's name ends in (models.effects: k_Nm_per_rad, mass_kg, ...), longest first
PARAM_UNITS = {"_Nm_per_rad": "N m/rad", "_N_per_m": "N/m", "_kgm2": "kg m²", "_per_rad2": "1/rad²",
               "_per_rad": "1/rad", "_kg": "kg", "_m": "m", "_deg": "deg", "_rad": "rad", "_hz": "Hz"}


def param_text(name: str, value: float) -> str:
    """A fitted parameter with the unit its name ends in (none for a ratio such as ``scale``).

    Examples
    --------
    >>> param_text("k_Nm_per_rad", 6616.2), param_text("inertia_kgm2", 0.01), param_text("scale", 0.6332)
    ('k_Nm_per_rad = 6616 N m/rad', 'inertia_kgm2 = 0.01 kg m²', 'scale = 0.6332')
    """
    unit = next((u for suffix, u in PARAM_UNITS.items() if name.endswith(suffix)), "")
    return f"{name} = {value:.4g}" + (f" {unit}" if unit else "")


def _verdict_params(verdict) -> str:
    """The verdict's fitted parameters with their units and 95 % intervals:
    ``k_Nm_per_rad = 6616 N m/rad (95 % interval 5359 .. 8168)``; empty for ``none``."""
    intervals = verdict.param_intervals or {}

    def interval(name: str) -> str:
        lo, hi = (tuple(intervals.get(name) or ()) + (None, None))[:2]
        return f" (95 % interval {lo:.4g} .. {hi:.4g})" if lo is not None and hi is not None else ""

    fitted = (verdict.params or {}).items()
    return "; ".join(f"{param_text(k, v)}{interval(k)}" for k, v in fitted if v is not None)


def _configs_words(d: Diagnosis) -> str:
    """The configurations the gap lies in: ``all 10 configurations`` when it is every one diagnosed,
    else their names."""
    configs = sorted(d.where.configs, key=natural_key)
    if d.configs and len(configs) > 1 and set(configs) == set(d.configs):
        return f"all {len(configs)} configurations"
    return f"configurations {', '.join(configs) or '-'}"


def _diagnosis_view(d: Diagnosis) -> dict:
    """The template's diagnosis section: the typed result as display text."""
    where, verdict = d.where, d.verdict
    return {
        "baseline_rms": _pct(d.baseline.rms_rel_error), "baseline_max": _pct(d.baseline.max_rel_error),
        "where": f"modes {', '.join(str(m) for m in where.modes) or '-'}; {_configs_words(d)}"
                 + (f"; region {where.region}" if where.region else ""),
        "verdict": f"{verdict.effect} at {verdict.location}" if verdict.location else verdict.effect,
        "params": _verdict_params(verdict),
        "summary": verdict.summary or "",
        "remaining": remaining_words(d) if not verdict.explained else "",
        "alternatives": alternatives_words(d),
        "advice": advice_words(d),
        "heldout": " / ".join(_pct(x) for x in (verdict.heldout_rms_rel_error_before,
                                                 verdict.heldout_rms_rel_error_after)),
        "explained": verdict.explained,
        # green only when what remains is noise; amber when most of the gap is removed but not all
        "grade_class": "ok" if verdict.explained else "partial" if verdict.grade == "largely explained"
                       else "warn",
        "explained_text": verdict_words(d) or ("yes" if verdict.explained else
                                               "no: the gap stays above the measurement scatter"),
        "ranking": [{"effect": r.effect, "location": r.location,
                     "params": ", ".join(param_text(k, v) for k, v in r.params.items() if v is not None),
                     "fit": _pct(r.fit_rms_rel_error), "heldout": _pct(r.heldout_rms_rel_error),
                     "n_params": r.n_params} for r in d.ranking[:8]],
        "holdout": d.holdout.scheme if d.holdout is not None else "",
        "scatter": scatter_line(d).removeprefix("scatter: ").replace("sqrt(m^2 + f^2)", "√(m² + f²)"),
        "frequencies": _diagnosis_frequencies(d.predictions) if d.predictions is not None else [],
        "warnings": [{"what": "not calibrated with shear" if SHEAR_UNCALIBRATED in w
                      else "measured shapes not used", "text": w} for w in d.warnings or ()],
    }


def _diagnosis_frequencies(pred: Predictions) -> list[dict]:
    """Rows (config, mode, measured, nominal model, best candidate held out) [Hz] of the diagnosis'
    predictions; a missing value is an empty cell."""
    def hz(table: Mapping[str, Sequence[float | None]] | None, config: str, mode: int) -> str:
        values = (table or {}).get(config) or ()
        v = values[mode] if mode < len(values) else None
        return f"{v:.2f}" if v is not None else ""

    return [{"config": c, "mode": m + 1, "measured": hz(pred.measured_hz, c, m),
             "baseline": hz(pred.baseline_hz, c, m), "best": hz(pred.best_heldout_hz, c, m)}
            for c, fm in sorted(pred.measured_hz.items(), key=lambda kv: natural_key(kv[0]))
            for m in range(len(fm))]


def _measured_rows(measured: ModalTable) -> list[dict]:
    rows = []
    for _, r in pd.concat([measured.rows(c) for c in ordered_configs(measured)]).iterrows():
        zeta = r.get("damping_ratio")
        rows.append({"config": r["config"], "pose": pose_text(measured.pose(r["config"])),
                     "mode": int(r["mode"]),
                     "freq": f"{r['freq_hz']:.2f}",
                     "zeta": f"{100 * zeta:.2f}" if zeta is not None and zeta == zeta else ""})
    return rows


def _version() -> str:
    try:
        return version("flexmodal")
    except PackageNotFoundError:
        return "(source tree)"


def write_report(out_path: str | Path, *, runs: Sequence[RunSummary] = (),
                 comparison: Comparison | None = None, measured: ModalTable | None = None,
                 repeats: Sequence[ModalTable] = (), predictions: Sequence[tuple[str, ModalTable]] = (),
                 shapes: Mapping[str, object] | None = None,
                 diagnosis: Diagnosis | None = None, rig_name: str = "",
                 title: str = "flexmodal validation report", inputs: Sequence[str | Path] | None = None,
                 geometry: Geometry | None = None,
                 progress: Callable[[str], None] | None = None) -> Path:
    """Render one self-contained HTML report to ``out_path`` and return its path.

    ``runs``: the runs to show (read, with FRFs and their identification, by the caller).
    ``comparison``: measured vs predicted modes (compare.tables.compare_tables).  ``measured``:
    identified modes; ``repeats``: further measured tables of the same configurations (error bars);
    ``predictions``: (name, table) pairs.  ``shapes``: {config: models.arm_shapes.ArmModes, or the
    reason none is drawn} for the mode-shape plots.  ``diagnosis``: a compare.result.Diagnosis (the
    one renderer of a diagnosis: ``diagnose`` writes its diagnosis.html with it too).  ``inputs``: the
    files the results came from, when the results are given in memory (default: the runs' files and the
    tables' sources); named relative to the report.  ``geometry``: a test geometry (UFF,
    reports.geometry) to animate the measured modes on.  ``progress`` is called with a short message per step.
    """
    out = Path(out_path)
    step = progress or (lambda _msg: None)
    summaries = _run_order(runs)
    comparison_html = "" if comparison is None else html_fragment(
        comparison, caption="Table 1. Measured and predicted natural frequencies")
    meta, quality, channel_sets = _run_rows(summaries)
    given = ReportInputs(tuple(summaries), comparison, measured, tuple(repeats), tuple(predictions), shapes,
                         diagnosis, rig_name)
    tables = {"comparison": bool(comparison_html), "diagnosis": diagnosis is not None,
              "identified": measured is not None}
    run_sections: list[dict] = []
    sections = []   # every registered section (reports.sections) the report shows, drawn in page order
    for name, section in SECTIONS.items():
        if section.block == "animations":
            figures = _animations(measured, predictions, shapes or {}, geometry)
            shown = bool(figures)
        elif section.block == "runs":
            run_sections = _run_sections(summaries, step)
            figures, shown = [f for s in run_sections for f in s["figures"]], bool(meta)
        elif section.block:
            figures, shown = [], tables[section.block]
        else:   # told before the (slow) drawing; a section with nothing to draw then says why
            step(f"plotting {section.title.lower()}")
            drawn = list(section.figures(given))
            if not drawn:
                step(f"no {section.title.lower()}: " + (f"it is drawn from {section.needs}" if section.needs
                                                        else "nothing in these inputs to draw it from"))
            figures = [_fig(fig, caption) for fig, caption in drawn]
            shown = bool(figures)
        if shown:
            sections.append({"id": section.anchor or f"section-{name}", "title": section.title,
                             "block": section.block, "figures": figures})
    _number([f for s in sections for f in s["figures"]])
    if inputs is None:
        inputs = [s.run.path for s in summaries]
        inputs += [t.source for t in ([measured] if measured is not None else []) + list(repeats)]
        inputs += [t.source for _, t in predictions]
    named = list(dict.fromkeys(relative_name(p, out.parent) for p in inputs))
    contents = [{"id": s["id"], "title": s["title"],
                 "children": [{"id": r["id"], "title": r["label"]} for r in run_sections]
                 if s["block"] == "runs" else []} for s in sections]
    env = jinja2.Environment(loader=jinja2.PackageLoader("flexmodal.reports", "templates"),
                             autoescape=jinja2.select_autoescape(["html"]), undefined=jinja2.StrictUndefined)
    html = env.get_template("report.html").render(
        title=title, generated=datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"), versions=versions(),
        rig_name=rig_name, inputs=named, comparison_html=comparison_html, contents=contents,
        tables_before=1 if comparison_html else 0, sections=sections,
        diagnosis=_diagnosis_view(diagnosis) if diagnosis is not None else None,
        animation_script=animate.SCRIPT,
        measured_rows=_measured_rows(measured) if measured is not None else [],
        measured_source=relative_name(measured.source, out.parent) if measured is not None else "",
        runs=meta, quality=quality, channel_sets=channel_sets, low_coherence=LOW_COHERENCE,
        run_sections=run_sections)
    out.parent.mkdir(parents=True, exist_ok=True)
    return write_text(out, html)


MAX_DIAGNOSIS_BYTES = 8 << 20
"""A diagnosis.json larger than this (8 MiB; the demo's is 20 kB, a diagnosis of hundreds of poses and
candidates well under 1 MiB) is refused unread: its reading time grows with its size (docs/formats.md)."""


def load_diagnosis(path: str | Path) -> Diagnosis:
    """Read a diagnosis.json (docs/formats.md) of at most MAX_DIAGNOSIS_BYTES; ReportError naming the
    file and the key when it is not JSON or not a diagnosis, naming the file when it is too large."""
    p = Path(path)
    try:
        return Diagnosis.from_json(read_text(p, ReportError, "diagnosis JSON file", MAX_DIAGNOSIS_BYTES))
    except CompareError as exc:
        raise ReportError(f"{p}: {exc}") from None
