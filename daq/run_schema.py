"""Structure of a stored run (docs/hdf5-format.md): checked before any of it is read.

A run file written by another tool, an older flexmodal or a hand edit may lack an attribute, hold one
of the wrong type, or have a dataset of the wrong rank or type.  :func:`check_run_group` inspects the
group's attributes and the datasets' shapes and types (no sample is read) and raises one DaqError
naming the file, run and item, instead of whatever numpy, json or h5py would raise later.
"""

from __future__ import annotations

import math
import os
import sys
from datetime import datetime
from pathlib import Path

import h5py
import numpy as np

from flexmodal.checked_io.text import (
    available_memory_bytes,
    loads_json,
    name_fault,
    nfc,
    one_line,
    shown_value,
)
from flexmodal.daq.errors import DaqError
from flexmodal.daq.h5file import open_read

CHANNEL_KINDS = ("acceleration", "force", "strain", "encoder", "voltage", "other")
#: the units that say a channel's kind (normalised: "m/s2" and "m/s²" are "m/s^2", "μ" is "µ"); a unit of
#: one kind given to a channel of another (a force in m/s^2, an acceleration in N) is refused, any unit
#: not listed here is accepted for every kind (kind "other" takes every unit)
KIND_UNITS = {
    "force": ("N", "kN", "mN", "lbf"),
    "acceleration": ("m/s^2", "mm/s^2", "g"),
    "strain": ("µε", "ε", "ue", "με", "microstrain"),
    "encoder": ("deg", "rad", "rev"),
    "voltage": ("V", "mV", "µV"),
}


def kind_unit_fault(kind: str, unit: str) -> str:
    """Words for a channel ``unit`` that belongs to another kind than ``kind``, or "" when it fits."""
    u = unit.replace("m/s2", "m/s^2").replace("m/s²", "m/s^2").replace("μ", "µ").strip()
    owner = next((k for k, units in KIND_UNITS.items() if u in units), None)
    if owner is None or owner == kind or kind == "other" or kind not in KIND_UNITS:
        return ""
    return f"unit {unit!r} is a unit of {owner}, not of {kind} ({kind}: {', '.join(KIND_UNITS[kind])}, ...)"


EVENT_KINDS = ("trigger", "gap", "overload", "corrupt", "reconnect", "note", "device_lost", "overrun",
               "stopped")
EXCITATIONS = ("impact", "random", "sweep", "free-decay", "operational")
CHANNEL_FIELDS = ("name", "kind", "unit", "sensitivity", "sensitivity_unit", "location", "direction")
EVENT_DETAIL_BYTES = 200
SHORT_CHARS = 80  # a stored value quoted in an error line is cut to this length
MAX_SAMPLE_RATE_HZ = 1e9  # 1 GHz; a finite rate far above it (1e300) overflows the spectra's arithmetic
MAX_EVENT_SAMPLES = 1 << 48  # an event's sample_index or count: more than any run holds (9 years at 1 MHz);
#                              first + count of a gap 2^62 long overflowed int64 and the gap was not skipped


#: a transducer sensitivity (in its sensitivity_unit: mV/g, pC/N, V/µε, counts/rev) lies in this range:
#: 0, a negative or an infinite one is a typing mistake, not a calibration
MIN_SENSITIVITY, MAX_SENSITIVITY = 1e-12, 1e12


def sensitivity_fault(value: float) -> str:
    """Why ``value`` cannot be a transducer sensitivity, or "" when it can: a finite number from
    :data:`MIN_SENSITIVITY` to :data:`MAX_SENSITIVITY` (the sign of a sensor's axis is its
    ``direction``; a negative sensitivity turned every FRF of the channel by 180 degrees).

    Examples
    --------
    >>> sensitivity_fault(100.0), sensitivity_fault(4096)
    ('', '')
    >>> sensitivity_fault(-50.0)
    'sensitivity = -50 is not in [1e-12, 1e+12] (a calibration value > 0)'
    """
    try:
        number = float(value) if not isinstance(value, bool | np.bool_ | str | bytes) else None
    except (TypeError, ValueError):
        number = None
    if number is not None and MIN_SENSITIVITY <= number <= MAX_SENSITIVITY:
        return ""
    shown = repr(value) if number is None else f"{number:g}"
    return (f"sensitivity = {shown} is not in [{MIN_SENSITIVITY:g}, {MAX_SENSITIVITY:g}] (a calibration "
            "value > 0)")


