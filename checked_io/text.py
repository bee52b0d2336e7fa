"""Text inputs (TOML configs, CSV tables, JSON files): read them as UTF-8 text or fail with one line.

Every loader of flexmodal reads its text files through :func:`read_text` (or :func:`read_toml`,
:func:`loads_json`), which turns the ways a text file goes wrong (missing, a FIFO or a device, a
directory, unreadable, too large, binary, not UTF-8, not TOML, nested too deeply) into one exception
of the calling package's error type whose message names the file, the line and the offending byte.
The module imports nothing from the flexmodal packages, so every package may use it.
"""

from __future__ import annotations

import json
import numbers
import os
import re
import stat
import tomllib
import unicodedata
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

ErrorType = Callable[[str], Exception]
MAX_MESSAGE_CHARS = 300  # a library message quoted in an error line is cut to this length
MAX_TEXT_BYTES = 256 << 20  # a config, table or JSON file larger than this is refused unread
MAX_NESTING = 100  # tables/arrays/objects nested deeper than this in TOML or JSON are refused
FLOAT_MAX_BITS = 1024  # an integer of more bits exceeds the largest float (sys.float_info.max)


NUMBER = re.compile(r"((?:(?<![^\W_])-)?\d+(?:\.\d+)?)")
"""A number in a name (:func:`natural_key`): a digit run with an optional decimal part, and a minus sign
when the ``-`` directly before it opens the name or follows a character that is neither a letter nor a
digit (``=``, ``_``, a space, another ``-``)."""


def _ascii_digits(digits: str) -> str:
    """``digits`` (decimal digits of any script; Arabic-Indic U+0663 is 3) as ASCII digits."""
    return digits if digits.isascii() else "".join(str(unicodedata.decimal(ch)) for ch in digits)


def _number_key(number: str) -> tuple:
    """Sort key of a signed decimal ``number`` (as :data:`NUMBER` matches it) by its value, without
    converting it to an int or a float (a run of more than 4300 digits exceeds Python's int conversion
    limit): the sign, then for a magnitude its integer digits' count and digits, then its decimal digits
    (trailing zeros dropped) -- each reversed for a negative value (digit ``d`` as ``9 - d``, and a
    decimal part that stops ranks above one that goes on).  Equal values get equal keys (``-0``, ``0``
    and ``0.00``; ``7.5`` and ``7.50``)."""
    negative = number.startswith("-")
    whole, _, decimals = number.lstrip("-").partition(".")
    whole, decimals = _ascii_digits(whole).lstrip("0"), _ascii_digits(decimals).rstrip("0")
    if not negative or not (whole or decimals):
        return 1, len(whole), whole, decimals
    flip = str.maketrans("0123456789", "9876543210")
    return 0, -len(whole), whole.translate(flip), decimals.translate(flip) + ":"   # ':' sorts after '9'


