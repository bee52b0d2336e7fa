"""One interface over the model packages: a rig and poses in, a modal table (docs/formats.md) out.

Models: ``fe`` (planar frame, models/frame.py), ``assumed-modes`` (exact beam eigenfunctions of the arm
as one straight uniform beam), ``lumped-mass`` (seed 003 flexibility matrix, planar coordinates) and
``blevins`` (closed-form table).  Rigid-body (0 Hz) modes are left out, so ``mode`` counts elastic modes
in every source.  Shapes are displacements at the rig's sensors along their directions, mass-normalised
(kg^-1/2) with the largest-magnitude sensor component positive; Blevins gives frequencies only.

External predictions (e.g. an ANSYS export) are just modal-table CSVs: ``load_external`` reads one and
fills a ``source`` column so it compares like any model here.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import numpy as np

from flexmodal.checked_io.blas import one_blas_thread
from flexmodal.contract.mac import largest_positive
from flexmodal.contract.table import POSE_PREFIX, SHAPE_PREFIX, ModalTable
from flexmodal.models.errors import ModelError
from flexmodal.models.registry import MODELS
from flexmodal.models.rig import Rig

RIGID_HZ = 1e-3  # modes below this are rigid-body motion
FE_CHUNK = 256  # poses assembled together by the frame FE
Result = tuple[np.ndarray, np.ndarray | None]  # frequencies [Hz], shapes [n_sensors, n_modes] or None


def _elastic(freq_hz: np.ndarray, shapes: np.ndarray | None, n_modes: int, where: str) -> Result:
    keep = np.flatnonzero(freq_hz >= RIGID_HZ)[:n_modes]
    if keep.size < n_modes:
        raise ModelError(f"{where}: only {keep.size} elastic modes available, asked for {n_modes}")
    return freq_hz[keep], None if shapes is None else shapes[:, keep]


def solve_fe(rig: Rig, poses: list[Mapping[str, float]], n_modes: int, options: Mapping) -> Iterator[Result]:
    """Frame FE, assembled in chunks of poses (models.frame.assemble_many), one eigensolve per pose; large
    frames are solved in a worker process that Ctrl-C abandons at once (models.eigen_worker)."""
    from flexmodal.models.eigen_worker import FrameSolver
    from flexmodal.models.frame import assemble_many

    mechanisms = 3 + sum(j.kind != "rigid" for j in rig.joints)  # at most this many rigid-body modes
    with FrameSolver() as solve:
        for start in range(0, len(poses), FE_CHUNK):
            for system in assemble_many(rig, poses[start:start + FE_CHUNK], options.get("elements_per_link"),
                                        bool(options.get("lumped_mass", False))):
                modes = solve(system, min(n_modes + mechanisms, system.n_dof))
                yield _elastic(modes.freq_hz, modes.sensor_shapes, n_modes, f"{rig.source}: model 'fe'")


def _one_by_one(solve: Callable[[Rig, Mapping[str, float], int, Mapping], Result]) -> Callable:
    def run(rig: Rig, poses: list[Mapping[str, float]], n_modes: int, options: Mapping) -> Iterator[Result]:
        return (solve(rig, pose, n_modes, options) for pose in poses)
    return run


def _assumed(rig: Rig, pose: Mapping[str, float], n_modes: int, options: Mapping) -> Result:
    from flexmodal.models.assumed_modes import beam_modes
    from flexmodal.models.straight_beam import straight_beam

    sb = straight_beam(rig, pose, "assumed-modes")
    modes = beam_modes(sb.beam, sb.left, sb.right, n_modes + 2)
    shapes = modes.shape(np.array(sb.sensor_x_m)) * np.array(sb.sensor_transverse, float)[:, None]
    freq, shapes = _elastic(modes.freq_hz, shapes, n_modes, f"{rig.source}: model 'assumed-modes'")
    return freq, shapes * largest_positive(shapes)


def _lumped(rig: Rig, pose: Mapping[str, float], n_modes: int, options: Mapping) -> Result:
    from flexmodal.models.lumped_mass import lumped_mass_modes

    masses, coordinates = options.get("masses_per_link"), options.get("coordinates")
    modes = lumped_mass_modes(rig, pose, n_modes, 4 if masses is None else int(masses),
                              "planar" if coordinates is None else str(coordinates))
    return modes.freq_hz, modes.sensor_shapes


def _blevins(rig: Rig, pose: Mapping[str, float], n_modes: int, options: Mapping) -> Result:
    from flexmodal.models.blevins import beam_frequencies_hz
    from flexmodal.models.straight_beam import straight_beam

    sb = straight_beam(rig, pose, "blevins")
    if sb.condition is None:
        raise ModelError(f"{rig.source}: model 'blevins' has no closed form for this arm's end masses or "
                         "spring base (use --model assumed-modes)")
    b = sb.beam
    return beam_frequencies_hz(sb.condition, b.length_m, b.EI_Nm2, b.mass_per_m_kg, n_modes), None


# the built-in entries of models.registry.MODELS (solve_fe above: every pose at once)
solve_assumed_modes = _one_by_one(_assumed)
solve_lumped_mass = _one_by_one(_lumped)
solve_blevins = _one_by_one(_blevins)


BUILT_IN_MODELS = ("fe", "assumed-modes", "lumped-mass", "blevins")
#: the built-in model each option belongs to; given (not None or False) to another built-in model it was
#: ignored in silence (predict --model fe --masses-per-link 3, --model lumped-mass --elements 5)
OPTION_MODELS = {"elements_per_link": "fe", "lumped_mass": "fe", "masses_per_link": "lumped-mass",
                 "coordinates": "lumped-mass"}


def _check_options(options: Mapping[str, object], model: str, builtin: bool) -> None:
    """The model options as ``flexmodal predict`` takes them (an unknown name, elements 0 or a count that
    is not whole ran in silence from the API, and so did an option of another model): ModelError naming
    the option.  A plug-in model (not ``builtin``) may read options of its own names."""
    from flexmodal.checked_io import options as opt
    from flexmodal.models.rig_schema import MAX_ELEMENTS

    kinds = {"elements_per_link": opt.integer(1, MAX_ELEMENTS), "masses_per_link": opt.integer(1, 1000)}
    for name, value in options.items():
        if name in kinds:
            if value is not None:
                opt.given(value, kinds[name], f"predict: {name}", ModelError)
        elif name == "coordinates":
            if value not in (None, "planar", "transverse"):
                raise ModelError(f"predict: coordinates = {value!r} is not planar or transverse")
        elif name != "lumped_mass" and builtin:
            raise ModelError(f"predict: unknown option {name!r} (options: elements_per_link, lumped_mass, "
                             "masses_per_link, coordinates)")
        owner = OPTION_MODELS.get(name, model)
        if builtin and owner != model and value is not None and value is not False:
            raise ModelError(f"predict: {name} = {value!r} is an option of model '{owner}'; model "
                             f"'{model}' does not use it (leave it out)")


def predict(rig: Rig, poses: Mapping[str, Mapping[str, float]], model: str = "fe", n_modes: int = 4, *,
            source: str | None = None, progress: Callable[[str], None] | None = None,
            **options: object) -> ModalTable:
    """Predicted modes of ``rig`` for each ``{config: pose}`` (degrees, kg) as a ModalTable.

    ``options``: ``elements_per_link``, ``lumped_mass`` (fe); ``masses_per_link``, ``coordinates``
    (lumped-mass).  ``source`` defaults to the model name.  ``progress(config)`` is called after each pose.
    """
    solve = MODELS.entry(model)
    if isinstance(n_modes, bool | np.bool_) or not isinstance(n_modes, numbers.Integral) or n_modes < 1:
        raise ModelError(f"number of modes must be a whole number >= 1 (got {n_modes!r})")
    n_modes = int(n_modes)   # numpy's whole numbers too (np.int64(2) was refused as "not a whole number")
    _check_options(options, model, builtin=solve in {MODELS.entry(m) for m in BUILT_IN_MODELS})
    records = []
    # a model may solve lazily, pose by pose: progress is told as each pose comes (a list of all results
    # first told it only at the end: a bar stood at 0 for 28 s, then jumped to 6/6); a generator is
    # closed on any error, so that a model's worker process ends with it
    with one_blas_thread():  # many small dense eigenproblems: threads contend
        results = iter(solve(rig, list(poses.values()), n_modes, options))
        try:
            for (config, pose), (freq, shapes) in zip(poses.items(), results, strict=True):
                for i, f in enumerate(freq):
                    row: dict[str, object] = {"config": str(config), "mode": i + 1, "freq_hz": float(f),
                                              "source": source or model}
                    row.update({POSE_PREFIX + k: v for k, v in pose.items()})
                    if shapes is not None:
                        row.update({SHAPE_PREFIX + s.name: float(shapes[k, i])
                                    for k, s in enumerate(rig.sensors)})
                    records.append(row)
                if progress is not None:
                    progress(str(config))
        finally:
            getattr(results, "close", lambda: None)()
    if not records:
        raise ModelError(f"{rig.source}: no poses to predict")
    return ModalTable.from_records(records, f"{rig.name}:{model}")


def load_external(path: str | Path, source: str | None = None) -> ModalTable:
    """A modal table written elsewhere (e.g. ANSYS); ``source`` (default: file stem) fills a missing
    ``source`` column so it compares like any other model."""
    table = ModalTable.read_csv(path)
    frame = table.frame
    if "source" not in frame.columns or frame["source"].isna().all():
        frame = frame.assign(source=source or Path(path).stem)
    return ModalTable.from_frame(frame, table.source)

