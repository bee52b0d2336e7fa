"""Dataset-58 records of a UFF file (function at a node): checked before they are assembled.

pyuff returns whatever a file holds: a data block cut short gives fewer values than the record's
header announces (``num_pts``), hand-made files can lack fields or hold NaN, and an abscissa may run
backwards.  :func:`check_functions` turns each of these into one ModalError naming the file, the
record and the field (UFF dataset 58 layout: I-DEAS Universal File Format, record 7 holds ``num_pts``,
``abscissa_min`` and ``abscissa_inc``).  Some analysers fill the last line of an ASCII data block
(six values) with zeros; pyuff returns those as extra points, which :func:`drop_line_padding` removes.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from flexmodal.checked_io.data_range import range_fault
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import check_freq_axis

REQUIRED = ("func_type", "rsp_node", "rsp_dir", "ref_node", "ref_dir", "x", "data")
VALUES_PER_LINE = 6   # an ASCII dataset-58 data line holds at most six numbers (format 6E13.5)


def drop_line_padding(funcs: Sequence[dict]) -> list[dict]:
    """The records with the zeros that fill an ASCII data block's last line removed.

    A record whose data hold more points than its header's ``num_pts``, the surplus being fewer
    values than one line and all exactly zero, is cut to ``num_pts`` points (data and abscissa);
    every other record is returned as it is (and :func:`check_functions` judges it).

    Examples
    --------
    >>> rec = {"num_pts": 3, "x": np.arange(4.0), "data": np.array([1.0, 2.0, 3.0, 0.0])}
    >>> drop_line_padding([rec])[0]["data"]
    array([1., 2., 3.])
    """
    out = []
    for s in funcs:   # a loop over records
        data = np.asarray(s.get("data", []))
        n = int(s.get("num_pts", data.size))
        per_point = 2 if data.dtype.kind == "c" else 1
        surplus = data[n:] if 0 < n < data.size else data[:0]
        if 0 < surplus.size * per_point < VALUES_PER_LINE and not np.any(surplus):
            s = {**s, "data": data[:n], "x": np.asarray(s["x"])[:n]}
        out.append(s)
    return out


AXIS_WORDS = {17: "time", 18: "frequency"}   # UFF specific data types of an abscissa


def check_functions(path: str | Path, funcs: Sequence[dict]) -> None:
    """Raise ModalError unless every dataset-58 record has its fields, ``num_pts`` values on a finite,
    increasing abscissa, and finite data within the range of checked_io.data_range."""
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
            why = "truncated data block?" if data.size < n else "values after the data block"
            raise ModalError(f"{where}: {data.size} data values and {x.size} abscissa values, the header "
                             f"announces num_pts = {n} ({why})")
        if n < 2:
            raise ModalError(f"{where}: needs at least 2 points (num_pts = {n})")
        if not (np.isfinite(x).all() and np.isfinite(data).all()):
            raise ModalError(f"{where}: abscissa or data hold NaN or infinite values")
        fault = range_fault(data)
        if fault:
            at, words = fault
            raise ModalError(f"{where}: data {words}" if not at else f"{where}: data point {at[0] + 1} "
                             f"(at {x[at[0]]:g} on the abscissa) {words}")
        if not (np.diff(x) > 0).all():
            raise ModalError(f"{where}: the abscissa does not increase")
        axis = int(s.get("abscissa_spec_data_type", 0) or 0)
        wrong = {1: 18, 4: 17}.get(int(s.get("func_type", 0) or 0))   # time history on Hz, FRF on s
        if axis == wrong:
            raise ModalError(f"{where}: function type {int(s['func_type'])} on an abscissa of "
                             f"{AXIS_WORDS[axis]} (abscissa data type {axis}); its axis is "
                             f"{AXIS_WORDS[35 - axis]} (data type {35 - axis})")
        if int(s.get("func_type", 0) or 0) == 4:
            check_freq_axis(x, where, "abscissa")

