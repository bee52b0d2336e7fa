"""Structure of a stored run (docs/hdf5-format.md): checked before any of it is read.

A run file written by another tool, an older flexmodal or a hand edit may lack an attribute, hold one
of the wrong type, or have a dataset of the wrong rank or type.  :func:`check_run_group` inspects the
group's attributes and the datasets' shapes and types (no sample is read) and raises one DaqError
naming the file, run and item, instead of whatever numpy, json or h5py would raise later.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import h5py
import numpy as np

from flexmodal.daq.errors import DaqError
from flexmodal.daq.h5file import open_read

CHANNEL_KINDS = ("acceleration", "force", "strain", "encoder", "voltage", "other")
EVENT_KINDS = ("trigger", "gap", "overload", "corrupt", "reconnect", "note", "device_lost", "overrun",
               "stopped")
EXCITATIONS = ("impact", "random", "sweep", "free-decay", "operational")
CHANNEL_FIELDS = ("name", "kind", "unit", "sensitivity", "sensitivity_unit", "location", "direction")
EVENT_DETAIL_BYTES = 200


def utf8(n_bytes: int) -> np.dtype:
    """A fixed-width UTF-8 string type of ``n_bytes`` (at least 1) for HDF5 compound tables."""
    return h5py.string_dtype("utf-8", max(int(n_bytes), 1))


EVENT_DTYPE = np.dtype([("kind", utf8(16)), ("sample_index", "i8"), ("count", "i8"),
                        ("detail", utf8(EVENT_DETAIL_BYTES))])

RUN_FIELDS = {"channels": CHANNEL_FIELDS, "events": EVENT_DTYPE.names}
NUMERIC_FIELDS = {"sensitivity": "f", "sample_index": "i", "count": "i"}


def _text(value: object) -> str | None:
    if isinstance(value, bytes):
        try:
            return value.decode()
        except UnicodeDecodeError:
            return None
    return value if isinstance(value, str) else None


def _check_attrs(g: h5py.Group, where: str) -> None:
    a = g.attrs
    for key in ("sample_rate_hz", "start_time", "excitation", "pose"):
        if key not in a:
            raise DaqError(f"{where}: missing attribute {key!r}")
    rate = a["sample_rate_hz"]
    if np.ndim(rate) != 0 or not isinstance(rate, (int, float, np.integer, np.floating)) \
            or isinstance(rate, bool | np.bool_) or not math.isfinite(float(rate)) or float(rate) <= 0:
        raise DaqError(f"{where}: attribute sample_rate_hz = {rate!r} is not a sample rate > 0 Hz")
    if _text(a["start_time"]) is None:
        raise DaqError(f"{where}: attribute start_time = {a['start_time']!r} is not a text")
    excitation = _text(a["excitation"])
    if excitation not in EXCITATIONS:
        raise DaqError(f"{where}: attribute excitation = {a['excitation']!r} is not one of "
                       f"{', '.join(EXCITATIONS)}")
    pose_text = _text(a["pose"])
    try:
        pose = json.loads(pose_text) if pose_text is not None else None
    except json.JSONDecodeError:
        pose = None
    if not isinstance(pose, dict):
        raise DaqError(f"{where}: attribute pose = {a['pose']!r} is not a JSON object string")


def _table(g: h5py.Group, name: str, where: str) -> h5py.Dataset:
    if name not in g or not isinstance(g[name], h5py.Dataset):
        raise DaqError(f"{where}: has no {name!r} dataset")
    d = g[name]
    fields = d.dtype.names or ()
    if d.ndim != 1 or not fields:
        raise DaqError(f"{where}: {name!r} is not a table of records (shape {d.shape}, type {d.dtype})")
    for field in RUN_FIELDS[name]:
        if field not in fields:
            raise DaqError(f"{where}: {name!r} table has no field {field!r}")
        kind = d.dtype[field].kind
        want = NUMERIC_FIELDS.get(field)
        ok = kind in ("iu" if want == "i" else "fiu") if want else kind in "SOU"
        if not ok:
            raise DaqError(f"{where}: {name!r} field {field!r} has type {d.dtype[field]} "
                           f"(expected {'a number' if want else 'text'})")
    return d


def check_run_group(g: h5py.Group, where: str) -> None:
    """Raise DaqError unless ``g`` has the attributes and datasets of a run (``where`` names it)."""
    if not isinstance(g, h5py.Group):
        raise DaqError(f"{where}: is not a group")
    _check_attrs(g, where)
    channels = _table(g, "channels", where)
    _table(g, "events", where)
    if "samples" not in g or not isinstance(g["samples"], h5py.Dataset):
        raise DaqError(f"{where}: has no 'samples' dataset")
    s = g["samples"]
    if s.ndim != 2 or s.dtype.kind not in "fiu":
        raise DaqError(f"{where}: 'samples' must be a 2-D numeric dataset (shape {s.shape}, type {s.dtype})")
    if s.shape[1] != channels.shape[0] or s.shape[1] == 0:
        raise DaqError(f"{where}: 'samples' has {s.shape[1]} columns but {channels.shape[0]} channels")


def check_run_file(path: str | Path, run_id: str) -> None:
    """Open ``path`` (:func:`flexmodal.daq.h5file.open_read`) and check run ``run_id`` without reading
    its samples: lets a command refuse a bad run file before it starts working."""
    with open_read(path) as f:
        key = f"runs/{run_id}"
        if key not in f:
            raise DaqError(f"{path}: no run {run_id!r}")
        check_run_group(f[key], f"{path}: run {run_id!r}")