def numeric_dtype(dtype: np.dtype, kinds: str = "fiu") -> bool:
    """Whether values of ``dtype`` are plain numbers of the numpy ``kinds``: an HDF5 enum (labelled
    states) reads back as integers but is refused, as are bools, strings, compounds and arrays.

    Examples
    --------
    >>> numeric_dtype(np.dtype("f4")), numeric_dtype(h5py.enum_dtype({"a": 0}, basetype="i1"))
    (True, False)
    """
    return dtype.kind in kinds and dtype.shape == () and h5py.check_enum_dtype(dtype) is None


def dtype_words(dtype: np.dtype) -> str:
    """``dtype`` as an error line names it: numpy's name, or 'HDF5 enum of int8' for an enum."""
    return f"HDF5 enum of {dtype}" if h5py.check_enum_dtype(dtype) is not None else str(dtype)


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
            return nfc(value.decode())
        except UnicodeDecodeError:
            return None
    return nfc(value) if isinstance(value, str) else None


def sample_rate_ok(rate_hz: float) -> bool:
    """Whether ``rate_hz`` is a usable sample rate: finite, above the subnormal numbers (whose inverse
    overflows) and at most :data:`MAX_SAMPLE_RATE_HZ`.

    Examples
    --------
    >>> sample_rate_ok(1024.0), sample_rate_ok(0.0), sample_rate_ok(5e-324), sample_rate_ok(1e300)
    (True, False, False, False)
    """
    return math.isfinite(rate_hz) and sys.float_info.min <= rate_hz <= MAX_SAMPLE_RATE_HZ


NUMBER_CLASSES = (h5py.h5t.INTEGER, h5py.h5t.FLOAT)   # HDF5 classes of a number (not ENUM: bools, labels)


def attribute_number(attrs: h5py.AttributeManager, key: str) -> int | float | None:
    """The value of the existing attribute ``key`` when HDF5 stores it as one number, as a Python int
    or float; None when it is stored as anything else.  The HDF5 type is judged, not the value h5py
    returns: an enum (h5py's bool is one, as are labelled states) reads back as a plain integer
    and was taken for a number, e.g. a sample rate of 1 Hz.  Refused too: text, compounds,
    references, arrays (even of one value) and empty attributes.

    Parameters
    ----------
    attrs : h5py.AttributeManager
        The attributes of a group or dataset.
    key : str
        The name of an attribute of ``attrs``.

    Returns
    -------
    int or float or None
        The number (an int for an HDF5 integer, a float for an HDF5 float), or None.

    Examples
    --------
    >>> import h5py, numpy as np
    >>> f = h5py.File("mem.h5", "w", driver="core", backing_store=False)
    >>> f.attrs["rate"], f.attrs["n"], f.attrs["on"], f.attrs["two"] = 2048.0, 3, True, [1.0, 2.0]
    >>> f.attrs.create("state", 1, dtype=h5py.enum_dtype({"off": 0, "on": 1}, basetype="i1"))
    >>> [attribute_number(f.attrs, k) for k in ("rate", "n", "on", "two", "state")]
    [2048.0, 3, None, None, None]
    >>> f.close()
    """
    aid = attrs.get_id(key)
    if aid.shape != () or aid.get_type().get_class() not in NUMBER_CLASSES:
        return None
    value = attrs[key]
    return int(value) if isinstance(value, np.integer) else float(value)


_CLASS_WORDS = {h5py.h5t.TIME: "time", h5py.h5t.STRING: "string", h5py.h5t.BITFIELD: "bitfield",
                h5py.h5t.OPAQUE: "opaque value", h5py.h5t.COMPOUND: "compound",
                h5py.h5t.REFERENCE: "reference", h5py.h5t.ENUM: "enum (h5py's bool is one)",
                h5py.h5t.VLEN: "variable-length sequence", h5py.h5t.ARRAY: "array type"}


