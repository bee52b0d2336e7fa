"""From an identify INPUT (HDF5 run file or UFF file) to FRFs and on to the modal table."""

from __future__ import annotations

from pathlib import Path

import h5py
import pandas as pd

from flexmodal.modal.compute import compute_frf, frf_of_record
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.identify import Modes, identify, modes_table
from flexmodal.modal.runs_io import read_frf
from flexmodal.modal.table import ModalTable


def _driving_point(run, result: FrfResult) -> int | None:
    """Output row measured where (location and direction) the first force acts, if any."""
    by_name = {c.name: c for c in run.channels}
    force = by_name.get(result.inputs[0]) if result.inputs else None
    if force is None or not force.location:
        return None
    for j, name in enumerate(result.outputs):
        c = by_name.get(name)
        if c is not None and c.location == force.location and c.direction == force.direction:
            return j
    return None


def hdf5_frfs(path: str | Path, run_id: str | None = None):
    """Yield (run, FrfResult) for the runs of an HDF5 file, stored FRFs first, else computed."""
    from flexmodal.daq.store import list_runs, read_run

    ids = list_runs(path)
    if run_id is not None:
        if run_id not in ids:
            raise ModalError(f"{path}: no run {run_id!r} (runs: {', '.join(ids) or 'none'})")
        ids = [run_id]
    if not ids:
        raise ModalError(f"{path}: holds no runs under /runs")
    for rid in ids:
        run = read_run(path, rid)
        yield run, (read_frf(path, rid) or compute_frf(run))


def _modes(result: FrfResult, *, driving_point: int | None = None, decay_rate_per_s: float | None = None,
           **options) -> Modes:
    """Modes of FRFs; ``decay_rate_per_s`` (1/s) overrides the exponential window the FRFs record."""
    decay = result.decay_rate_per_s if decay_rate_per_s is None else decay_rate_per_s
    return identify(result.freq_hz, result.H, coherence=result.coherence,
                    quantity=result.quantity if result.quantity in ("accelerance", "mobility", "receptance")
                    else "accelerance", decay_rate_per_s=decay, driving_point=driving_point, **options)


def identify_input(path: str | Path, *, method: str = "lscf", fmin: float | None = None,
                   fmax: float | None = None, max_order: int | None = None, run_id: str | None = None,
                   **identify_options) -> tuple[ModalTable, dict[str, tuple[Modes, tuple[str, ...]]]]:
    """The modal table of INPUT and, per configuration, the identified modes and output names.
    ``identify_options``: ``poles_hz``, ``thresholds``, ``decay_rate_per_s`` of
    :func:`modal.identify.identify` (the last overriding the FRFs' own exponential window)."""
    p = Path(path)
    if not p.is_file():
        raise ModalError(f"{p}: input not found")
    options = {"method": method, "fmin": fmin, "fmax": fmax, "max_order": max_order, **identify_options}
    found: dict[str, tuple[Modes, tuple[str, ...]]] = {}
    tables = []
    if h5py.is_hdf5(p):
        for run, result in hdf5_frfs(p, run_id):
            modes = _modes(result, driving_point=_driving_point(run, result), **options)
            found[run.run_id] = (modes, result.outputs)
            tables.append(modes_table(modes, result.outputs, config=run.run_id, pose=run.pose).frame)
    else:
        from flexmodal.modal.uff import UffFrfs, read_uff

        data = read_uff(p)
        if isinstance(data, UffFrfs):
            result = FrfResult(data.freq_hz, data.H, None, "stored", "", 0, 0, float("nan"), data.quantity,
                               data.outputs, data.inputs)
        else:
            exc = "impact" if _impulsive(data.samples[:, list(data.kinds).index("force")]) else "random"
            result = frf_of_record(data.samples, data.sample_rate_hz, data.names, data.kinds,
                                   excitation=exc, where=str(p))
        modes = _modes(result, **options)
        found[p.stem] = (modes, result.outputs)
        tables.append(modes_table(modes, result.outputs, config=p.stem).frame)
    return ModalTable.from_frame(pd.concat(tables, ignore_index=True), str(p)), found


def _impulsive(force) -> bool:
    """A force record is an impact when its peak is far above its rms (crest factor above 8)."""
    f = force - force.mean()
    return float(abs(f).max()) > 8 * float((f ** 2).mean() ** 0.5)
