"""Stored stabilisation diagrams: run the stabilisation once, pick many times.

Every pLSCF identification written to ``MODES.csv`` stores its stabilisation diagram beside it, in
``MODES.diagram.npz`` (one diagram per configuration, each under the key of the FRFs and options it was
computed from: :func:`inputs_key`).  ``identify --poles F1,F2`` then re-picks the poles nearest F1, F2
from the stored diagram whose key matches its own input and options instead of running the
stabilisation again (``--from-diagram``: only from it, an error when none matches).  The file is
written atomically with the modal table and read back with allow_pickle off, every array checked.
"""

from __future__ import annotations

import hashlib
import io
import os
import zipfile
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexmodal.checked_io.output import atomic_path
from flexmodal.checked_io.text import available_memory_bytes
from flexmodal.modal.errors import ModalError
from flexmodal.modal.lscf import Stabilisation

FORMAT = "flexmodal stabilisation diagrams 1"
# the arrays of a Stabilisation and the kind of each ("i" integer, "f" float, "c" complex, "b" bool)
KINDS = {"order": "i", "freq_hz": "f", "damping_ratio": "f", "pole": "c", "stable_freq": "b",
         "stable_damping": "b", "stable_shape": "b", "previous": "i"}
MAX_BYTES = 1 << 28   # 256 MiB of arrays (a diagram of 10^6 poles holds ~40 MB)
MAX_ORDER = 1 << 16   # no pLSCF is fitted at a higher order (its normal equations: (order + 1)^2 numbers
#                       per output, 34 GB at this one; --max-order stops at 400, the default caps near it)


@dataclass(frozen=True)
class StoredDiagram:
    """The stabilisation diagram of one configuration: ``key`` (:func:`inputs_key` of the FRFs and
    options it was computed from), ``config``, the ``stabilisation`` and its ``order_note``."""

    key: str
    config: str
    stabilisation: Stabilisation
    order_note: str


@dataclass(frozen=True)
class DiagramStore:
    """Stored diagrams by key, read from ``source``; ``required``: a pick must come from one of them
    (``identify --from-diagram``), else a pick without a matching diagram runs the stabilisation."""

    diagrams: Mapping[str, StoredDiagram]
    source: str
    required: bool = False

    def find(self, key: str) -> StoredDiagram | None:
        """The diagram stored for ``key`` (ModalError when none is and one is required)."""
        found = self.diagrams.get(key)
        if found is None and self.required:
            raise ModalError(f"{self.source}: no stored stabilisation diagram matches this input and these "
                             "options (identify it again without --poles, or leave out --from-diagram)")
        return found


def diagram_path(out: str | Path) -> Path:
    """``MODES.diagram.npz`` beside the modal table ``MODES.csv``."""
    out = Path(out)
    return out.with_name(out.stem + ".diagram.npz")


def inputs_key(freq_hz: np.ndarray, H: np.ndarray, **options: object) -> str:
    """SHA-256 of the band's frequency lines [Hz], the FRFs and the options that shape the diagram
    (repr of each, sorted by name): equal keys, equal diagrams."""
    digest = hashlib.sha256()
    for array in (np.ascontiguousarray(freq_hz, float), np.ascontiguousarray(H, complex)):
        digest.update(repr((array.shape, array.dtype.str)).encode())
        digest.update(array.tobytes())
    digest.update(repr(sorted(options.items())).encode())
    return digest.hexdigest()


def write_diagrams(path: str | Path, diagrams: Iterable[StoredDiagram]) -> Path:
    """Write ``diagrams`` to ``path`` (.npz, atomically); returns ``path``."""
    arrays: dict[str, np.ndarray] = {"format": np.array(FORMAT)}
    for k, d in enumerate(diagrams):
        arrays |= {f"d{k}.key": np.array(d.key), f"d{k}.config": np.array(d.config),
                   f"d{k}.order_note": np.array(d.order_note)}
        arrays |= {f"d{k}.{name}": np.asarray(getattr(d.stabilisation, name)) for name in KINDS
                   if getattr(d.stabilisation, name) is not None}
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)
    return Path(path)


def is_diagram_store(path: str | Path) -> bool:
    """True when ``path`` is a zip archive holding the ``format`` entry :func:`write_diagrams` writes
    (a store flexmodal wrote, even one damaged since): the only kind of file the diagrams beside a
    modal table may replace."""
    try:
        with zipfile.ZipFile(path) as zf:
            return "format.npy" in zf.namelist()
    except (OSError, zipfile.BadZipFile, ValueError):
        return False