def stored_as(attrs: h5py.AttributeManager, key: str) -> str:
    """How the existing attribute ``key`` is stored, in words for an error line, when it is not one
    number (:func:`attribute_number`), e.g. ``" (stored as an HDF5 enum (h5py's bool is one))"``;
    "" when it is one number."""
    aid = attrs.get_id(key)
    if aid.shape is None:
        return " (stored as an empty HDF5 attribute)"
    if aid.shape != ():
        return f" (stored as an array of shape {aid.shape})"
    words = _CLASS_WORDS.get(aid.get_type().get_class())
    return f" (stored as an HDF5 {words})" if words else ""


def _check_attrs(g: h5py.Group, where: str) -> None:
    a = g.attrs
    for key in ("sample_rate_hz", "start_time", "excitation", "pose"):
        if key not in a:
            raise DaqError(f"{where}: missing attribute {key!r}")
    rate = attribute_number(a, "sample_rate_hz")
    if rate is None or not sample_rate_ok(float(rate)):
        shown = _shown(a["sample_rate_hz"] if rate is None else rate)
        raise DaqError(f"{where}: attribute sample_rate_hz = {shown}{stored_as(a, 'sample_rate_hz')} "
                       f"is not a sample rate > 0 Hz and <= {MAX_SAMPLE_RATE_HZ:g} Hz")
    start = _text(a["start_time"])
    try:
        datetime.fromisoformat(start or "")
    except ValueError:
        raise DaqError(f"{where}: attribute start_time = {_shown(a['start_time'])} is not an ISO 8601 "
                       "date and time (e.g. 2026-11-26T21:00:00+00:00)") from None
    excitation = _text(a["excitation"])
    if excitation not in EXCITATIONS:
        raise DaqError(f"{where}: attribute excitation = {_shown(a['excitation'])} is not one of "
                       f"{', '.join(EXCITATIONS)}")
    pose_text = _text(a["pose"])
    pose = loads_json(pose_text, f"{where}: attribute pose", DaqError) if pose_text is not None else None
    if not isinstance(pose, dict):
        raise DaqError(f"{where}: attribute pose = {_shown(a['pose'])} is not a JSON object string")
    for name, value in pose.items():
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise DaqError(f"{where}: attribute pose: {_short(name)} = {_short(value)} is not a finite "
                           "number")


def check_run_id(run_id: str, where: str) -> str:
    """``run_id`` when it can name a run group: not empty, not ``.`` or ``..``, without ``/`` or NUL
    and at most 255 characters (HDF5 link names; ``.`` is the group itself)."""
    if not run_id or run_id in (".", "..") or "/" in run_id or "\x00" in run_id or len(run_id) > 255:
        raise DaqError(f"{where} {_short(run_id)!r} cannot name a run (non-empty, not '.' or '..', no '/', "
                       "at most 255 characters)")
    fault = name_fault(run_id)
    if fault:
        raise DaqError(f"{where} {run_id!r} cannot name a run: it {fault}")
    return run_id


MAX_LINK_HOPS = 40  # soft links followed to find an external link at their end (HDF5's own limit: 16)


