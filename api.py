"""flexmodal's public Python API: the functions the command line is a thin shell over.

Read a run, compute FRFs, identify modes, predict them with a model, compare, diagnose the gap, and get
matplotlib figures back instead of files.  Every function takes paths or the objects the previous step
returned, raises the package's own error type (``DaqError``, ``ModalError``, ``ModelError``,
``CompareError``, ``ReportError``: one line naming the file, field or value) on bad input, and imports
its heavy dependencies only when called, so ``import flexmodal`` stays cheap.  Worked example:
docs/python-api.md.  Units: frequencies Hz, damping ratios as fractions, poses in degrees and kg.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from flexmodal.compare.result import Diagnosis
    from flexmodal.compare.tables import Comparison
    from flexmodal.daq.acquire import Summary
    from flexmodal.daq.session import Session
    from flexmodal.daq.store import Run
    from flexmodal.modal.frf import FrfResult
    from flexmodal.modal.identify import Modes
    from flexmodal.modal.table import ModalTable
    from flexmodal.models.rig import Rig

__all__ = [
    "Identification", "acquire", "compare_modes", "compute_frf", "compute_frfs", "diagnose",
    "format_comparison", "identify", "list_runs", "load_rig", "plot_comparison", "plot_frf", "plot_gap",
    "plot_mode_shapes", "plot_stabilisation", "predict", "read_diagnosis", "read_poses", "read_run",
    "read_table", "report", "write_diagnosis",
]

SHAPE_CONFIGS = 2              # configurations whose mode shapes a report draws on the arm (first, last)

PathLike = str | Path


# -- runs ------------------------------------------------------------------------------------------

def list_runs(path: PathLike) -> list[str]:
    """Run ids stored in an HDF5 run file (docs/hdf5-format.md), sorted."""
    from flexmodal.daq.store import list_runs as _list

    return _list(path)


def read_run(path: PathLike, run_id: str | None = None) -> Run:
    """One stored run read into memory (``daq.store.Run``: samples [n_samples, n_channels] in physical
    units, channels, events, pose).  ``run_id`` may be left out when the file holds one run."""
    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.store import read_run as _read

    if run_id is None:
        ids = list_runs(path)
        if len(ids) != 1:
            raise DaqError(f"{path}: holds {len(ids)} runs ({', '.join(ids) or 'none'}); name one")
        run_id = ids[0]
    return _read(path, run_id)


def acquire(session: PathLike | Session, out: PathLike, *, duration_s: float | None = None,
            run_id: str | None = None, recover: bool = False, quiet: bool = True) -> Summary:
    """Record the devices of a session config (TOML path or ``daq.session.Session``;
    docs/acquisition.md) into a run of the HDF5 file ``out``; ``recover`` first clears the
    open-for-writing flags a killed writer left in ``out``.  Returns the acquisition summary."""
    from flexmodal.daq.acquire import acquire as _acquire
    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.session import load_session
    from flexmodal.valid_output import hdf5_output

    if isinstance(session, str | Path):
        session = load_session(session)
    hdf5_output(out, DaqError, "run file (--out)")
    if duration_s is not None and duration_s <= 0:
        raise DaqError(f"--duration {duration_s}: must be > 0 seconds")
    if recover and Path(out).exists():
        from flexmodal.daq.store import recover as _recover

        _recover(out)
    return _acquire(session, out, duration_s=duration_s, quiet=quiet, run_id=run_id)


# -- FRFs ------------------------------------------------------------------------------------------

def compute_frf(run: Run | PathLike, *, estimator: str = "H1", nfft: int | None = None,
                window: str | None = None, overlap: float = 0.5, averaging: str = "linear",
                store: bool = False) -> FrfResult:
    """FRFs and coherence of one run (a ``Run``, or the path of a one-run file): ``H`` [n_out, n_in,
    n_freq], ``coherence`` [n_out, n_freq], ``freq_hz`` (docs/modal.md for the estimators, windows and
    impact processing).  ``store`` writes them back under ``/runs/<id>/frf`` of the run's file."""
    from flexmodal.modal.compute import compute_frf as _compute

    if isinstance(run, str | Path):
        run = read_run(run)
    if store:
        from flexmodal.modal.errors import ModalError
        from flexmodal.valid_output import hdf5_output

        hdf5_output(run.path, ModalError, "run file (store=True)")
    result = _compute(run, estimator=estimator, nfft=nfft, window=window, overlap=overlap,
                      averaging=averaging)
    if store:
        from flexmodal.modal.runs_io import write_frf

        write_frf(run.path, run.run_id, result)
    return result