def check_replaceable(path: str | Path) -> None:
    """ModalError when ``path`` holds a file that is not a stored stabilisation diagram: the diagrams
    written beside ``--out`` never replace a file of the user's own."""
    if os.path.isfile(path) and not is_diagram_store(path):
        raise ModalError(f"{path}: exists and is not a stabilisation diagram flexmodal stored; refusing to "
                         "replace it (move it, or choose another --out)")


def _array(raw: bytes, name: str, path: str | Path) -> np.ndarray:
    """The .npy bytes ``raw`` as an array, its header checked against its size before allocation."""
    buf = io.BytesIO(raw)
    major, _ = np.lib.format.read_magic(buf)
    read_header = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
    shape, _, dtype = read_header(buf)
    if dtype.hasobject:
        raise ModalError(f"{path}: entry {name!r} holds pickled Python objects, not numbers")
    if int(np.prod(shape, dtype=object)) * dtype.itemsize > len(raw) - buf.tell():
        raise ModalError(f"{path}: entry {name!r} declares shape {shape} of {dtype}, more than it holds")
    return np.load(io.BytesIO(raw), allow_pickle=False)


def _arrays(path: str | Path) -> dict[str, np.ndarray]:
    """Every array of the .npz ``path``, sizes checked before reading (ModalError naming the file)."""
    limit = min(MAX_BYTES, available_memory_bytes() // 4)
    try:
        if os.path.getsize(path) > limit:
            raise ModalError(f"{path}: {os.path.getsize(path)} bytes, more than a stabilisation diagram "
                             f"holds (limit {limit})")
        with zipfile.ZipFile(path) as zf:
            infos = [i for i in zf.infolist() if i.filename.endswith(".npy")]
            total = sum(i.file_size for i in infos)
            if total > limit:
                raise ModalError(f"{path}: its arrays unpack to {total} bytes, more than a stabilisation "
                                 f"diagram holds (limit {limit})")
            return {i.filename[:-4]: _array(zf.read(i), i.filename[:-4], path) for i in infos}
    except ModalError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, MemoryError) as exc:
        raise ModalError(f"{path}: not a stored stabilisation diagram ({exc})") from None


def _check_values(entry: Mapping[str, np.ndarray], k: int, path: str | Path) -> None:
    """ModalError naming diagram ``k`` when a stored value is impossible: a frequency that is not
    finite and positive, a damping ratio or pole that is not finite, an order outside 1..MAX_ORDER, a
    ``previous`` index outside the diagram."""
    n = entry["order"].size
    bad = {"freq_hz": ~(np.isfinite(entry["freq_hz"]) & (entry["freq_hz"] > 0)),
           "damping_ratio": ~np.isfinite(entry["damping_ratio"]), "pole": ~np.isfinite(entry["pole"]),
           "order": (entry["order"] < 1) | (entry["order"] > MAX_ORDER)}
    if "previous" in entry:
        bad["previous"] = (entry["previous"] < -1) | (entry["previous"] >= n)
    for name, wrong in bad.items():
        if wrong.any():
            i = int(np.flatnonzero(wrong)[0])
            raise ModalError(f"{path}: diagram {k + 1}: {name}[{i}] = {entry[name][i]} is impossible")


def read_diagrams(path: str | Path) -> dict[str, StoredDiagram]:
    """The diagrams of a file :func:`write_diagrams` wrote, by key (ModalError naming the file and the
    entry that is not one).  Sizes are checked before anything is read (at most ``MAX_BYTES`` or a
    quarter of the available memory) and every value before it is used."""
    data = _arrays(path)
    if str(data.get("format", "")) != FORMAT:
        raise ModalError(f"{path}: not a stored stabilisation diagram (no format {FORMAT!r})")
    found = {}
    for k in range(sum(name.endswith(".key") for name in data)):
        entry = {name.partition(".")[2]: value for name, value in data.items() if name.startswith(f"d{k}.")}
        missing = [n for n in ("key", "config", "order_note", *KINDS) if n not in entry and n != "previous"]
        size = entry["order"].shape if "order" in entry else None
        wrong = [a for a, kind in KINDS.items() if a in entry
                 and (entry[a].shape != size or entry[a].ndim != 1 or entry[a].dtype.kind != kind)]
        if missing or wrong:
            raise ModalError(f"{path}: diagram {k + 1}: {', '.join(missing)} missing" if missing else
                             f"{path}: diagram {k + 1}: {', '.join(wrong)} of the wrong kind or length")
        _check_values(entry, k, path)
        stab = Stabilisation(**{a: entry[a] for a in KINDS if a in entry})
        found[str(entry["key"])] = StoredDiagram(str(entry["key"]), str(entry["config"]), stab,
                                                 str(entry["order_note"]))
    return found