def external_link_on_path(parent: h5py.Group, name: str) -> h5py.ExternalLink | None:
    """The external link that opening ``parent[name]`` would follow, or None: ``name`` itself, or any
    link on the way through soft links (``samples`` -> ``/ext`` -> another file).  HDF5 opens the
    other file, and one that is a FIFO blocks the ``open()`` for ever, a Ctrl-C or SIGTERM included;
    only link records are read here, never an external file.  Paths that do not resolve (missing,
    a loop) return None: opening them raises, and the caller names that.

    Parameters
    ----------
    parent : h5py.Group
        The group ``name`` is looked up in.
    name : str
        A member name or a path (``runs/r1/samples``; absolute soft-link targets are followed from
        the file's root, at most :data:`MAX_LINK_HOPS` soft links).

    Returns
    -------
    h5py.ExternalLink or None
        The first external link on the way, or None when there is none.

    Examples
    --------
    >>> import h5py, numpy as np
    >>> f = h5py.File("mem.h5", "w", driver="core", backing_store=False)
    >>> f["runs/r1/samples"] = np.zeros(3)
    >>> f["runs/r2"] = h5py.ExternalLink("/tmp/fifo", "/runs/r1")
    >>> f["runs/r3"] = h5py.SoftLink("/runs/r2")
    >>> external_link_on_path(f, "runs/r1/samples") is None
    True
    >>> [external_link_on_path(f, p).filename for p in ("runs/r2/samples", "runs/r3/samples")]
    ['/tmp/fifo', '/tmp/fifo']
    >>> f.close()
    """
    hops = 0

    def walk(group: h5py.Group, path: str) -> h5py.ExternalLink | None:
        nonlocal hops
        if path.startswith("/"):
            group, path = group.file, path.lstrip("/")
        parts = [p for p in path.split("/") if p not in ("", ".")]
        for k, part in enumerate(parts):
            if not isinstance(group, h5py.Group):
                return None
            link = group.get(part, getlink=True)
            if link is None or isinstance(link, h5py.ExternalLink):
                return link
            if isinstance(link, h5py.SoftLink):
                hops += 1
                found = walk(group, link.path) if hops <= MAX_LINK_HOPS else None
                if found is not None or hops > MAX_LINK_HOPS:
                    return found
            if k + 1 < len(parts):
                group = group[part]   # safe: no external link on the way to it
        return None

    try:
        return walk(parent, name)
    except (KeyError, RuntimeError, OSError, ValueError):   # a broken or looping path: opening names it
        return None


def member(parent: h5py.Group, name: str, where: str, error: type[Exception] = DaqError) -> object | None:
    """``parent[name]``, or None when there is no such member; an external link (never followed: it
    would read another file), a dangling or looping soft link, or an object HDF5 cannot open raises
    ``error`` naming ``where`` and the member."""
    link = parent.get(name, getlink=True)
    if link is None:
        return None
    if isinstance(link, h5py.ExternalLink):
        raise error(f"{where}: {name!r} is an external link to {link.filename}:{link.path} (not followed)")
    far = external_link_on_path(parent, name) if isinstance(link, h5py.SoftLink) else None
    if far is not None:
        raise error(f"{where}: {name!r} is a soft link to {link.path}, which reaches an external link to "
                    f"{far.filename}:{far.path} (not followed)")
    try:
        return parent[name]
    except (KeyError, RuntimeError, OSError, ValueError) as exc:
        what = "a dangling or looping link" if isinstance(link, h5py.SoftLink) else "an unreadable object"
        raise error(f"{where}: {name!r} is {what} ({_short(exc)})") from None


def check_filters(d: h5py.Dataset, where: str, error: type[Exception] = DaqError) -> None:
    """Raise ``error`` when dataset ``d`` is stored with a required filter (compression) this HDF5
    lacks: its data could not be read (HDF5 filter registry, ``H5Zfilter_avail``; an optional filter
    that is missing was skipped when the data were written)."""
    plist = d.id.get_create_plist()
    for i in range(plist.get_nfilters()):
        code, flags, _values, name = plist.get_filter(i)
        if not flags & h5py.h5z.FLAG_OPTIONAL and not h5py.h5z.filter_avail(code):
            label = name.decode(errors="replace") if isinstance(name, bytes) else str(name)
            raise error(f"{where}: {d.name.rsplit('/', 1)[-1]!r} is compressed with filter {code} "
                        f"({label or 'unnamed'}), which is not installed (pip install hdf5plugin)")


def _short(value: object) -> str:
    """A value or message quoted in an error line: one line, at most :data:`SHORT_CHARS` characters."""
    return one_line(value, SHORT_CHARS)


def _shown(value: object) -> str:
    """A stored attribute's value in an error line: a number as written, else quoted text (:func:`_short`)."""
    return shown_value(value, SHORT_CHARS)