def natural_key(text: str) -> list:
    """Sort key that orders the numbers in names by value (``theta60`` before ``theta120``,
    ``theta=-30`` before ``theta=-15`` before ``theta=0``, ``theta7.25`` before ``theta7.5``):
    configurations and runs are listed in this order everywhere (tables, CSV files, reports, diagnosis
    text).  Names whose numbers have equal values are then ordered as text (``theta01`` before
    ``theta1``).  A number of any length is compared (no int or float conversion: a name of 5000 digits
    sorts too).

    A number is a run of decimal digits with an optional decimal part (``7.25``; a second point ends it:
    ``1.2.3`` is 1.2, ``.``, 3, so version-like names sort as decimals, ``v1.10`` before ``v1.9``), and
    is negative when a ``-`` directly before it opens the name or follows a character that is neither a
    letter nor a digit: ``theta=-15`` (the names ``identify --track`` gives), ``theta_-30``, ``-30``.
    After a letter or a digit a ``-`` is a hyphen, as in ``run-3``, ``theta30-impact`` or ``theta0-90``:
    ``run-1``, ``run-2``, ``run-3`` keep their order, and ``theta-30`` reads as a hyphen and 30.
    Exponents are not read (``1e-05`` is 1, ``e-``, 5).

    Examples
    --------
    >>> sorted(["theta150", "theta30", "theta0", "theta120"], key=natural_key)
    ['theta0', 'theta30', 'theta120', 'theta150']
    >>> sorted(["theta=30", "theta=7.5", "theta=-15", "theta=2.5", "theta=-30", "theta=0", "theta=7.25"],
    ...        key=natural_key)
    ['theta=-30', 'theta=-15', 'theta=0', 'theta=2.5', 'theta=7.25', 'theta=7.5', 'theta=30']
    >>> sorted(["run-3", "run-10", "run-1", "theta30-impact", "theta0-impact"], key=natural_key)
    ['run-1', 'run-3', 'run-10', 'theta0-impact', 'theta30-impact']
    >>> sorted(["theta1a", "theta1", "theta001b", "theta01", "theta1.0"], key=natural_key)
    ['theta01', 'theta1', 'theta1.0', 'theta1a', 'theta001b']
    >>> [len(n) for n in sorted(["c" + "9" * 5000, "c" + "1" * 5001, "c7"], key=natural_key)]
    [2, 5001, 5002]
    >>> [len(n) for n in sorted(["9" * 5000, "-" + "9" * 5000, "7", "-" + "1" * 5001], key=natural_key)]
    [5002, 5001, 1, 5000]
    """
    parts = NUMBER.split(text)   # text at even places, numbers at odd places
    return [[_number_key(t) if k % 2 else t for k, t in enumerate(parts)], text]


def natural_order(names: Iterable[str]) -> list[str]:
    """``names`` without repeats, in natural order (:func:`natural_key`)."""
    return sorted(set(names), key=natural_key)


