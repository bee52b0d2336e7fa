"""From an identify INPUT (HDF5 run file or UFF file) to FRFs and on to the modal table."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from flexmodal.checked_io.errors import FlexmodalError
from flexmodal.checked_io.progress import progress_bar
from flexmodal.checked_io.text import naming, regular_file
from flexmodal.contract.table import ModalTable
from flexmodal.modal.compute import compute_frf, frf_of_record
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import FrfResult
from flexmodal.modal.identify import Modes, identify, modes_table
from flexmodal.modal.oma import default_method, identify_output_only, output_channels
from flexmodal.modal.registry import output_only
from flexmodal.modal.runs_io import read_frf
from flexmodal.modal.sweep import sweep_plan


def _driving_point(run, result: FrfResult) -> int | None:
    """Output row measured where (location and direction, without case or surrounding spaces) the
    first force acts, if any, and only when the forces are given in N and the responses in m/s^2
    (:func:`given_unit`, the units :func:`si_frf` brings them to): mass
    normalisation takes the accelerance as (m/s^2)/N, so a run stored in g or kN would get shapes off
    by sqrt(9.81) or sqrt(1000) in silence (they are scaled to unit maximum instead, as without a
    driving point)."""
    from flexmodal.daq.session import unit_factor

    by_name = {c.name: c for c in run.channels}
    if not all(n in by_name for n in (*result.outputs, *result.inputs)) or not result.inputs:
        return None
    force = by_name[result.inputs[0]]
    given = [given_unit([by_name[n].unit for n in names]) for names in (result.inputs, result.outputs)]
    if not force.location or None in given or unit_factor(given[0], "N") != 1.0:
        return None
    place = lambda c: (c.location.strip().casefold(), c.direction.strip().casefold())   # 'Transverse'
    for j, name in enumerate(result.outputs):
        if place(by_name[name]) == place(force):
            return j if unit_factor(given[1], "m/s^2") == 1.0 else None
    return None


def hdf5_run_ids(path: str | Path, run_id: str | None = None) -> list[str]:
    """The run ids of an HDF5 file (only ``run_id`` if given; ModalError when there is none)."""
    from flexmodal.daq.store import list_runs

    ids = list_runs(path)
    if run_id is not None:
        if run_id not in ids:
            raise ModalError(f"{path}: no run {run_id!r} (runs: {', '.join(ids) or 'none'})")
        ids = [run_id]
    if not ids:
        raise ModalError(f"{path}: holds no runs under /runs")
    return ids


def hdf5_runs(path: str | Path, run_id: str | None = None):
    """Yield the runs of an HDF5 file (only ``run_id`` if given)."""
    from flexmodal.daq.store import read_run

    for rid in hdf5_run_ids(path, run_id):
        yield read_run(path, rid)


def by_reciprocity(result: FrfResult) -> FrfResult:
    """FRFs with more references than responses (a roving-hammer test: one accelerometer, the hammer
    at each point) read by Maxwell-Betti reciprocity, ``H_jk = H_kj``: the hammer points become the
    outputs (the points of the shapes) and the accelerometers the references, so pLSCF fits them with
    as few references as there are sensors.  Other FRFs are returned as they are."""
    n_out, n_in = result.H.shape[:2]
    if n_in <= n_out:
        return result
    coh = result.coherence
    if coh is not None:   # per response; the hammer points share it
        coh = np.broadcast_to(np.mean(coh, axis=0), (n_in, coh.shape[-1])).copy()
    return dataclasses.replace(result, H=np.ascontiguousarray(result.H.transpose(1, 0, 2)), coherence=coh,
                               outputs=result.inputs, inputs=result.outputs)


def excitation_of(result: FrfResult) -> str | None:
    """How FRFs were made, for advice on resolution: ``impact`` (hit records, force/exponential
    windows), ``sweep`` (each sweep's whole record), ``random`` (Welch-averaged: random runs, and
    sweep runs given an nfft), None (stored FRFs, e.g. UFF, or FRFs given as arrays: api.frf_from_arrays)."""
    if result.estimator in ("stored", "given"):
        return None
    if result.provenance.get("excitation") == "sweep":
        return "sweep"
    return "impact" if "force" in result.window or "exponential" in result.window else "random"


def identify_frf(result: FrfResult, *, driving_point: int | None = None,
                 decay_rate_per_s: float | None = None, **options) -> Modes:
    """Modes of FRFs in memory (``modal.identify.identify`` with the result's quantity; ``options`` as
    there); ``decay_rate_per_s`` (1/s) overrides the exponential window the FRFs record."""
    from flexmodal.modal.uncertainty import welch_noise, with_uncertainty

    decay = result.decay_rate_per_s if decay_rate_per_s is None else decay_rate_per_s
    options.setdefault("excitation", excitation_of(result))
    quantity = result.quantity if result.quantity in ("accelerance", "mobility", "receptance") \
        else "accelerance"
    modes = identify(result.freq_hz, result.H, coherence=result.coherence, quantity=quantity,
                     decay_rate_per_s=decay, driving_point=driving_point, **options)
    # freq_std_hz / damping_std (issue 26): the poles refined with their FRF-noise uncertainty (and
    # with the window's leakage modelled for Welch-averaged FRFs)
    welch = welch_noise(result.window, result.nfft, float(result.provenance.get("overlap", 0.5))) \
        if excitation_of(result) == "random" else None
    return with_uncertainty(modes, result.freq_hz, result.H, result.coherence, result.n_averages, quantity,
                            decay, welch)


def identify_input(path: str | Path, *, method: str | None = None, fmin: float | None = None,
                   fmax: float | None = None, max_order: int | None = None, run_id: str | None = None,
                   references: Sequence[str] | None = None, failed: list | None = None, quiet: bool = True,
                   **identify_options) -> tuple[ModalTable, dict[str, tuple[Modes, tuple[str, ...]]]]:
    """The modal table of INPUT and, per configuration, the identified modes and output names.

    ``method`` None: output-only ``ssi`` for operational runs and records without a force channel,
    else ``lscf`` (modal.oma.default_method); ``references`` name the reference outputs of ssi/fdd.
    ``identify_options``: ``poles_hz``, ``thresholds``, ``decay_rate_per_s`` of
    :func:`modal.identify.identify` (the last overriding the FRFs' own exponential window).
    ``failed``: a list that gets (``FILE:RUN_ID``, error) for each bad run of an HDF5 file (bad input:
    a FlexmodalError), which is then skipped, not raised (when every run is bad, the first error is
    raised).  A progress bar of the runs on stderr unless ``quiet`` (checked_io.progress)."""
    p = regular_file(path, ModalError, "RUN.h5 or UFF input")
    options = {"fmin": fmin, "fmax": fmax, "max_order": max_order, **identify_options}
    oma = {"fmin": fmin, "fmax": fmax, "max_order": max_order, "references": references}
    found: dict[str, tuple[Modes, tuple[str, ...]]] = {}
    tables = []
    if h5py.is_hdf5(p):
        from flexmodal.daq.store import read_run

        chosen_of, bad = [], []
        ids = hdf5_run_ids(p, run_id)
        with progress_bar(len(ids), "identify", quiet) as advance:
            for rid in ids:
                try:
                    run = read_run(p, rid)
                    chosen = method or default_method([c.kind for c in run.channels], run.excitation)
                except FlexmodalError as exc:
                    _skip(failed, bad, f"{p}:{rid}", exc, advance)
                    continue
                chosen_of.append(chosen)
                if len(chosen_of) == 1 and not output_only(chosen) and method is not None:
                    _references_used(p, references, chosen_of)   # one method for all: said before any work
                try:
                    modes, outputs = _identify_run(p, run, chosen, options, oma)
                except FlexmodalError as exc:
                    _skip(failed, bad, f"{p}:{rid}", exc, advance)
                    continue
                found[rid] = (modes, outputs)
                tables.append(modes_table(modes, outputs, config=rid, pose=run.pose).frame)
                advance()
        if bad and not found:
            raise bad[0][1]
        if failed is not None:
            failed += bad
        _references_used(p, references, chosen_of)
    else:
        from flexmodal.modal.uff import UffFrfs, read_uff

        uff_without_run(p, run_id)
        packed = _compressed(p)
        if packed is not None:  # a gzipped or damaged run store: not "line 1: text outside any dataset"
            raise ModalError(f"{p}: neither an HDF5 file (no HDF5 signature) nor UFF text ({packed})")
        data = read_uff(p)
        chosen = method or ("lscf" if isinstance(data, UffFrfs) else default_method(data.kinds))
        _references_used(p, references, [chosen if not isinstance(data, UffFrfs) else "lscf"])
        if not isinstance(data, UffFrfs) and output_only(chosen):
            res, outputs = identify_output_only(data.samples, data.sample_rate_hz, data.names, data.kinds,
                                                method=chosen, where=str(p), **oma)
            found[p.stem] = (res.modes, outputs)
            table = modes_table(res.modes, outputs, config=p.stem)
            return ModalTable.from_frame(table.frame, str(p)), found
        if isinstance(data, UffFrfs):
            result = FrfResult(data.freq_hz, data.H, None, "stored", "", 0, 0, float("nan"), data.quantity,
                               data.outputs, data.inputs, data.decay_rate_per_s)
        else:
            result = _uff_record_frfs(p, data)
        result = by_reciprocity(result)
        with naming(p, ModalError):
            modes = identify_frf(result, method=chosen, **options)
        found[p.stem] = (modes, result.outputs)
        tables.append(modes_table(modes, result.outputs, config=p.stem).frame)
    return ModalTable.from_frame(pd.concat(tables, ignore_index=True), str(p)), found


def uff_without_run(path: Path, run_id: str | None) -> None:
    """ModalError when a run is chosen (``--run``) for ``path``, a UFF file: runs are the parts of an
    HDF5 run store, and a UFF file is one record (the choice was ignored without a word)."""
    if run_id is not None:
        raise ModalError(f"{path}: --run {run_id}: --run applies to HDF5 run stores (RUN.h5); this is a UFF "
                         "file, one record")


def _compressed(path: Path) -> str | None:
    """What ``path`` is when it is a packed file (:func:`~flexmodal.checked_io.uff_blocks.packed_format`),
    else None."""
    from flexmodal.checked_io.uff_blocks import packed_format

    with open(path, "rb") as fh:
        name = packed_format(fh.read(8))
    if name == "zip" and path.suffix.lower() == ".npz":   # not "unpack it": identify's own sidecar
        return "a NumPy .npz archive such as identify's stabilisation diagrams, not a record"
    return None if name is None else f"{name}-compressed: unpack it first"


def _skip(failed: list | None, bad: list, name: str, exc: FlexmodalError, advance) -> None:
    """Note bad run ``name`` in ``bad`` and go on, or raise its error when the caller takes no
    ``failed`` list."""
    if failed is None:
        raise exc
    bad.append((name, exc))
    advance()


#: the unit channels of one quantity stored in different units are brought to (modal.sources.si_factors)
SI_UNITS = {"acceleration": "m/s^2", "velocity": "m/s", "strain": "µε", "force": "N"}


def quantity_of(unit: str) -> str | None:
    """The quantity (a key of :data:`SI_UNITS`) ``unit`` has a known factor to, None when none.

    Examples
    --------
    >>> quantity_of("g"), quantity_of("microstrain"), quantity_of("lbf"), quantity_of("ft/s^2")
    ('acceleration', 'strain', 'force', None)
    """
    from flexmodal.daq.session import unit_factor

    return next((q for q, si in SI_UNITS.items() if unit_factor(unit, si) is not None), None)


def given_unit(units: Sequence[str]) -> str | None:
    """The one unit channels stored in ``units`` are given in: theirs when they share one (FRFs and shapes
    then stay in it, docs/hdf5-format.md), else the SI unit of their quantity (:data:`SI_UNITS`) when
    every unit has a known factor to it, else None (units of different or unknown quantities)."""
    from flexmodal.daq.session import unit_factor

    if all(unit_factor(u, units[0]) == 1.0 for u in units):
        return units[0]
    quantities = {quantity_of(u) for u in units}
    return SI_UNITS[quantities.pop()] if len(quantities) == 1 and None not in quantities else None


def si_factors(units: Sequence[str]) -> np.ndarray | None:
    """Factors [n] taking channels stored in ``units`` to their :func:`given_unit` when the units differ
    (all nan when there is none); None when they share one."""
    from flexmodal.daq.session import unit_factor

    if all(unit_factor(u, units[0]) == 1.0 for u in units):
        return None
    to = given_unit(units)
    return np.array([np.nan if to is None else unit_factor(u, to) for u in units], float)


def _si_factors(channels: Sequence, where: str, role: str = "response") -> np.ndarray | None:
    """:func:`si_factors` of the ``role`` (response or force) ``channels``: an output in g beside outputs
    in m/s^2 gave mode shapes of mixed units, off by 9.81 at that sensor, and a force in kN beside one in N
    FRFs off by 1000 for that input, with exit 0.  ModalError naming each channel's unit and quantity when
    the units differ and are not all of one quantity with known factors."""
    factors = si_factors([c.unit for c in channels])
    if factors is not None and np.isnan(factors).any():
        named = ", ".join(f"{c.name} ({c.unit or 'no unit'}: "
                          f"{quantity_of(c.unit) or 'no known factor to ' + ', '.join(SI_UNITS.values())})"
                          for c in channels)
        raise ModalError(f"{where}: the {role} channels are in different units ({named}), not all of one "
                         "quantity with known factors: the "
                         + ("mode shapes" if role == "response" else "FRFs of the inputs")
                         + " would mix the units (store them in one unit)")
    return factors


def si_frf(frf: FrfResult, channels: Sequence, where: str) -> FrfResult:
    """``frf`` with its rows (outputs) and columns (inputs), named among the run's ``channels``, brought
    to the SI unit of their quantity (m/s^2, N, ...) when the outputs or the inputs are stored in
    different units (:func:`_si_factors`), else as given."""
    by_name = {c.name: c for c in channels}
    if not all(o in by_name for o in (*frf.outputs, *frf.inputs)):
        return frf
    outs = _si_factors([by_name[o] for o in frf.outputs], where)
    ins = _si_factors([by_name[i] for i in frf.inputs], where, "force") if frf.inputs else None
    if outs is None and ins is None:
        return frf
    H = frf.H * (1.0 if outs is None else outs[:, None, None]) / (1.0 if ins is None else ins[None, :, None])
    return dataclasses.replace(frf, H=H)


def si_samples(samples, channels: Sequence, outputs: Sequence[int], where: str):
    """``samples`` [n_samples, n_channels] with the ``outputs`` columns brought to m/s^2 when those
    ``channels`` are stored in different units (:func:`_si_factors`; a copy in memory), else as given."""
    factors = _si_factors([channels[j] for j in outputs], where)
    if factors is None:
        return samples
    scaled = np.array(samples[()], float)
    scaled[:, list(outputs)] *= factors
    return scaled


def _identify_run(p: Path, run, chosen: str, options: dict, oma: dict) -> tuple[Modes, tuple[str, ...]]:
    """The modes of one run of ``p`` by method ``chosen`` and the outputs their shapes are given at
    (responses stored in different units brought to m/s^2 first, :func:`_si_factors`)."""
    names, kinds = [c.name for c in run.channels], [c.kind for c in run.channels]
    where = f"{p}:{run.run_id}"
    if output_only(chosen):
        samples = si_samples(run.samples, run.channels, output_channels(kinds), where)
        res, outs = identify_output_only(samples, run.sample_rate_hz, names, kinds, method=chosen,
                                         where=where, **oma)
        return res.modes, outs
    stored = si_frf(read_frf(p, run.run_id) or compute_frf(run), run.channels, where)
    result = by_reciprocity(stored)
    point = _driving_point(run, result) if result is stored else None
    with naming(where, ModalError):
        modes = identify_frf(result, driving_point=point, method=chosen, **options)
    return modes, result.outputs


def _references_used(p: Path, references: Sequence[str] | None, methods: Sequence[str]) -> None:
    """ModalError when ``references`` are given but no run of ``p`` is identified output-only (their
    method's): FRF methods take the force channels as references, and the option was ignored in
    silence."""
    if references and methods and not any(output_only(m) for m in methods):
        raise ModalError(f"{p}: --references name the reference outputs of ssi/fdd, but the input is "
                         f"identified with {methods[0]} from FRFs (whose references are the force channels); "
                         "use --method ssi or fdd, or leave --references out")


def _uff_record_frfs(p: Path, data) -> FrfResult:
    """FRFs of UFF time histories: one record per channel (sine sweeps: H1 of one rectangular segment
    per sweep, :mod:`modal.sweep`; else impact or random by the force's crest factor), or hits assembled from
    several records per channel (impact, each record starting at its hit's start)."""
    if "force" not in data.kinds:
        raise ModalError(f"{p}: no force channel among the time histories {', '.join(data.names)} (a force "
                         "is a dataset 58 ordinate of data type 13), so no FRF can be formed")
    if data.hit_len is None:
        forces = data.samples[:, [j for j, k in enumerate(data.kinds) if k == "force"]]
        starts = sweep_plan(forces)   # sine sweeps: one rectangular segment per sweep
        if starts is not None:
            return frf_of_record(data.samples, data.sample_rate_hz, data.names, data.kinds, sweeps=starts,
                                 where=str(p))
        force = forces[:, 0]
        if not _impulsive(force):
            return frf_of_record(data.samples, data.sample_rate_hz, data.names, data.kinds, where=str(p))
        from flexmodal.modal.impact import find_triggers

        first = find_triggers(force)   # a record that starts at its hit keeps what lies before it
        lead = min(0.02, first[0] / data.sample_rate_hz) if first.size else 0.02
        return frf_of_record(data.samples, data.sample_rate_hz, data.names, data.kinds, excitation="impact",
                             where=str(p), pretrigger_s=lead)
    n_hits = data.samples.shape[0] // data.hit_len
    if not data.triggers or len(data.triggers) != n_hits:
        raise ModalError(f"{p}: {n_hits} records per channel are read as impact hits, but the force shows "
                         f"a hit in {len(data.triggers or ())} of them")
    lead = min(t - k * data.hit_len for k, t in enumerate(data.triggers))   # samples before each impact
    return frf_of_record(data.samples, data.sample_rate_hz, data.names, data.kinds, excitation="impact",
                         where=str(p), triggers=list(data.triggers), pretrigger_s=lead / data.sample_rate_hz)


def _impulsive(force) -> bool:
    """A force record is an impact when its peak is far above its rms (crest factor above 8)."""
    f = force - force.mean()
    return float(abs(f).max()) > 8 * float((f ** 2).mean() ** 0.5)