def _table(g: h5py.Group, name: str, where: str) -> h5py.Dataset:
    d = member(g, name, where)
    if not isinstance(d, h5py.Dataset):
        raise DaqError(f"{where}: has no {name!r} dataset")
    fields = d.dtype.names or ()
    if d.ndim != 1 or not fields:
        raise DaqError(f"{where}: {name!r} is not a table of records (shape {d.shape}, type {d.dtype})")
    for field in RUN_FIELDS[name]:
        if field not in fields:
            raise DaqError(f"{where}: {name!r} table has no field {field!r}")
        kind = d.dtype[field].kind
        want = NUMERIC_FIELDS.get(field)
        ok = numeric_dtype(d.dtype[field], "iu" if want == "i" else "fiu") if want else kind in "SOU"
        if not ok:
            raise DaqError(f"{where}: {name!r} field {field!r} has type {dtype_words(d.dtype[field])} "
                           f"(expected {'a number' if want else 'text'})")
    return d


def check_run_group(g: h5py.Group, where: str) -> None:
    """Raise DaqError unless ``g`` has the attributes and datasets of a run (``where`` names it)."""
    if not isinstance(g, h5py.Group):
        raise DaqError(f"{where}: is not a group")
    check_run_id(g.name.rsplit("/", 1)[-1], f"{where}: run id") if g.name else None
    _check_attrs(g, where)
    channels = _table(g, "channels", where)
    events = _table(g, "events", where)
    s = member(g, "samples", where)
    if not isinstance(s, h5py.Dataset):
        raise DaqError(f"{where}: has no 'samples' dataset")
    if s.ndim != 2 or not numeric_dtype(s.dtype):
        raise DaqError(f"{where}: 'samples' must be a 2-D numeric dataset (shape {s.shape}, type "
                       f"{dtype_words(s.dtype)})")
    if s.shape[1] != channels.shape[0] or s.shape[1] == 0:
        raise DaqError(f"{where}: 'samples' has {s.shape[1]} columns but {channels.shape[0]} channels")
    for d in (channels, events, s):
        check_dataset(d, where, whole=d is not s)
    for table in (channels, events):
        _check_texts(table, where)
    _check_names(channels, where)
    _check_event_places(events, s.shape[0], where)


def _check_event_places(events: h5py.Dataset, n_samples: int, where: str) -> None:
    """Every event has sample_index and count from 0 to MAX_EVENT_SAMPLES, and a trigger lies within the
    record
    (sample_index < n_samples): a trigger 10^6 samples past the end was cut into hit records of
    -995698 samples.  Other events may point past the stored rows (a run stopped by a full disk
    records where it stopped, after rows that never reached the disk): they describe, and the run
    stays readable."""
    table = events[()]
    index, count = table["sample_index"], table["count"]
    trigger = np.array([_text(k) == "trigger" for k in table["kind"]], bool)   # a loop over events
    outside = (index < 0) | (trigger & (index >= n_samples)) | (index > MAX_EVENT_SAMPLES)
    bad = np.flatnonzero(outside | (count < 0) | (count > MAX_EVENT_SAMPLES))
    if bad.size:
        row = int(bad[0])
        what = (f"sample_index = {index[row]} is outside the record (0 to {n_samples - 1})" if outside[row]
                else f"count = {count[row]} is not from 0 to {MAX_EVENT_SAMPLES} samples")
        raise DaqError(f"{where}: 'events' row {row} ({_text(table['kind'][row])}): {what}")


def _check_texts(table: h5py.Dataset, where: str) -> None:
    """Every text field of a run's table is UTF-8 (the error names table, row, field and value; it was
    "cannot read ('utf-8' codec ...)" naming none of them)."""
    data = table[()]
    for field in table.dtype.names or ():
        if data.dtype[field].kind not in "SO" or not data.size:
            continue
        values, first = np.unique(data[field], return_index=True)
        for value, row in zip(values, first, strict=True):
            if isinstance(value, bytes | str) and _text(value) is None:
                raise DaqError(f"{where}: {table.name.rsplit('/', 1)[-1]!r} row {row} field {field!r}: "
                               f"{bytes(value)!r} is not UTF-8 text")


