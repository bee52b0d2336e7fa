"""Text inputs (TOML configs, CSV tables, JSON files): read them as UTF-8 text or fail with one line.

Every loader of flexmodal reads its text files through :func:`read_text` (or :func:`read_toml`), which
turns the ways a text file goes wrong (missing, a directory, unreadable, binary, not UTF-8, not TOML)
into one exception of the calling package's error type whose message names the file, the line and the
offending byte.  The module imports nothing from the flexmodal packages, so every package may use it.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

ErrorType = Callable[[str], Exception]
MAX_MESSAGE_CHARS = 300  # a library message quoted in an error line is cut to this length


def one_line(text: object) -> str:
    """``text`` with every run of whitespace (newlines included) collapsed to one space, at most
    :data:`MAX_MESSAGE_CHARS` characters: library messages quoted inside a one-line error."""
    flat = " ".join(str(text).split())
    return flat if len(flat) <= MAX_MESSAGE_CHARS else flat[:MAX_MESSAGE_CHARS - 3] + "..."


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


def read_bytes(path: str | Path, error: ErrorType, what: str = "file") -> bytes:
    """The bytes of an existing regular file; ``error`` names the file when it is missing or unreadable."""
    p = Path(path)
    if not p.exists():
        raise error(f"{p}: {what} not found")
    if p.is_dir():
        raise error(f"{p}: is a directory, expected a {what}")
    try:
        return p.read_bytes()
    except OSError as exc:
        raise error(f"{p}: cannot read the {what} ({exc.strerror or one_line(exc)})") from None


def decode_text(data: bytes, where: str | Path, error: ErrorType, what: str = "text file") -> str:
    """Decode UTF-8 (an optional byte-order mark is dropped); a NUL byte or an invalid UTF-8 sequence
    raises ``error`` naming the line and the byte."""
    nul = data.find(b"\x00")
    if nul >= 0:
        line = data.count(b"\n", 0, nul) + 1
        raise error(f"{where}: line {line}: binary data (NUL byte at offset {nul}), not a {what}")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise error(f"{where}: line {line}: byte 0x{data[exc.start]:02x} at offset {exc.start} is not "
                    f"UTF-8 (save the {what} as UTF-8)") from None


def read_text(path: str | Path, error: ErrorType, what: str = "text file") -> str:
    """The UTF-8 text of ``path`` (see :func:`decode_text`)."""
    return decode_text(read_bytes(path, error, what), path, error, what)


def read_toml(path: str | Path, error: ErrorType, what: str = "TOML file") -> dict:
    """Parse a UTF-8 TOML file (TOML 1.0 via :mod:`tomllib`); a syntax error names its line and column."""
    text = read_text(path, error, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML ({one_line(exc)})") from None
