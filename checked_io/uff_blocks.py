"""Universal File Format text: whole datasets between delimiter lines, checked before pyuff parses them.

A UFF file is a sequence of datasets, each opened and closed by a line ``    -1`` (columns 1-6), the
line after the opening one naming the dataset type (e.g. ``    58`` or ``    58b``).  pyuff pairs the
delimiters it finds and skips what it cannot pair or parse: a file cut short loses its last dataset,
a dataset whose number line is damaged is dropped, text between datasets is ignored, all silently.
:func:`check_blocks` finds the delimiters as pyuff does and names the file and line of each of these,
and of a dataset 58 whose node, direction or load case field pyuff would read as 0.
"""

from __future__ import annotations

from pathlib import Path

from flexmodal.checked_io.output import HDF5_SIGNATURE
from flexmodal.checked_io.text import ErrorType

BOM = b"\xef\xbb\xbf"   # a UTF-8 byte-order mark some editors put first (pyuff reads past it)
DELIMITER = b"    -1"   # the line that opens and closes every dataset (columns 1-6)
#: the leading bytes of packed files (no UFF, not even binary dataset 58b, starts so)
PACKED = ((b"\x1f\x8b", "gzip"), (b"BZh", "bzip2"), (b"\xfd7zXZ", "xz"), (b"PK\x03\x04", "zip"),
          (b"(\xb5/\xfd", "zstd"))


def packed_format(head: bytes) -> str | None:
    r"""The packed format (gzip, bzip2, xz, zip, zstd) of a file whose first bytes are ``head``, else
    None.

    Examples
    --------
    >>> packed_format(b"\x1f\x8b\x08\x08"), packed_format(b"    -1\n")
    ('gzip', None)
    """
    return next((name for magic, name in PACKED if head.startswith(magic)), None)


#: the whole-number fields of a dataset 58's record 6 (its 8th line: function and DOF identification,
#: format 2(I5,I10),2(1X,10A1,I10,I4)) as (first column, end column, name); pyuff reads a field it cannot
#: parse there as 0, so 'abcd' in the response node became node 0, silently
DOF_FIELDS = ((0, 5, "function type"), (5, 15, "function id"), (15, 20, "version number"),
              (20, 30, "load case"), (41, 51, "response node"), (51, 55, "response direction"),
              (66, 76, "reference node"), (76, 80, "reference direction"))
DOF_LINE = 7   # record 6 is the 8th line of a dataset 58, after the delimiter, its number and 5 id lines


def _whole_number(text: bytes) -> bool:
    try:
        int(text)
    except ValueError:
        return False
    return True


def _check_dof_line(path: str | Path, head: list[bytes], line: int, error: ErrorType) -> None:
    """``error`` naming the line and field of a dataset 58 whose record 6 holds text that is not a whole
    number in a field of :data:`DOF_FIELDS` (a blank field is left to pyuff and the record checks)."""
    if len(head) <= DOF_LINE:
        return   # a header cut short: pyuff refuses it, and the caller names the dataset
    text = head[DOF_LINE]
    for first, end, name in DOF_FIELDS:
        cell = text[first:end].strip()
        if cell and not _whole_number(cell):
            raise error(f"{path}: line {line + DOF_LINE}: the {name} of this dataset 58 (columns {first + 1}-"
                        f"{end}) is {cell.decode('latin-1')!r}, not a whole number")


def _delimiters(data: bytes) -> list[int]:
    """Offsets of the dataset delimiters, found as pyuff finds them (``    -1`` followed by an end of
    line, the end of the file, or blanks up to column 80), so the blocks named here are its blocks."""
    found, i, end = [], data.find(DELIMITER), len(data)
    while i >= 0:   # a loop over delimiters (two per dataset), not over values
        after = i + len(DELIMITER)
        if after == end or data[after] in (10, 13) or data[after:i + 80] == b" " * (80 - len(DELIMITER)):
            found.append(i)
        i = data.find(DELIMITER, i + 1)
    return found


def check_blocks(path: str | Path, data: bytes, error: ErrorType) -> list[int]:
    """The dataset numbers of a UFF file's datasets, in order, after checking that its text is whole
    datasets: every dataset opened by a ``-1`` delimiter line is closed by one (a file cut short
    loses its last dataset silently in pyuff), the line after the opening delimiter is a dataset
    number (else pyuff skips the dataset), nothing but blank lines lies between datasets, and the
    identification fields of a dataset 58 that pyuff would read as 0 hold whole numbers (:data:`DOF_FIELDS`).
    ``error`` (the caller's error type) names the file and line.

    Examples
    --------
    >>> check_blocks("a.uff", b"    -1\\n    58\\n1\\n    -1\\n", ValueError)
    [58]
    >>> check_blocks("a.uff", b"    -1\\n    58\\n1\\n", ValueError)
    Traceback (most recent call last):
    ...
    ValueError: a.uff: line 1: the dataset opened here has no closing -1 delimiter line (file cut short?)
    """
    def line(offset: int) -> int:
        return data.count(b"\n", 0, offset) + 1

    packed = packed_format(data[:8])   # its bytes were quoted as "line 1: text outside any dataset"
    if packed is not None or data.startswith(HDF5_SIGNATURE):
        what = f"{packed}-compressed: unpack it first" if packed else "an HDF5 file"
        raise error(f"{path}: not Universal File text ({what})")

    def outside(a: int, b: int) -> None:
        text = data[a:b].removeprefix(BOM) if a == 0 else data[a:b]
        if text.strip():
            at = b - len(text.lstrip())
            shown = text.strip()[:40].decode("latin-1")
            raise error(f"{path}: line {line(at)}: text outside any dataset ({shown!r}; each dataset lies "
                        "between two -1 delimiter lines)")

    tags = _delimiters(data)
    if len(tags) % 2:
        raise error(f"{path}: line {line(tags[-1])}: the dataset opened here has no closing -1 delimiter "
                    "line (file cut short?)")
    numbers, previous_end = [], 0
    for start, stop in zip(tags[::2], tags[1::2], strict=True):   # a loop over datasets
        outside(previous_end, start)
        head = data[start:min(stop, start + 1200)].splitlines()   # bytes: LF, CR or CR LF only
        number = head[1][:6].lstrip(b" ") if len(head) > 1 else b""
        if not number.isdigit():
            shown = number.decode("latin-1")
            raise error(f"{path}: line {line(start) + 1}: {shown!r} is not a dataset number (the line after "
                        "an opening -1 delimiter names the dataset type, e.g. 58)")
        numbers.append(int(number))
        if numbers[-1] == 58:
            _check_dof_line(path, head, line(start), error)
        nl = data.find(b"\n", stop)
        previous_end = len(data) if nl < 0 else nl + 1
    outside(previous_end, len(data))
    return numbers