def compute_frfs(runs: Sequence[PathLike | tuple[PathLike, str]], *, estimator: str = "H1",
                 nfft: int | None = None, window: str | None = None, overlap: float = 0.5,
                 averaging: str = "linear", workers: int | None = 0, scheduler: str | None = None,
                 out: PathLike | None = None, quiet: bool = True) -> list[tuple[str, str]]:
    """Batch FRFs of stored runs (a file means all its runs, ``FILE::RUN_ID`` or (file, id) one run),
    written back into each file or into ``out``; returns the (file, run id) pairs written.

    ``workers`` 0 (the default) computes the runs here one after the other; None chooses as the
    ``frf`` command does (here, or a pool of local processes once the measured cost predicts that it
    pays for its start-up, see ``modal.batch.run_batch``); N forces a pool of N processes;
    ``scheduler`` sends the runs to that dask address.  Pool workers start from a fork server that
    imports the calling script again as ``__mp_main__`` (as ``multiprocessing`` does), so a script
    passing ``workers`` None or N keeps its own work under ``if __name__ == "__main__":``.
    Estimators registered in this process (``modal.frf.register_estimator``) reach worker processes
    only if they register them too."""
    from flexmodal.modal.batch import frf_batch

    if out is not None:
        from flexmodal.modal.errors import ModalError
        from flexmodal.valid_output import hdf5_output

        hdf5_output(out, ModalError, "FRF file (--out)")
    options = {"estimator": estimator, "nfft": nfft, "window": window, "overlap": overlap,
               "averaging": averaging}
    return frf_batch(runs, options, workers=workers, scheduler=scheduler, out=out, quiet=quiet)


# -- modes -----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Identification:
    """Identified modes: the modal ``table`` (docs/formats.md, modal table CSV) and, per configuration,
    the ``modes`` (``modal.identify.Modes``) and the ``outputs`` their shapes are given at."""

    table: ModalTable
    modes: Mapping[str, Modes]
    outputs: Mapping[str, tuple[str, ...]]

    @property
    def warnings(self) -> list[str]:
        """``config: message`` for every warning met on the way."""
        return [f"{c}: {w}" for c, m in self.modes.items() for w in m.warnings]


def identify(source: PathLike | FrfResult, *, method: str | None = None, fmin: float | None = None,
             fmax: float | None = None, max_order: int | None = None, run_id: str | None = None,
             config: str = "run", pose: Mapping[str, float] | None = None,
             poles_hz: Sequence[float] | None = None, thresholds=None,
             decay_rate_per_s: float | None = None,
             references: Sequence[str] | None = None) -> Identification:
    """Natural frequencies [Hz], damping ratios and mode shapes of an HDF5 run file (each run one
    configuration; stored FRFs, else computed), a UFF file (dataset 58 FRFs or time histories), or an
    ``FrfResult`` in memory (then named ``config`` at ``pose``).  ``method``: ``lscf`` (pLSCF +
    stabilisation + LSFD) or ``peak`` (CMIF peaks, half-power damping); ``max_order`` caps the pLSCF
    order (default: it adapts to the data); ``poles_hz`` picks the stable poles nearest these
    frequencies; ``thresholds`` (``modal.identify.Thresholds``) the automatic selection's limits;
    ``decay_rate_per_s`` [1/s] the exponential window to take out (default: the one the FRFs record).
    ``method`` None lets the data decide: ``lscf`` where a force channel exists, else output-only
    ``ssi`` (also ``fdd``), whose ``references`` are channel names (docs/oma.md); output-only shapes
    are unscaled.  docs/modal.md."""
    from flexmodal.modal.identify import modes_table
    from flexmodal.modal.sources import identify_frf, identify_input

    options = {"method": method, "fmin": fmin, "fmax": fmax, "max_order": max_order, "poles_hz": poles_hz,
               "thresholds": thresholds, "decay_rate_per_s": decay_rate_per_s}
    if isinstance(source, str | Path):
        table, found = identify_input(source, run_id=run_id, references=references, **options)
        return Identification(table, {c: m for c, (m, _) in found.items()},
                              {c: tuple(o) for c, (_, o) in found.items()})
    modes = identify_frf(source, **{**options, "method": method or "lscf"})
    table = modes_table(modes, source.outputs, config=config, pose=pose)
    return Identification(table, {config: modes}, {config: tuple(source.outputs)})


