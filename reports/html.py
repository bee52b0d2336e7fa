"""The self-contained HTML validation report (jinja2 template ``templates/report.html``).

One file: images are embedded as base64 PNG, the style sheet is inline, there is no script and nothing
is fetched from a network.  Sections (each only when its input is given): comparison table of
measured vs predicted modes (compare.tables), diagnosis summary (CONTRACT §5), frequency-vs-pose,
trend and mode-shape plots, run metadata, channel list, data quality (trigger/overload/gap/corrupt
events, rejected hits, coherence) with the FRF plot of each run and its stabilisation diagram (pLSCF of
modal.lscf over orders 2..``MAX_ORDER``), and the gap per mode before and after the diagnosed effect.
"""

from __future__ import annotations

import base64
import json
from collections.abc import Callable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path

import jinja2
import pandas as pd

from flexmodal.compare.tables import compare_tables, html_fragment, natural_key, ordered_configs, table_name
from flexmodal.daq.store import expand_runs
from flexmodal.modal.table import ModalTable
from flexmodal.reports import plots
from flexmodal.reports.errors import ReportError
from flexmodal.reports.runs import LOW_COHERENCE, RunSummary, summarise_run

UNIT_SUFFIXES = {"_deg": "deg", "_kg": "kg", "_m": "m", "_rad": "rad", "_n": "N"}
MAX_SHAPE_CONFIGS = 2
MAX_ORDER = 32
FRF_UNITS = {"accelerance": "(m/s²)/N", "mobility": "(m/s)/N", "receptance": "m/N"}


def pose_unit(var: str) -> str:
    """Unit of a pose variable from its name's suffix (``theta_deg`` -> deg), ``-`` if none."""
    for suffix, unit in UNIT_SUFFIXES.items():
        if var.lower().endswith(suffix):
            return unit
    return "-"


def _pose_text(pose: Mapping[str, object]) -> str:
    return ", ".join(f"{k} = {v:g} {pose_unit(k)}" if isinstance(v, int | float) else f"{k} = {v}"
                     for k, v in pose.items())


def _fig(fig, caption: str) -> dict:
    return {"png": base64.b64encode(plots.figure_png(fig)).decode("ascii"), "caption": caption}


def _varying_pose_vars(table: ModalTable) -> list[str]:
    out = []
    for col in table.pose_columns:
        values = table.frame.groupby("config")[col].first()
        if values.nunique() > 1 and values.dtype.kind in "fi":
            out.append(col[len("pose."):])
    return out


def _mode_figures(measured: ModalTable | None, repeats: Sequence[ModalTable],
                  predictions: Sequence[tuple[str, ModalTable]], rig) -> list[dict]:
    figs = []
    ref = measured if measured is not None else (predictions[0][1] if predictions else None)
    if ref is None:
        return figs
    varying = _varying_pose_vars(ref)
    meas = ([measured] if measured is not None else []) + list(repeats)
    if varying:
        var = varying[0]
        figs.append(_fig(plots.plot_freq_vs_pose(meas, list(predictions), var, pose_unit(var)),
                         f"Natural frequency against {var}: a line per model and mode, experiment mean "
                         f"± 1 standard deviation over {len(meas)} test(s)"))
    if len(varying) >= 2:
        x = next((v for v in varying if "payload" in v), varying[1])
        group = next(v for v in varying if v != x)
        figs.append(_fig(plots.plot_trends(ref, x, group, pose_unit(x), pose_unit(group)),
                         f"Trends of each mode's frequency with {x}, a line per {group} "
                         f"({table_name(ref, 'modes')})"))
    shared = set()
    if rig is not None and measured is not None:
        shared = set(measured.sensors) & {s.name for s in rig.sensors}
    if len(shared) >= 2:
        configs = ordered_configs(measured)
        for config in list(dict.fromkeys([configs[0], configs[-1]]))[:MAX_SHAPE_CONFIGS]:
            pose = measured.pose(config)
            missing = [v for v in rig.pose_variables if v not in pose]
            if missing:
                figs.append({"png": None, "caption": f"No mode shapes drawn for {config}: the measured table "
                                                     f"gives no pose.{missing[0]} for the rig"})
                continue
            figs.append(_fig(plots.plot_mode_shapes(rig, pose, measured, config),
                             f"Measured mode shapes at {config} ({_pose_text(pose)}) on the arm, with the "
                             f"frame FE model's best-matching mode (by MAC) as a curve"))
    return figs