def check_dataset(d: h5py.Dataset, where: str, error: type[Exception] = DaqError, *,
                  whole: bool = True) -> None:
    """Raise ``error`` unless dataset ``d`` can be read as stored in this file: its filters are
    installed (:func:`check_filters`), it is not a virtual dataset (it maps other files, which are not
    followed, like external links), its external raw-data files (if any) hold all its bytes, it stores
    what it declares (:func:`_check_stored`) and, when read ``whole``, it fits in memory."""
    name = d.name.rsplit("/", 1)[-1] if d.name else "dataset"
    check_filters(d, where, error)
    if d.is_virtual:
        raise error(f"{where}: {name!r} is a virtual dataset mapping other files (not followed; store the "
                    "data in the file, e.g. h5repack)")
    _check_external(d, name, where, error)
    _check_stored(d, name, where, error)
    if whole:
        need, room = d.size * d.dtype.itemsize, available_memory_bytes()
        if need > room // 2:
            raise error(f"{where}: {name!r} declares {d.shape} values ({need / 2**30:.1f} GiB), more than "
                        f"the {room / 2**30:.1f} GiB of memory available")


def _check_external(d: h5py.Dataset, name: str, where: str, error: type[Exception]) -> None:
    """Raise ``error`` when the external raw-data files of ``d`` (HDF5 external storage) are missing or
    shorter than the data they should hold (HDF5 would read the missing bytes as zeros)."""
    plist = d.id.get_create_plist()
    count = plist.get_external_count()
    if not count:
        return
    held = 0
    for i in range(count):
        file, offset, size = plist.get_external(i)
        raw = Path(os.fsdecode(file))  # HDF5 reads a relative name from the current folder
        try:
            length = raw.stat().st_size
        except OSError as exc:
            raise error(f"{where}: {name!r} is stored in the external file {raw}, which cannot be read "
                        f"({exc.strerror or exc})") from None
        held += max(0, min(size, length - offset))
    need = d.size * d.dtype.itemsize
    if held < need:
        raise error(f"{where}: {name!r} needs {need} bytes from its external files but they hold {held}")


def _check_stored(d: h5py.Dataset, name: str, where: str, error: type[Exception]) -> None:
    """Raise ``error`` when ``d`` declares data it never stored beyond the last two chunk slabs along
    the axis it grows on (the first when resizable there, else its longest in chunks): a writer that
    grows a dataset ends at most one chunk past what it wrote, and HDF5 gives the rest back as fill
    values, so a file that declares 10^11 rows in 6 kB would otherwise be streamed as days of fill
    values, or allocated whole."""
    if d.size == 0:
        return
    if d.chunks is None:
        stored, expected, spare = int(d.id.get_storage_size() > 0), 1, 0
    else:
        per_axis = [-(-n // c) for n, c in zip(d.shape, d.chunks, strict=True)]
        stored, expected = d.id.get_num_chunks(), math.prod(per_axis)
        growing = 0 if d.maxshape and d.maxshape[0] is None else per_axis.index(max(per_axis))
        spare = 2 * (expected // per_axis[growing])   # two slabs of chunks along the axis it grows on
    if stored < expected - spare:
        raise error(f"{where}: {name!r} declares shape {d.shape} but stores {stored} of its {expected} "
                    "chunks (data never written)")


def _check_names(channels: h5py.Dataset, where: str) -> None:
    """Channel names are unique: two sensors of one name would silently become one in the shapes."""
    names = [_text(n) for n in channels["name"]]
    seen: set[str | None] = set()
    for n in names:
        fault = name_fault(n) if n is not None else "is not UTF-8 text"
        if fault:
            raise DaqError(f"{where}: channel name {n!r} {fault}")
        if n in seen:
            raise DaqError(f"{where}: channel name {n!r} appears twice (each channel needs its own name)")
        seen.add(n)


def check_run_file(path: str | Path, run_id: str) -> None:
    """Open ``path`` (:func:`flexmodal.daq.h5file.open_read`) and check run ``run_id`` without reading
    its samples: lets a command refuse a bad run file before it starts working."""
    with open_read(path) as f:
        runs = member(f, "runs", str(path))
        g = member(runs, run_id, f"{path}: run {run_id!r}") if isinstance(runs, h5py.Group) else None
        if g is None:
            raise DaqError(f"{path}: no run {run_id!r}")
        check_run_group(g, f"{path}: run {run_id!r}")