def one_line(text: object, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``text`` with every run of whitespace (newlines included) collapsed to one space, at most
    ``limit`` characters: library messages quoted inside a one-line error."""
    flat = " ".join(str(text).split())
    return flat if len(flat) <= limit else flat[:limit - 3] + "..."


def shown_value(value: object, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``value`` as an error line quotes it (``attribute nfft = 16777218``): a number as written, any
    other value as one line of text (:func:`one_line`) cut to ``limit`` characters, in quotes.

    Examples
    --------
    >>> shown_value(16777218), shown_value(2.5), shown_value("16777218"), shown_value("a\\n  b")
    ('16777218', '2.5', "'16777218'", "'a b'")
    """
    return str(value) if isinstance(value, numbers.Number) else repr(one_line(value, limit))


@contextmanager
def naming(where: str | Path, error: type[Exception]) -> Iterator[None]:
    """Errors of type ``error`` raised inside that do not name ``where`` (a file, or ``FILE:RUN``) are
    raised again, same type, as ``"{where}: {message}"``: every error line about a file names it."""
    try:
        yield
    except error as exc:
        if str(where) in str(exc):
            raise
        raise type(exc)(f"{where}: {exc}") from None


def available_memory_bytes() -> int:
    """Memory the system can give this process now (Linux ``MemAvailable``; else its free pages):
    the bound of inputs read whole into memory and of matrices allocated from them."""
    try:
        with open("/proc/meminfo", "rb") as fh:
            for line in fh:
                if line.startswith(b"MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def file_kind(mode: int) -> str:
    """What a file that is not a regular file is, in words (from its ``stat`` mode)."""
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def not_empty_path(path: str | Path, error: ErrorType, what: str) -> None:
    """Raise ``error`` when ``path`` is an empty or blank text (``--rig ""``, a script's unset
    variable), which ``Path`` would read as the current folder '.'.

    Parameters
    ----------
    path : str or Path
        The path as given.
    error : type of Exception
        The calling package's error type.
    what : str
        What the path names, for the message ("rig file").

    Examples
    --------
    >>> not_empty_path("rig.toml", ValueError, "rig file")
    >>> not_empty_path(" ", ValueError, "rig file")
    Traceback (most recent call last):
    ...
    ValueError: the rig file path is empty (' '; an unset variable in a script?)
    """
    if isinstance(path, str) and not path.strip():
        raise error(f"the {what} path is empty ({path!r}; an unset variable in a script?)")


def regular_file(path: str | Path, error: ErrorType, what: str = "file") -> Path:
    """``path`` when it names an existing regular file (symlinks followed); a FIFO, a device (it
    would block or never end), a socket or a directory raises ``error`` naming the file.  An empty
    path (``--rig ""``, a script's unset variable) is refused as empty, not read as the folder '.'."""
    not_empty_path(path, error, what)
    p = Path(path)
    try:
        mode = os.stat(p).st_mode
    except FileNotFoundError:
        raise error(f"{p}: {what} not found") from None
    except OSError as exc:
        raise error(f"{p}: cannot read the {what} ({exc.strerror or one_line(exc)})") from None
    if stat.S_ISDIR(mode):
        raise error(f"{p}: is a directory, expected a {what}")
    if not stat.S_ISREG(mode):
        raise error(f"{p}: is {file_kind(mode)}, not a regular file (expected a {what})")
    return p


def fits_in_memory(path: str | Path, error: ErrorType, what: str = "file", factor: int = 4) -> Path:
    """``path`` (a regular file, :func:`regular_file`) when ``factor`` times its size fits in the
    available memory (a parser that holds the text and its arrays at once); else ``error`` naming it."""
    p = regular_file(path, error, what)
    size, room = p.stat().st_size, available_memory_bytes()
    if size > room // factor:
        raise error(f"{p}: {size / 2**30:.1f} GiB is too large to read with the {room / 2**30:.1f} GiB "
                    "of memory available")
    return p


def read_bytes(path: str | Path, error: ErrorType, what: str = "file",
               limit_bytes: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of an existing regular file of at most ``limit_bytes``; ``error`` names the file when
    it is missing, unreadable, not a regular file (a FIFO or ``/dev/zero`` is never waited on or read
    without end) or too large."""
    p = regular_file(path, error, what)
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # never waits, even if swapped for a FIFO
        with os.fdopen(fd, "rb") as fh:
            st = os.fstat(fh.fileno())
            if not stat.S_ISREG(st.st_mode):
                raise error(f"{p}: is {file_kind(st.st_mode)}, not a regular file (expected a {what})")
            data = fh.read(limit_bytes + 1)
    except OSError as exc:
        raise error(f"{p}: cannot read the {what} ({exc.strerror or one_line(exc)})") from None
    if len(data) > limit_bytes:
        raise error(f"{p}: larger than {limit_bytes >> 20} MiB, too large for a {what}")
    return data


def decode_text(data: bytes, where: str | Path, error: ErrorType, what: str = "text file") -> str:
    """Decode UTF-8 (an optional byte-order mark is dropped) into Unicode normal form C (composed
    characters: names that look alike are alike); a NUL byte or an invalid UTF-8 sequence raises
    ``error`` naming the line and the byte."""
    nul = data.find(b"\x00")
    if nul >= 0:
        line = data.count(b"\n", 0, nul) + 1
        raise error(f"{where}: line {line}: binary data (NUL byte at offset {nul}), not a {what}")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise error(f"{where}: line {line}: byte 0x{data[exc.start]:02x} at offset {exc.start} is not "
                    f"UTF-8 (save the {what} as UTF-8)") from None
    return nfc(text)


def nfc(text: str) -> str:
    """``text`` in Unicode normal form C: one spelling per name ('é' typed as e + a combining accent,
    as macOS file tools write it, and as one character look alike and would name two configs, sensors
    or pose variables).

    Examples
    --------
    >>> nfc("the\u0301ta0") == "th\u00e9ta0"
    True
    """
    return text if text.isascii() else unicodedata.normalize("NFC", text)


#: Unicode's bidirectional controls (embeddings, overrides, isolates, marks): invisible, and they show
#: a name's characters in another order ('\u202etheta0' shows as '0ateht'), so two names that read
#: alike are different and a table or terminal line shows what is not there
BIDI_CONTROLS = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def name_fault(name: str) -> str | None:
    """Why ``name`` cannot name a thing a user picks by name (a channel, run, configuration, sensor,
    link, pose variable), or None when it can: it must hold a visible character, and no control
    character or line break (a tab, newline or NUL would split the one-line messages, tables and
    CSV rows it is printed in, and ``'   '`` looks like no name at all), and no bidirectional control
    (:data:`BIDI_CONTROLS`).

    Examples
    --------
    >>> name_fault("a1"), name_fault("théta 0")
    (None, None)
    >>> name_fault("   "), name_fault("a\\nb")
    ('is blank', "holds the control character '\\\\n'")
    """
    if not name.strip():
        return "is blank"
    for ch in name:
        if unicodedata.category(ch) in ("Cc", "Zl", "Zp"):
            return f"holds the control character {ch!r}"
        if ch in BIDI_CONTROLS:
            return f"holds the bidirectional control U+{ord(ch):04X}, which reorders how the text is shown"
    return None


def read_text(path: str | Path, error: ErrorType, what: str = "text file",
              limit_bytes: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of ``path`` of at most ``limit_bytes`` (see :func:`read_bytes`, :func:`decode_text`)."""
    return decode_text(read_bytes(path, error, what, limit_bytes), path, error, what)


def _depth(doc: object) -> tuple[int, int | None]:
    """Nesting depth of a parsed document (lists and dicts; iterative, so any depth is measured) and
    its first integer too large for a float (beyond about 1.8e308), or None."""
    deepest, huge, stack = 0, None, [(doc, 1)]
    while stack:
        node, level = stack.pop()
        if isinstance(node, dict | list):
            deepest = max(deepest, level)
            stack.extend((child, level + 1) for child in (node.values() if isinstance(node, dict) else node))
        elif isinstance(node, int) and not isinstance(node, bool) and huge is None \
                and abs(node).bit_length() > FLOAT_MAX_BITS:
            huge = node
    return deepest, huge


def _parsed(doc: object, where: str | Path, error: ErrorType, what: str) -> object:
    deepest, huge = _depth(doc)
    if deepest > MAX_NESTING:
        raise error(f"{where}: nested more than {MAX_NESTING} levels deep, not a {what}")
    if huge is not None:
        digits = str(abs(huge))  # at most sys.get_int_max_str_digits() digits: the parser made it
        raise error(f"{where}: the integer {'-' if huge < 0 else ''}{digits[:12]}... ({len(digits)} digits) "
                    "is too large for a number (at most about 1.8e308)")
    return doc


class _DuplicateKey(ValueError):
    """A JSON object names a key twice (raised by :func:`_unique_keys`, reported by :func:`loads_json`)."""


def _unique_keys(items: list[tuple[str, object]]) -> dict:
    """A JSON ``object_pairs_hook`` refusing an object that names a key twice (json keeps the last
    silently; TOML and the CSV headers refuse it too)."""
    out: dict = {}
    for key, value in items:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def read_toml(path: str | Path, error: ErrorType, what: str = "TOML file") -> dict:
    """Parse a UTF-8 TOML file (TOML 1.0 via :mod:`tomllib`); a syntax error names its line and column,
    nesting deeper than :data:`MAX_NESTING` and integers longer than Python converts are refused."""
    text = read_text(path, error, what)
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML ({one_line(exc)})") from None
    except RecursionError:
        raise error(f"{path}: nested too deeply, not a {what}") from None
    except ValueError as exc:  # an integer of more than sys.get_int_max_str_digits() digits
        raise error(f"{path}: not a valid {what} ({one_line(exc)})") from None
    return _parsed(doc, path, error, what)  # type: ignore[return-value]


def loads_json(text: str | bytes, where: str | Path, error: ErrorType, what: str = "JSON text") -> object:
    """Parse JSON text read from ``where``; a syntax error, nesting deeper than :data:`MAX_NESTING`,
    or an integer longer than Python converts raise ``error`` naming ``where``."""
    try:
        doc = json.loads(text, object_pairs_hook=_unique_keys)
    except json.JSONDecodeError as exc:
        raise error(f"{where}: not valid JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})") from None
    except RecursionError:
        raise error(f"{where}: nested too deeply, not a {what}") from None
    except _DuplicateKey as exc:
        raise error(f"{where}: key {one_line(exc.args[0])[:60]!r} appears twice in one object, not a "
                    f"valid {what}") from None
    except (ValueError, TypeError) as exc:
        raise error(f"{where}: not a valid {what} ({one_line(exc)})") from None
    return _parsed(doc, where, error, what)