def read_table(path: PathLike) -> ModalTable:
    """A modal table CSV (docs/formats.md): one row per (configuration, mode)."""
    from flexmodal.modal.table import ModalTable

    return ModalTable.read_csv(path)


def read_poses(path: PathLike) -> dict[str, dict[str, float]]:
    """A POSES.csv (docs/formats.md): {config: {pose variable: value}} (degrees, kg)."""
    from flexmodal.modal.table import poses_from_csv

    return poses_from_csv(path)


def _table(table: ModalTable | PathLike) -> ModalTable:
    return read_table(table) if isinstance(table, str | Path) else table


# -- models ----------------------------------------------------------------------------------------

def load_rig(path: PathLike) -> Rig:
    """A rig description (TOML, docs/formats.md), validated."""
    from flexmodal.models.rig import load_rig as _load

    return _load(path)


def _rig(rig: Rig | PathLike) -> Rig:
    return load_rig(rig) if isinstance(rig, str | Path) else rig


def predict(rig: Rig | PathLike, poses: Mapping[str, Mapping[str, float]] | ModalTable | PathLike,
            model: str = "fe", n_modes: int = 4, *, source: str | None = None,
            progress: Callable[[str], None] | None = None, **options: object) -> ModalTable:
    """Predicted modes of ``rig`` for every configuration of ``poses`` (a POSES.csv path, a
    {config: pose} mapping, or a modal table whose configurations and poses are taken) by ``model``
    (``fe``, ``assumed-modes``, ``lumped-mass``, ``blevins``; docs/models.md for ``options``)."""
    from flexmodal.models.errors import ModelError
    from flexmodal.models.predict import predict as _predict

    if isinstance(poses, str | Path):
        poses = read_poses(poses)
    elif not isinstance(poses, Mapping):
        poses = {c: poses.pose(c) for c in poses.configs}
    if not poses:
        raise ModelError("predict: no configurations")
    return _predict(_rig(rig), poses, model, n_modes, source=source, progress=progress, **options)


# -- comparison and diagnosis ----------------------------------------------------------------------

def _named(tables: Iterable[ModalTable | PathLike | tuple[str, ModalTable]]) -> list[tuple[str, ModalTable]]:
    from flexmodal.compare.tables import table_name

    out = []
    for t in tables:
        if isinstance(t, tuple):
            out.append(t)
        else:
            table = _table(t)
            out.append((table_name(table, Path(str(t)).stem if isinstance(t, str | Path)
                                   else Path(table.source).stem), table))
    return out


def compare_modes(measured: ModalTable | PathLike,
                  *predicted: ModalTable | PathLike | tuple[str, ModalTable],
                  min_mac: float = 0.5) -> Comparison:
    """Pair every predicted table with the measured one (by MAC where both have shapes at two or more
    common sensors, else by frequency order); names come from the ``source`` column, else the file
    name.  ``format_comparison`` prints it; docs/compare-and-report.md."""
    from flexmodal.compare.errors import CompareError
    from flexmodal.compare.tables import compare_tables, table_name

    if not 0.0 <= min_mac <= 1.0:
        raise CompareError(f"--min-mac: must lie in [0, 1] (got {min_mac})")
    meas = _table(measured)
    return compare_tables(meas, _named(predicted), measured_name=table_name(meas, "experiment"),
                          min_mac=min_mac)


def format_comparison(comparison: Comparison, fmt: str = "md", layout: str = "modes",
                      caption: str = "Measured and predicted natural frequencies") -> str:
    """The comparison as text: ``md``, ``csv`` (full precision), ``tex`` or ``html``; ``layout``
    ``modes`` (a row per mode) or ``sources`` (a row per source)."""
    from flexmodal.compare.tables import render

    return render(comparison, fmt, layout, caption)


