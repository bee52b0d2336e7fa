"""CSV tables too wide or too long to read in seconds are refused on their header and line count, before
a row is parsed (checked_io.csv_tables); the widest table accepted is read and compared.

Before: `compare` on a modal table of 200,000 columns took 74 s, one of 10,000 shape columns 112 s
(pandas set one column at a time, and the sensors of a table were listed again for every sensor).
"""

from __future__ import annotations

import csv
import io
import time
from pathlib import Path

import numpy as np
import pytest

from flexmodal.app import main
from flexmodal.checked_io.csv_tables import MAX_CELLS, MAX_COLUMNS, MAX_ROWS

HEADER = ["config", "mode", "freq_hz"]


def _write(path: Path, header: list[str], rows: list[str]) -> Path:
    """A table of ``header`` and ``rows``; its second line is one field only: a table whose rows were
    parsed would be refused for that line, one refused on its size never reaches it."""
    path.write_text(",".join(header) + "\nbroken\n" + "".join(rows), encoding="utf-8")
    return path


def _refusal(path: Path, capsys) -> str:
    assert main(["--quiet", "compare", str(path), str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


def test_header_wider_than_the_limit_is_refused_before_its_rows(tmp_path, capsys) -> None:
    header = HEADER + [f"shape.s{k}" for k in range(MAX_COLUMNS + 1 - len(HEADER))]
    path = _write(tmp_path / "wide.csv", header, ["theta0,1,10" + "," * (len(header) - 3) + "\n"])
    assert _refusal(path, capsys) == (f"flexmodal: error: {path}: line 1: the header names 10,001 columns, "
                                      "more than the 10,000 a modal table may have\n")


def test_more_lines_than_the_limit_are_refused_before_they_are_parsed(tmp_path, capsys) -> None:
    rows = [f"theta{k},1,10\r\n" for k in range(MAX_ROWS)]   # + the broken line: one line too many
    path = _write(tmp_path / "long.csv", HEADER, rows)
    assert _refusal(path, capsys) == (f"flexmodal: error: {path}: 100,001 lines after the header, more "
                                      "than the 100,000 rows a modal table may have\n")


def test_more_cells_than_the_limit_are_refused_before_they_are_parsed(tmp_path, capsys) -> None:
    header = HEADER + [f"shape.s{k}" for k in range(197)]   # 200 columns
    rows = [f"theta{k},1,10" + ",1" * 197 + "\n" for k in range(MAX_CELLS // 200)]
    path = _write(tmp_path / "cells.csv", header, rows)
    assert _refusal(path, capsys) == (f"flexmodal: error: {path}: 5,001 lines of 200 columns after the "
                                      "header (1,000,200 cells) are more than the 1,000,000 cells a modal "
                                      "table may hold\n")


@pytest.mark.slow   # 4 s
def test_a_table_at_the_column_limit_is_read_and_compared(tmp_path, capsys) -> None:
    """10,000 columns (9,997 sensors), two modes whose shapes are orthogonal: each pairs with itself,
    MAC 1.  The CPU-time bound is far above the ~3 s it takes (and far below
    the 112 s of the quadratic reading): it cannot fail under load, a quadratic regression fails it."""
    n = MAX_COLUMNS - len(HEADER)
    path = tmp_path / "widest.csv"
    path.write_text(",".join(HEADER + [f"shape.s{k}" for k in range(n)]) + "\n"
                    + "theta0,1,10," + ",".join(["1"] * n) + "\n"
                    + "theta0,2,20," + ",".join(["1", "-1"] * (n // 2) + ["0"] * (n % 2)) + "\n",
                    encoding="utf-8")
    start = time.process_time()
    assert main(["--quiet", "compare", str(path), str(path), "--format", "csv"]) == 0
    assert time.process_time() - start < 60
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [(r["mode"], float(r["widest_freq_hz"]), float(r["widest_mac"])) for r in rows] == [
        ("1", 10.0, pytest.approx(1.0, abs=1e-12)), ("2", 20.0, pytest.approx(1.0, abs=1e-12))]


@pytest.mark.slow   # 5 s CPU
def test_a_table_at_the_line_limit_is_read_and_compared(tmp_path, capsys) -> None:
    """100,000 lines of 10 columns (the cell limit too): 10,000 configurations of 10 modes, each mode's
    shape a different sign pattern at 7 sensors; every mode pairs with itself, MAC 1.  Reading took
    0.87 s CPU before the number columns were checked at once (0.56 s after), compare 6 s; the bound
    is far above either, for a regression to a per-cell scan of the reading or the pairing."""
    signs = np.where((np.arange(1, 11)[:, None] >> np.arange(7)[None, :]) & 1, -1.0, 1.0)   # [mode, sensor]
    lines = [",".join(HEADER + [f"shape.s{k}" for k in range(7)])]
    lines += [f"c{c},{m + 1},{10 + m + c * 1e-4:.4f}," + ",".join(f"{v:g}" for v in signs[m])
              for c in range(MAX_ROWS // 10) for m in range(10)]
    path = tmp_path / "longest.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    start = time.process_time()
    assert main(["--quiet", "compare", str(path), str(path), "--format", "csv"]) == 0
    assert time.process_time() - start < 120
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == MAX_ROWS
    assert [(r["config"], r["mode"]) for r in rows[:2]] == [("c0", "1"), ("c0", "2")]
    np.testing.assert_allclose([float(r["longest_mac"]) for r in rows], 1.0, atol=1e-12)