def _run_order(runs: Sequence[RunSummary]) -> list[RunSummary]:
    """Runs grouped by file (in the order given), then by numeric pose values, then naturally by id."""
    files = list(dict.fromkeys(r.path for r in runs))

    def key(r: RunSummary) -> tuple:
        pose = tuple((k, float(v)) for k, v in sorted(r.pose.items()) if isinstance(v, int | float))
        return files.index(r.path), pose, natural_key(r.run_id)

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
        label = f"{r.path.name}::{r.run_id}"
        meta.append({"file": r.path.name, "run_id": r.run_id, "start_time": _start_time(r.start_time),
                     "excitation": r.excitation, "pose": _pose_text(r.pose), "fs": f"{r.sample_rate_hz:g}",
                     "duration": f"{r.duration_s:.2f}", "n_samples": r.n_samples,
                     "n_channels": len(r.channels)})
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
        key = tuple(r.channels)
        if key not in sets:
            sets[key] = {"runs": [], "channels": [
                {"name": c.name, "kind": c.kind, "unit": c.unit,
                 "sensitivity": f"{c.sensitivity:g} {c.sensitivity_unit}".strip(), "location": c.location,
                 "direction": c.direction, "peak": f"{p:.4g} {c.unit}"}
                for c, p in zip(r.channels, r.peak_abs, strict=True)]}
            channel_sets.append(sets[key])
        sets[key]["runs"].append(label)
    return meta, quality, channel_sets


