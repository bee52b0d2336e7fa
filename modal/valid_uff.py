"""Dataset-58 records of a UFF file (function at a node): checked before they are assembled.

pyuff returns whatever a file holds: a data block cut short gives fewer values than the record's
header announces (``num_pts``), hand-made files can lack fields or hold NaN, and an abscissa may run
backwards.  :func:`check_functions` turns each of these into one ModalError naming the file, the
record and the field (UFF dataset 58 layout: I-DEAS Universal File Format, record 7 holds ``num_pts``,
``abscissa_min`` and ``abscissa_inc``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from flexmodal.modal.errors import ModalError

REQUIRED = ("func_type", "rsp_node", "rsp_dir", "ref_node", "ref_dir", "x", "data")


def check_functions(path: str | Path, funcs: Sequence[dict]) -> None:
    """Raise ModalError unless every dataset-58 record has its fields, ``num_pts`` values on a finite,
    increasing abscissa, and finite data."""
    for k, s in enumerate(funcs, start=1):
        where = f"{path}: dataset 58 record {k}"
        for key in REQUIRED:
            if key not in s:
                raise ModalError(f"{where}: missing field {key!r}")
        x, data = np.asarray(s["x"]), np.asarray(s["data"])
        if x.ndim != 1 or data.ndim != 1 or x.dtype.kind not in "fiu" or data.dtype.kind not in "fiuc":
            raise ModalError(f"{where}: abscissa and data must be 1-D numbers")
        n = int(s.get("num_pts", data.size))
        if not x.size == data.size == n:
            raise ModalError(f"{where}: {data.size} data values and {x.size} abscissa values, the header "
                             f"announces num_pts = {n} (truncated data block?)")
        if n < 2:
            raise ModalError(f"{where}: needs at least 2 points (num_pts = {n})")
        if not (np.isfinite(x).all() and np.isfinite(data).all()):
            raise ModalError(f"{where}: abscissa or data hold NaN or infinite values")
        if not (np.diff(x) > 0).all():
            raise ModalError(f"{where}: the abscissa does not increase")