def diagnose(rig: Rig | PathLike, measured: ModalTable | PathLike, *, effects: str | Sequence[str] = "all",
             holdout: str | Sequence[str] = "auto", scatter: float = 0.005) -> Diagnosis:
    """Sim-to-real gap diagnosis of the nominal ``rig`` against ``measured`` modes over several poses:
    where the gap is, which unmodelled effect explains it, judged on held-out configurations
    (docs/diagnosis.md).  The result is a tree of frozen records (compare/result.py:
    ``.verdict.effect``, ``.ranking[0].params``, ...); ``.to_json()`` is diagnosis.json (docs/formats.md)."""
    from flexmodal.compare.diagnosis import diagnose as _diagnose

    return _diagnose(_rig(rig), _table(measured), effects=effects, holdout=holdout, scatter=scatter)


def write_diagnosis(result: Diagnosis, out_dir: PathLike,
                    inputs: Sequence[PathLike] = ()) -> tuple[Path, Path]:
    """Write ``diagnosis.json`` (strict JSON) and ``diagnosis.html`` of a :func:`diagnose` result into
    ``out_dir``.  The page is the validation report's diagnosis section alone (one renderer,
    reports/html.py), naming ``inputs`` (the rig and the measured modes it was diagnosed from)."""
    from flexmodal.compare.errors import CompareError
    from flexmodal.reports.html import write_report
    from flexmodal.valid_output import output_dir, write_text

    out = output_dir(out_dir, CompareError, "diagnosis folder (--out)")
    out.mkdir(parents=True, exist_ok=True)
    pj = write_text(out / "diagnosis.json", result.to_json())
    ph = write_report(out / "diagnosis.html", diagnosis=result, title="Sim-to-real gap diagnosis",
                      inputs=list(inputs))
    return pj, ph


def read_diagnosis(path: PathLike) -> Diagnosis:
    """A diagnosis.json (docs/formats.md) read back into the :func:`diagnose` result it was written
    from; ReportError naming the file and the key when it is not one."""
    from flexmodal.reports.html import load_diagnosis

    return load_diagnosis(path)


# -- figures ---------------------------------------------------------------------------------------

def plot_frf(frf: FrfResult, title: str = "") -> Figure:
    """Magnitude, phase [deg] and coherence [-] of the FRFs of one run (first reference)."""
    from flexmodal.reports import plots

    return plots.plot_frf(frf.freq_hz, frf.H, frf.coherence, frf.outputs,
                          plots.frf_unit(frf.quantity), title=title)


def plot_stabilisation(frf: FrfResult, modes: Modes | None = None, *, fmin: float | None = None,
                       fmax: float | None = None, max_order: int | None = None, title: str = "") -> Figure:
    """Stabilisation diagram of the pLSCF identification of ``frf`` over the CMIF of its band: that of
    ``modes`` (an :func:`identify` result's ``modes[config]``) if given, else of ``frf`` identified here
    in [fmin, fmax] Hz with ``max_order`` (default: the order adapts to the data)."""
    from flexmodal.modal.sources import identify_frf
    from flexmodal.reports import plots

    if modes is None:
        modes = identify_frf(frf, fmin=fmin, fmax=fmax, max_order=max_order)
    return plots.plot_identification_diagram(frf, modes, plots.frf_unit(frf.quantity), title=title)


def plot_mode_shapes(rig: Rig | PathLike, measured: ModalTable | PathLike, config: str,
                     n_fe_modes: int = 8, title: str = "") -> Figure:
    """Measured shapes of ``config`` at the rig's sensors drawn on the arm at its pose, each with the
    best-matching (MAC) of the frame FE model's ``n_fe_modes`` lowest modes as a curve."""
    from flexmodal.models.arm_shapes import arm_modes
    from flexmodal.reports import plots

    rig, measured = _rig(rig), _table(measured)
    sensors = [s.name for s in rig.sensors if s.name in measured.sensors]
    return plots.plot_mode_shapes(arm_modes(rig, measured.pose(config), sensors, n_fe_modes), measured,
                                  config, title=title)