def _stabilisation_figure(frf, label: str, unit: str) -> dict:
    from flexmodal.modal.errors import ModalError
    from flexmodal.modal.lscf import stabilisation

    band = frf.freq_hz > 0
    f, H = frf.freq_hz[band], frf.H[..., band]
    top = min(MAX_ORDER, (f.size - 2) // 2)
    try:
        poles = stabilisation(f, H, range(2, top + 1))
    except ModalError as exc:
        return {"png": None, "caption": f"{label}: no stabilisation diagram ({exc})"}
    return _fig(plots.plot_stabilisation(f, H, poles, unit, title=label),
                f"{label}: pLSCF stabilisation diagram, orders 2-{top} (filled: stable in frequency, "
                f"damping and shape), over the complex mode indicator function")


def _oma_figures(r: RunSummary, label: str) -> list[dict]:
    """FDD and SSI figures of an output-only run (reports/oma.py); none for other runs without FRFs."""
    from flexmodal.daq.store import read_run
    from flexmodal.reports.oma import is_output_only, oma_figures

    kinds = [c.kind for c in r.channels]
    if not is_output_only(kinds, r.excitation):
        return []
    run = read_run(r.path, r.run_id)
    return [_fig(fig, caption) if fig is not None else {"png": None, "caption": caption}
            for fig, caption in oma_figures(run.samples, run.sample_rate_hz, [c.name for c in run.channels],
                                            kinds, label)]


def _run_figures(runs: Sequence[RunSummary]) -> list[dict]:
    figs = []
    for r in runs:
        label = f"{r.path.name}::{r.run_id}"
        if r.frf is None:
            figs += _oma_figures(r, label)
            continue
        inputs = ", ".join(r.frf.inputs) or "force"
        unit = FRF_UNITS.get(r.frf.quantity, "FRF unit")
        figs.append(_fig(plots.plot_frf(r.frf.freq_hz, r.frf.H, r.frf.coherence, r.frf.outputs, unit,
                                        title=f"{label} ({r.excitation})"),
                         f"{label}: FRF magnitude, phase and coherence (input {inputs}, "
                         f"pose {_pose_text(r.pose)})"))
        figs.append(_stabilisation_figure(r.frf, label, unit))
    return figs


def _pct(value) -> str:
    """A fraction as percent with three significant digits (0.0002 -> 0.02)."""
    return f"{100 * float(value):.3g}" if value is not None else ""


def _diagnosis_view(d: Mapping) -> dict:
    base, where, verdict = d.get("baseline", {}), d.get("where", {}), d.get("verdict", {})
    region = where.get("region", "")
    return {
        "baseline_rms": _pct(base.get("rms_rel_error")), "baseline_max": _pct(base.get("max_rel_error")),
        "where": f"modes {', '.join(str(m) for m in where.get('modes', [])) or '-'}; configurations "
                 f"{', '.join(str(c) for c in where.get('configs', [])) or '-'}"
                 + (f"; region {region}" if region else ""),
        "verdict": f"{verdict.get('effect', '?')} at {verdict.get('location', '?')}",
        "summary": str(verdict.get("summary", "")),
        "heldout": f"{_pct(verdict.get('heldout_rms_rel_error_before'))} / "
                   f"{_pct(verdict.get('heldout_rms_rel_error_after'))}",
        "explained": bool(verdict.get("explained")),
        "explained_text": "yes" if verdict.get("explained") else "no: the best candidate leaves a gap above "
                                                                  "the measurement scatter",
        "ranking": [{"effect": r.get("effect"), "location": r.get("location"),
                     "params": ", ".join(f"{k} = {v:.4g}" for k, v in r.get("params", {}).items()),
                     "fit": _pct(r.get("fit_rms_rel_error")), "heldout": _pct(r.get("heldout_rms_rel_error")),
                     "n_params": r.get("n_params", "")} for r in d.get("ranking", [])[:8]],
    }


def _measured_rows(measured: ModalTable) -> list[dict]:
    rows = []
    for _, r in pd.concat([measured.rows(c) for c in ordered_configs(measured)]).iterrows():
        zeta = r.get("damping_ratio")
        rows.append({"config": r["config"], "pose": _pose_text(measured.pose(r["config"])),
                     "mode": int(r["mode"]),
                     "freq": f"{r['freq_hz']:.2f}",
                     "zeta": f"{100 * zeta:.2f}" if zeta is not None and zeta == zeta else ""})
    return rows


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("flexmodal")
    except PackageNotFoundError:
        return "(source tree)"


def write_report(out_path: str | Path, *, runs: Sequence[str | Path | tuple[str | Path, str]] = (),
                 measured: ModalTable | None = None, repeats: Sequence[ModalTable] = (),
                 predictions: Sequence[ModalTable | tuple[str, ModalTable]] = (),
                 diagnosis: Mapping | None = None, rig=None, title: str = "flexmodal validation report",
                 progress: Callable[[str], None] | None = None) -> Path:
    """Write one self-contained HTML report to ``out_path`` and return its path.

    ``runs``: HDF5 files (all their runs), ``FILE::RUN_ID`` strings or (file, run id) tuples.
    ``measured``: identified modes; ``repeats``: further measured tables of the same configurations
    (repeated tests, for error bars).  ``predictions``: ModalTables (named by their ``source`` column)
    or (name, table) pairs.  ``diagnosis``: a parsed diagnosis.json (CONTRACT §5).  ``rig``: a
    ``models.rig.Rig`` for mode shapes on the arm.  ``progress`` is called with a short message per step.
    """
    step = progress or (lambda _msg: None)
    named = [p if isinstance(p, tuple) else (table_name(p, Path(p.source).stem), p) for p in predictions]
    summaries = []
    for path, run_id in expand_runs(runs):
        step(f"reading {path.name}::{run_id}")
        summaries.append(summarise_run(path, run_id))
    summaries = _run_order(summaries)
    comparison_html = ""
    if measured is not None and named:
        step("comparing modes")
        comp = compare_tables(measured, named, measured_name=table_name(measured, "experiment"))
        comparison_html = html_fragment(comp)
    step("plotting modes")
    figures_modes = _mode_figures(measured, repeats, named, rig)
    step("plotting runs")
    figures_runs = _run_figures(summaries)
    figures_diag = []
    if diagnosis is not None:
        try:
            figures_diag.append(_fig(plots.plot_gap(diagnosis), "Relative frequency error per mode of the "
                                     "nominal model and with the diagnosed effect; held-out RMS error"))
        except ReportError as exc:
            raise ReportError(f"diagnosis: {exc}") from None
    meta, quality, channel_sets = _run_rows(summaries)
    inputs = [str(p) for p in dict.fromkeys(str(s.path) for s in summaries)]
    inputs += [t.source for t in ([measured] if measured is not None else []) + list(repeats)]
    inputs += [t.source for _, t in named]
    env = jinja2.Environment(loader=jinja2.PackageLoader("flexmodal.reports", "templates"),
                             autoescape=jinja2.select_autoescape(["html"]), undefined=jinja2.StrictUndefined)
    html = env.get_template("report.html").render(
        title=title, generated=datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"), version=_version(),
        rig_name=getattr(rig, "name", ""), inputs=inputs, comparison_html=comparison_html,
        diagnosis=_diagnosis_view(diagnosis) if diagnosis is not None else None,
        figures_modes=figures_modes, measured_rows=_measured_rows(measured) if measured is not None else [],
        measured_source=measured.source if measured is not None else "", runs=meta, quality=quality,
        channel_sets=channel_sets, low_coherence=LOW_COHERENCE, figures_runs=figures_runs,
        figures_diagnosis=figures_diag)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(html, encoding="utf-8")
    return out


def load_diagnosis(path: str | Path) -> dict:
    """Read a diagnosis.json (CONTRACT §5); ReportError naming the file when it is not JSON."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ReportError(f"{p}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(doc, dict) or "baseline" not in doc:
        raise ReportError(f"{p}: not a diagnosis (no 'baseline' object)")
    return doc
