"""Mode shapes no MAC can use, on either side of `flexmodal compare`, as a class: each is refused with one
line naming the file, row and columns (exit 2), or paired by frequency order with one warning naming the
file(s) and columns; never an exit 0 with nothing paired.

Before: shapes all below 1e-100 (their squares underflow), all zero (MAC 0/0) or given at no sensor
(NaN) paired nothing, or paired by frequency order under a note that blamed the sensor names, exit 0.

* tiny (a mode shape nonzero but at most 1e-100 at every sensor): refused, as measured data below
  1e-100 are (checked_io.data_range): a unit error, whose squares every shape comparison reads as 0;
* infinite: refused (contract/table.py);
* all zero at the common sensors: MAC is undefined, so the modes pair by frequency order, with a warning;
* NaN or empty at the common sensors: no shape given, paired by frequency order, with a warning;
* large (1e140, inside the 1e150 bound): paired by MAC, the exact closed-form value 1.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest
from test_compare_pairing import BETA_L, cantilever_shapes

from flexmodal.app import main

SENSORS = ("a1", "a2", "a3", "a4")
PHI = cantilever_shapes(np.linspace(0.25, 1.0, 4))[:, :3]       # exact beam shapes [sensor, mode]
F_HZ = 20.0 * BETA_L[:3] ** 2 / BETA_L[0] ** 2
POSES = {"theta0": 0.0, "theta60": 60.0}


def _write(path: Path, cell, freq_factor: float) -> Path:
    """A modal table of both poses, three modes each; shape cell k of mode m is ``cell(PHI[k, m])``."""
    lines = ["config,mode,freq_hz,pose.theta_deg," + ",".join(f"shape.{s}" for s in SENSORS)]
    for config, theta in POSES.items():
        for m in range(3):
            shape = ",".join(cell(PHI[k, m]) for k in range(len(SENSORS)))
            lines.append(f"{config},{m + 1},{_text(freq_factor * F_HZ[m])},{theta},{shape}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _text(value: float) -> str:
    return repr(float(value))   # all 17 digits, as a plain number (not numpy's 'np.float64(...)')


CELLS = {
    "plain": _text,
    "tiny": lambda v: _text(v * 1e-120),
    "near_subnormal": lambda v: _text(v * 1e-300),
    "zero": lambda v: "0",
    "nan": lambda v: "nan",
    "empty": lambda v: "",
    "inf": lambda v: "inf",
    "large": lambda v: _text(v * 1e140),
}


def _compare(tmp_path: Path, capsys, side: str, kind: str) -> tuple[int, str, str, Path, Path]:
    measured = _write(tmp_path / "measured.csv", CELLS[kind if side == "measured" else "plain"], 1.03)
    predicted = _write(tmp_path / "fe.csv", CELLS[kind if side == "predicted" else "plain"], 1.0)
    code = main(["--quiet", "compare", str(measured), str(predicted), "--format", "csv"])
    out, err = capsys.readouterr()
    return code, out, err, measured, predicted


@pytest.mark.parametrize("side", ["measured", "predicted"])
@pytest.mark.parametrize("kind", ["tiny", "near_subnormal", "inf"])
def test_shapes_no_arithmetic_can_use_are_refused_naming_the_file(tmp_path, capsys, side, kind) -> None:
    code, out, err, measured, predicted = _compare(tmp_path, capsys, side, kind)
    path = measured if side == "measured" else predicted
    assert (code, out) == (2, "")
    assert err.count("\n") == 1 and "Traceback" not in err
    if kind == "inf":
        assert err == f"flexmodal: error: {path}: row 2: column 'shape.a1' holds an infinite value\n"
    else:
        peak = float(CELLS[kind](np.abs(PHI[:, 0]).max()))
        assert err == (f"flexmodal: error: {path}: row 2: the mode shape (shape.a1 .. shape.a4) is at most "
                       f"{peak:.4g} in magnitude, below 1e-100 (its squares underflow to 0: is the unit "
                       "right?)\n")


def _rows(out: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(out)))


def _paired_by_frequency_order(out: str) -> None:
    """Every measured mode k (at 1.03 f_k) paired with predicted mode k (at f_k), no MAC column."""
    rows = _rows(out)
    assert "fe_mac" not in rows[0]
    assert [(r["config"], r["mode"]) for r in rows] == [(c, str(m)) for c in POSES for m in (1, 2, 3)]
    np.testing.assert_allclose([float(r["fe_freq_hz"]) for r in rows], np.tile(F_HZ, 2), rtol=1e-15)
    np.testing.assert_allclose([float(r["fe_err_pct"]) for r in rows], 100 * (1 / 1.03 - 1), rtol=1e-12)


@pytest.mark.parametrize("side", ["measured", "predicted"])
def test_zero_shapes_pair_by_frequency_order_with_one_warning(tmp_path, capsys, side) -> None:
    code, out, err, measured, predicted = _compare(tmp_path, capsys, side, "zero")
    path = measured if side == "measured" else predicted
    assert code == 0
    assert err == (f"flexmodal: warning: fe: every {side} mode shape is zero at the common sensors (MAC "
                   f"undefined) in 2 configurations (theta0, theta60) of {path} (shape.a1 .. shape.a4, 4 "
                   "columns): paired by frequency order, not by MAC\n")
    _paired_by_frequency_order(out)


@pytest.mark.parametrize("side", ["measured", "predicted"])
@pytest.mark.parametrize("kind", ["nan", "empty"])
def test_shapes_given_at_no_sensor_pair_by_frequency_order_with_one_warning(tmp_path, capsys, side,
                                                                            kind) -> None:
    code, out, err, measured, predicted = _compare(tmp_path, capsys, side, kind)
    assert code == 0
    columns = "shape.a1 .. shape.a4, 4 columns"
    assert err == (f"flexmodal: warning: fe: fewer than two common sensors hold a shape value (not empty, "
                   f"not NaN) for every mode in 2 configurations (theta0, theta60) of {measured} ({columns}) "
                   f"and {predicted} ({columns}): paired by frequency order, not by MAC\n")
    _paired_by_frequency_order(out)


def test_zero_shapes_are_named_in_the_markdown_notes_per_configuration(tmp_path, capsys) -> None:
    measured = _write(tmp_path / "measured.csv", CELLS["plain"], 1.03)
    predicted = _write(tmp_path / "fe.csv", CELLS["zero"], 1.0)
    assert main(["--quiet", "compare", str(measured), str(predicted)]) == 0
    notes = [line for line in capsys.readouterr().out.splitlines() if line.startswith("- ")]
    assert notes == [f"- fe: {c}: every predicted mode shape is zero at the common sensors (MAC undefined): "
                     "paired by frequency order, not by MAC" for c in POSES]


@pytest.mark.parametrize("side", ["measured", "predicted"])
def test_large_shapes_pair_by_mac_exactly(tmp_path, capsys, side) -> None:
    """Shapes of 1e140 (the MAC's fourth powers, 1e560, overflowed to inf / inf = NaN) on one side, and on
    both: every mode pairs with its own, MAC 1 to rounding."""
    code, out, err, _, _ = _compare(tmp_path, capsys, side, "large")
    assert (code, err) == (0, "")
    rows = _rows(out)
    assert [(r["mode"], float(r["fe_mac"])) for r in rows] == [(str(m), pytest.approx(1.0, abs=1e-14))
                                                                for _ in POSES for m in (1, 2, 3)]
    both = _write(tmp_path / "fe.csv", CELLS["large"], 1.0)
    assert main(["--quiet", "compare", str(both), str(both), "--format", "csv"]) == 0
    np.testing.assert_allclose([float(r["fe_mac"]) for r in _rows(capsys.readouterr().out)], 1.0, rtol=1e-14)


@pytest.mark.parametrize(("cells", "fault"), [
    # a column of numbers (read at once, as a block) after a text column: the text column's fault first
    ({"a1": "0.1+0.2j", "a2": "x", "a3": "inf"}, "column 'shape.a2' holds a value that is not a number"),
    ({"a1": "1", "a2": "inf", "a3": "x"}, "row 2: column 'shape.a2' holds an infinite value"),
    ({"a1": "1e151", "a2": "0.5", "a3": "nan+1j"}, "row 2: column 'shape.a1' holds 1e+151, above 1e+150 in "
                                                   "magnitude"),
    ({"a1": "1", "a2": "0.1+0.2j", "a3": "-1e151"}, "row 2: column 'shape.a3' holds -1e+151, above 1e+150 "
                                                    "in magnitude"),
])
def test_the_first_faulty_shape_column_in_table_order_is_named(tmp_path, capsys, cells, fault) -> None:
    """Shape columns of numbers are checked as one block and text columns (complex values) one by one;
    either way the message names the first faulty column of the table, as when each was read alone."""
    path = tmp_path / "m.csv"
    rows = [cells, {"a1": "1", "a2": "0.5", "a3": "2"}]
    lines = [f"t,{k + 1},{10 * (k + 1)},{r['a1']},{r['a2']},{r['a3']}\n" for k, r in enumerate(rows)]
    path.write_text("config,mode,freq_hz,shape.a1,shape.a2,shape.a3\n" + "".join(lines), encoding="utf-8")
    assert main(["--quiet", "compare", str(path), str(path)]) == 2
    assert capsys.readouterr().err == f"flexmodal: error: {path}: {fault}\n"


def test_shape_columns_of_numbers_and_of_text_read_back_in_table_order(tmp_path) -> None:
    """Numbers, complex text and an empty cell in one table: values, dtypes and column order kept."""
    from flexmodal.contract.table import ModalTable

    path = tmp_path / "m.csv"
    path.write_text("config,mode,shape.b,freq_hz,shape.a,shape.c\nt,1,0.5,10,1e-320,0.1+0.2j\n"
                    "t,2,,20,-3,2\n", encoding="utf-8")
    table = ModalTable.read_csv(path)
    assert list(table.frame.columns) == ["config", "mode", "shape.b", "freq_hz", "shape.a", "shape.c"]
    np.testing.assert_array_equal(table.shapes("t"), [[0.5, np.nan], [0.0, -3.0], [0.1 + 0.2j, 2.0]])
    assert [table.frame[c].dtype.kind for c in table.shape_columns] == ["f", "f", "c"]