def plot_comparison(measured: ModalTable | PathLike,
                    *predicted: ModalTable | PathLike | tuple[str, ModalTable], pose_var: str | None = None,
                    repeats: Sequence[ModalTable | PathLike] = (),
                    title: str = "") -> Figure:
    """Measured (mean ± 1 sd over ``repeats``) and predicted natural frequencies [Hz] against the pose
    variable ``pose_var`` (default the first that varies), a line per model and mode."""
    from flexmodal.reports import plots
    from flexmodal.reports.errors import ReportError
    from flexmodal.reports.html import pose_unit, varying_pose_vars

    meas = [_table(measured)] + [_table(r) for r in repeats]
    if pose_var is None:
        varying = varying_pose_vars(meas[0])
        if not varying:
            raise ReportError(f"{meas[0].source}: no pose variable varies across configurations")
        pose_var = varying[0]
    return plots.plot_freq_vs_pose(meas, _named(predicted), pose_var, pose_unit(pose_var), title=title)


def plot_gap(diagnosis: Diagnosis | Mapping | PathLike, title: str = "") -> Figure:
    """Per-mode relative frequency error [%] before and after the diagnosed effect (a :func:`diagnose`
    result, a parsed diagnosis.json or its path)."""
    from flexmodal.reports import plots

    return plots.plot_gap(_diagnosis(diagnosis), title=title)


def _diagnosis(diagnosis: Diagnosis | Mapping | PathLike) -> Diagnosis:
    """A :func:`diagnose` result as it is, or read from a parsed diagnosis.json or its path
    (ReportError naming the key that does not fit docs/formats.md)."""
    from flexmodal.compare.errors import CompareError
    from flexmodal.compare.result import Diagnosis
    from flexmodal.reports.errors import ReportError

    if isinstance(diagnosis, str | Path):
        return read_diagnosis(diagnosis)
    if isinstance(diagnosis, Mapping):
        try:
            return Diagnosis.from_dict(dict(diagnosis))
        except CompareError as exc:
            raise ReportError(str(exc)) from None
    return diagnosis


# -- report ----------------------------------------------------------------------------------------

