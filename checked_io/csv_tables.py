"""CSV tables (modal tables, POSES.csv): UTF-8 text with one header line and equally long rows.

:func:`read_table` reads a table into a pandas DataFrame after checking what pandas lets through
silently or reports over several lines: an empty file, a header naming a column twice, a header
separated by ``;`` or tabs (a spreadsheet export with decimal commas), rows with more or fewer fields
than the header, missing required columns and empty cells in them, and a table too wide or too long
to read in seconds (:data:`MAX_COLUMNS`, :data:`MAX_ROWS`, :data:`MAX_CELLS`: refused on its header
and line count, before any row is parsed).  Failures raise the calling package's error type with the
file, line and column named.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from flexmodal.checked_io.text import FLOAT_MAX_BITS, ErrorType, one_line, read_text

#: the words pandas reads as a missing value by default (pandas.read_csv, ``na_values``)
NA_WORDS = ("", "#N/A", "#N/A N/A", "#NA", "-1.#IND", "-1.#QNAN", "-NaN", "-nan", "1.#IND", "1.#QNAN",
            "<NA>", "N/A", "NA", "NULL", "NaN", "None", "n/a", "nan", "null")
MAX_COLUMNS = 10_000     # a modal table's columns: a shape column per sensor (a large laser scan: thousands)
MAX_ROWS = 100_000       # lines below the header (a config per pose and mode): a compare takes ~8 s
MAX_CELLS = 1_000_000    # columns x lines below the header: about 10 s of parsing and comparing at most


def read_table(path: str | Path, error: ErrorType, *, required: Sequence[str] = (),
               text_columns: Sequence[str] = (), what: str = "CSV table") -> pd.DataFrame:
    """Read a comma-separated table; ``required`` columns must exist and have no empty cell,
    ``text_columns`` are kept as strings (e.g. ``config``) without white space around them."""
    text = read_text(path, error, what)
    try:
        rows = [(n, r) for n, r in _numbered_rows(text, path, error, what)   # the first cell decides most
                if (r and r[0].strip()) or any(cell.strip() for cell in r)]
    except csv.Error as exc:
        raise error(f"{path}: not a readable CSV ({one_line(exc)})") from None
    if not rows:
        need = f" (expected a header line with {', '.join(required)})" if required else ""
        raise error(f"{path}: empty {what}{need}")
    header = [name.strip() for name in rows[0][1]]
    seen: set[str] = set()
    for name in header:
        if name in seen and name:
            raise error(f"{path}: line {rows[0][0]}: column {name!r} appears twice in the header")
        seen.add(name)
    hint = _separator_hint(rows[0][1])
    if hint and (len(header) == 1 or any(len(r) != len(header) for _, r in rows[1:])):
        raise error(f"{path}: line {rows[0][0]}: {hint}")
    for line, row in rows[1:]:
        if len(row) != len(header):
            raise error(f"{path}: line {line}: {len(row)} fields, the header has {len(header)}")
    missing = [c for c in required if c not in seen]
    if missing:
        raise error(f"{path}: missing required column {missing[0]!r} (columns: {', '.join(header)})")
    # pandas reads 'NA', 'None', 'null', 'nan', ... as missing: right for numbers, wrong for a name
    # (a configuration called NA became an "empty" cell); text columns keep every word as written
    # (read again, those columns alone: a per-column na_values costs pandas 0.1 ms a column)
    texts = [k for k, name in enumerate(header) if name in text_columns]
    try:
        frame = pd.read_csv(io.StringIO(text), skipinitialspace=True, keep_default_na=False,
                            na_values=list(NA_WORDS))
        words = pd.read_csv(io.StringIO(text), skipinitialspace=True, keep_default_na=False, dtype=str,
                            usecols=texts) if texts else frame.iloc[:, :0]
    except (pd.errors.ParserError, ValueError) as exc:
        raise error(f"{path}: not a readable CSV ({one_line(exc)})") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    for k, col in zip(texts, words.columns, strict=True):   # "theta0 " is "theta0"
        frame[frame.columns[k]] = words[col].str.strip()
    _refuse_huge_integers(frame, path, rows, error)
    for col in required:
        empty = frame[col].isna().to_numpy()
        if not pd.api.types.is_numeric_dtype(frame[col]):   # a blank text cell is empty (numbers: no scan)
            empty = empty | (frame[col].astype(str).str.strip() == "").to_numpy()
        if empty.any():
            i = int(empty.argmax())  # pandas keeps some lines csv drops (only a form feed, say)
            where = f"line {rows[1 + i][0]}" if 1 + i < len(rows) else f"data row {i + 1}"
            raise error(f"{path}: {where}: empty {col!r} cell")
    return frame


def _refuse_huge_integers(frame: pd.DataFrame, path: str | Path, rows: list, error: ErrorType) -> None:
    """``error`` naming the line and column of a whole number too large for a float (pandas keeps one
    of more than about 308 digits as a Python int, which every later float conversion fails on)."""
    for name in frame.columns[(frame.dtypes == "object").to_numpy()]:   # a loop over text columns
        huge = frame[name].map(lambda v: isinstance(v, int) and abs(v).bit_length() > FLOAT_MAX_BITS)
        if huge.any():
            i = int(huge.to_numpy().argmax())
            digits = len(str(abs(frame[name].iloc[i])))
            where = f"line {rows[1 + i][0]}" if 1 + i < len(rows) else f"data row {i + 1}"
            raise error(f"{path}: {where}: column {name!r}: a whole number of {digits} digits is too large "
                        "for a number (at most about 1.8e308)")


def _separator_hint(header: Sequence[str]) -> str:
    """Words for a header that is separated by ``;`` or tabs (a spreadsheet export in a locale with
    decimal commas), or "" when it is not."""
    text = ",".join(header)
    for sep, name in ((";", "semicolons"), ("\t", "tabs")):
        if text.count(sep) >= 1 and text.count(sep) >= len(header) - 1:
            return (f"the header is separated by {name}, not commas (a spreadsheet export with decimal "
                    "commas?): save the table as comma-separated values with '.' as decimal point")
    return ""


def _numbered_rows(text: str, path: str | Path, error: ErrorType, what: str):
    """(line number, fields) of every record of ``text`` (the line where the record ends); ``error``
    when the first record that is not blank (the header) names more than :data:`MAX_COLUMNS` columns,
    more than :data:`MAX_ROWS` lines follow it, or they hold more than :data:`MAX_CELLS` cells: checked
    before any further record is parsed."""
    reader = csv.reader(io.StringIO(text))
    for row in reader:
        yield reader.line_num, row
        if any(cell.strip() for cell in row):
            _check_size(text, reader.line_num, len(row), path, error, what)
            break
    for row in reader:
        yield reader.line_num, row


def _check_size(text: str, header_line: int, columns: int, path: str | Path, error: ErrorType,
                what: str) -> None:
    """``error`` naming the file when a header of ``columns`` columns on line ``header_line`` is wider
    than :data:`MAX_COLUMNS`, or the lines after it (``\\n``, ``\\r\\n`` or ``\\r`` ended; a quoted
    line break counts as a line) are more than :data:`MAX_ROWS` or hold more than :data:`MAX_CELLS`
    cells."""
    if columns > MAX_COLUMNS:
        raise error(f"{path}: line {header_line}: the header names {columns:,} columns, more than the "
                    f"{MAX_COLUMNS:,} a {what} may have")
    breaks = text.count("\n") + text.count("\r") - text.count("\r\n")
    lines = breaks + (not text.endswith(("\n", "\r"))) - header_line
    if lines > MAX_ROWS:
        raise error(f"{path}: {lines:,} lines after the header, more than the {MAX_ROWS:,} rows a {what} "
                    "may have")
    if lines * columns > MAX_CELLS:
        raise error(f"{path}: {lines:,} lines of {columns} columns after the header ({lines * columns:,} "
                    f"cells) are more than the {MAX_CELLS:,} cells a {what} may hold")