def report(out: PathLike, *, runs: Sequence[PathLike | tuple[PathLike, str]] = (),
           measured: ModalTable | PathLike | None = None, repeats: Sequence[ModalTable | PathLike] = (),
           predictions: Sequence[ModalTable | PathLike | tuple[str, ModalTable]] = (),
           diagnosis: Diagnosis | Mapping | PathLike | None = None,
           rig: Rig | PathLike | None = None, title: str = "flexmodal validation report",
           oma_fmin: float | None = None, oma_fmax: float | None = None,
           fmin: float | None = None, fmax: float | None = None,
           progress: Callable[[str], None] | None = None) -> Path:
    """Write the self-contained HTML validation report ``out`` (its folder must exist; checked before
    any work) and return its path.

    ``runs``: HDF5 files (all their runs), ``FILE::RUN_ID`` or (file, id); their stored FRFs are shown
    with the stabilisation diagram of their identification (:func:`identify` in ``fmin``..``fmax`` [Hz],
    as the measured table was identified, so diagram, caption and table agree); a
    run without FRFs that is output-only (operational, or no force channel) with its FDD singular
    values and SSI-cov stabilisation diagram (``modal.oma.output_only_results``, docs/oma.md), both
    identified in the band ``oma_fmin``..``oma_fmax`` [Hz] (``identify --fmin/--fmax``; default the
    whole record).
    ``measured``/``repeats``/``predictions``: modal tables; ``diagnosis``: a :func:`diagnose` result,
    a parsed diagnosis.json, or its path; ``rig``: draws the measured shapes on the arm.  Everything
    is computed here; ``reports.html`` only renders it."""
    from flexmodal.reports.errors import ReportError
    from flexmodal.valid_output import output_file

    output_file(out, ReportError, "report (--out)")
    from flexmodal.compare.tables import compare_tables, ordered_configs, table_name
    from flexmodal.daq.store import expand_runs
    from flexmodal.modal.errors import ModalError
    from flexmodal.modal.oma import default_method, output_only_results
    from flexmodal.modal.runs_io import read_frf
    from flexmodal.modal.sources import identify_frf
    from flexmodal.reports.html import write_report
    from flexmodal.reports.runs import RunSummary

    if not (runs or measured is not None or predictions or diagnosis is not None):
        raise ReportError("report: nothing to report (give RUN.h5 files, --measured, --pred or --diagnosis)")
    for name, value in (("oma_fmin", oma_fmin), ("oma_fmax", oma_fmax), ("fmin", fmin), ("fmax", fmax)):
        if value is not None and not (isinstance(value, int | float) and 0 < value < float("inf")):
            raise ReportError(f"report: {name} = {value!r} must be a positive number of Hz")
    if oma_fmin is not None and oma_fmax is not None and oma_fmin >= oma_fmax:
        raise ReportError(f"report: oma_fmin = {oma_fmin:g} Hz must be below oma_fmax = {oma_fmax:g} Hz")
    if fmin is not None and fmax is not None and fmin >= fmax:
        raise ReportError(f"report: fmin = {fmin:g} Hz must be below fmax = {fmax:g} Hz")
    step = progress or (lambda _msg: None)
    summaries = []
    for path, run_id in expand_runs(runs):
        step(f"reading and identifying {path.name}::{run_id}")
        run, frf = read_run(path, run_id), read_frf(path, run_id)
        modes = oma = None
        if frf is not None:
            try:
                modes = identify_frf(frf, fmin=fmin, fmax=fmax)
            except ModalError as exc:
                modes = str(exc)
        elif default_method([c.kind for c in run.channels], run.excitation) == "ssi":
            oma = output_only_results(run.samples, run.sample_rate_hz, [c.name for c in run.channels],
                                      [c.kind for c in run.channels], fmin=oma_fmin, fmax=oma_fmax,
                                      where=f"{path.name}::{run_id}")
        summaries.append(RunSummary(run, frf, modes, oma))
    meas = _table(measured) if measured is not None else None
    named = _named(predictions)
    comparison = None
    if meas is not None and named:
        step("comparing modes")
        comparison = compare_tables(meas, named, measured_name=table_name(meas, "experiment"))
    rig = _rig(rig) if rig is not None else None
    shapes: dict[str, object] = {}
    common = [s.name for s in rig.sensors if s.name in meas.sensors] if rig is not None and meas else []
    if len(common) >= 2:
        from flexmodal.models.arm_shapes import arm_modes

        step("solving the FE model for the mode shapes")
        configs = ordered_configs(meas)
        for config in list(dict.fromkeys([configs[0], configs[-1]]))[:SHAPE_CONFIGS]:
            pose = meas.pose(config)
            missing = [v for v in rig.pose_variables if v not in pose]
            shapes[config] = (f"No mode shapes drawn for {config}: the measured table gives no "
                              f"pose.{missing[0]} for the rig") if missing else arm_modes(rig, pose, common)
    inputs = [path for path, _ in expand_runs(runs)]
    inputs += [t.source for t in ([meas] if meas is not None else []) + [_table(r) for r in repeats]]
    inputs += [t.source for _, t in named]
    inputs += [diagnosis] if isinstance(diagnosis, str | Path) else []
    inputs += [rig.source] if rig is not None else []
    return write_report(out, runs=summaries, comparison=comparison, measured=meas,
                        repeats=[_table(r) for r in repeats], predictions=named, shapes=shapes,
                        diagnosis=_diagnosis(diagnosis) if diagnosis is not None else None,
                        rig_name=getattr(rig, "name", ""), title=title, inputs=inputs, progress=progress)


def report_pdf(html: PathLike, pdf: PathLike | None = None) -> Path:
    """Print the HTML report ``html`` to ``pdf`` (default: beside it, ``.pdf``) with headless Chromium,
    every run's block opened, tables whole with repeated headers; returns the PDF's path.  ReportError
    (one line) where no Chromium is installed."""
    from flexmodal.reports.errors import ReportError
    from flexmodal.reports.pdf import print_pdf
    from flexmodal.valid_output import output_file

    target = output_file(Path(html).with_suffix(".pdf") if pdf is None else pdf, ReportError, "PDF report")
    return print_pdf(html, target)
