"""Typed fields of a parsed TOML document (rig TOML, session TOML): one validation kit for every package.

:class:`Fields` wraps one table of a document read by :func:`flexmodal.checked_io.text.read_toml` and hands
out its values by type: a required or optional number with a range and finiteness, a string from a set,
a whole number, a list, a sub-table.  Each failure raises the calling package's error type (``error``,
e.g. ``DaqError``, ``ModelError``) with one line naming the file, the table and the field.  The words of
that line are the package's :class:`Wording`: :data:`KEY_EQUALS` (``s.toml: channel 'F': kind = 'forse'
is not one of ...``, session configs) or :data:`DOTTED_PATH` (``arm.toml: link[0].length_m: must be > 0
(got -1)``, rig files).  The module imports nothing from the flexmodal packages, so every package may
use it.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from flexmodal.checked_io.text import ErrorType, name_fault


@dataclass(frozen=True)
class Wording:
    """How a package words a bad field; each template is formatted with ``key`` (the field's name),
    ``field`` (its dotted path in the document), ``value`` (its repr), ``kind`` (the expected type,
    in words with its article, :data:`KINDS`), ``options`` (the allowed strings) and ``why``
    (the rule it breaks, e.g. ``must be > 0``)."""

    missing: str
    wrong_type: str
    not_finite: str
    broken_rule: str
    not_in_set: str
    unknown: str
    not_table: str
    kinds: Mapping[type, str] = field(default_factory=dict)


#: the expected type of a value in words, with its article ("is not a whole number", never "a int")
KINDS = {float: "a number", int: "a whole number", str: "a string", bool: "true or false", list: "a list",
         dict: "a table"}
KEY_EQUALS = Wording(
    missing="missing field {field!r}", wrong_type="{field} = {value} is not {kind}",
    not_finite="{field} = {value} is not a finite number", broken_rule="{field} = {value} {why}",
    not_in_set="{field} = {value} is not one of {options}", unknown="unknown field {field!r}",
    not_table="expected a table", kinds=KINDS)
DOTTED_PATH = Wording(
    missing="{field}: missing required field", wrong_type="{field}: must be {kind} (got {value})",
    not_finite="{field}: {why} (got {value})", broken_rule="{field}: {why} (got {value})",
    not_in_set="{field}: unknown value {value} (expected one of {options})", unknown="{field}: unknown field",
    not_table="{field}: must be a table (got {value})",
    kinds=KINDS)


def _number_text(x: float) -> str:
    """``x`` as a reader writes it: 0, 0.5, 86400, 1e7."""
    return f"{x:g}".replace("e+0", "e").replace("e+", "e")


def range_rule(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
               hi_open: bool = False, unit: str = "") -> str:
    """The words of a range: ``must be > 0``, ``must be <= 60 s``, ``must be in [0, 1)``; empty for
    no range."""
    unit = f" {unit}" if unit else ""
    if lo is None and hi is None:
        return ""
    if hi is None:
        return f"must be {'>' if lo_open else '>='} {_number_text(lo)}{unit}"  # type: ignore[arg-type]
    if lo is None:
        return f"must be {'<' if hi_open else '<='} {_number_text(hi)}{unit}"
    return (f"must be in {'(' if lo_open else '['}{_number_text(lo)}, {_number_text(hi)}"
            f"{')' if hi_open else ']'}{unit}")


class Fields:
    """Typed access to one table of a TOML document; failures raise ``error`` naming ``where`` (the
    file, and for :data:`KEY_EQUALS` the item), the table's dotted ``path`` and the field.

    ``ranges`` maps field names to the (lo, hi) range every whole number of that name must lie in
    (e.g. a TCP ``port``: 1..65535)."""

    def __init__(self, doc: Any, where: str, error: ErrorType, *, path: str = "",
                 wording: Wording = KEY_EQUALS, ranges: Mapping[str, tuple[int, int]] | None = None) -> None:
        self.where, self.error, self.path, self.wording = where, error, path, wording
        self.ranges = ranges or {}
        if not isinstance(doc, Mapping):
            raise self._bad("not_table", "", doc)
        self.doc: Mapping[str, Any] = doc

    def field(self, key: str) -> str:
        """The dotted path of ``key`` in the document (the table's path alone for ``key = ""``)."""
        return ".".join(p for p in (self.path, key) if p)

    def fail(self, key: str, what: str) -> Exception:
        """An error naming the file, the field's dotted path and ``what`` is wrong with it."""
        return self.error(f"{self.where}: {self.field(key)}: {what}")

    def _bad(self, template: str, key: str, value: Any, **words: Any) -> Exception:
        text = getattr(self.wording, template).format(key=key, field=self.field(key), value=repr(value),
                                                      **words)
        return self.error(f"{self.where}: {text}")

    def sub(self, key: str, doc: Any) -> Fields:
        """The table ``doc`` found at ``key`` of this one, with the same error type and wording."""
        return Fields(doc, self.where, self.error, path=self.field(key), wording=self.wording,
                      ranges=self.ranges)

    def get(self, key: str, kind: type | tuple[type, ...], default: Any = ..., *,
            check: Callable[[Any], Any] | None = None, why: str = "") -> Any:
        """The value of ``key``, of type ``kind`` (an int is taken for a float; a bool is never a
        number; a float must be finite and not subnormal, and -0.0 is 0.0; ``object`` takes any value),
        passing ``check`` (else ``why`` says the rule it breaks); ``default`` when absent (required when
        no default is given)."""
        if key not in self.doc:
            if default is ...:
                raise self._bad("missing", key, None)
            return default
        value = raw = self.doc[key]  # messages quote the value as written (-1, not -1.0)
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            try:
                value = float(value)
            except OverflowError:   # a TOML integer beyond a float's range (10**400)
                raise self._bad("not_finite", key, raw, why=why) from None
        kinds = kind if isinstance(kind, tuple) else (kind,)
        numeric = bool({int, float} & set(kinds)) and bool not in kinds
        if not isinstance(value, kinds) or (isinstance(value, bool) and numeric):
            name = " or ".join(self.wording.kinds.get(k, f"of type {k.__name__}") for k in kinds)
            raise self._bad("wrong_type", key, raw, kind=name)
        if isinstance(value, float) and not math.isfinite(value):
            raise self._bad("not_finite", key, raw, why=why)
        if isinstance(value, float) and value and abs(value) < sys.float_info.min:
            raise self._bad("broken_rule", key, raw,
                            why=f"must not be subnormal (nonzero, below {sys.float_info.min:.3g})")
        if isinstance(value, float):
            value += 0.0   # -0.0 is 0
        lo, hi = self.ranges.get(key, (None, None)) if isinstance(value, int) else (None, None)
        if lo is not None and not lo <= value <= hi:
            raise self._bad("broken_rule", key, raw, why=f"is out of range {lo}..{hi}")
        if check is not None and not check(value):
            raise self._bad("broken_rule", key, raw, why=why)
        return value

    def name(self, key: str, default: Any = ...) -> str:
        """A name (of a device, channel, run, ...): text with a visible character and no control
        character (:func:`flexmodal.checked_io.text.name_fault`); ``default`` (which may be ``""``)
        when absent."""
        value = self.get(key, str, default)
        fault = name_fault(value) if key in self.doc else None
        if fault:
            raise self._bad("broken_rule", key, value, why=fault)
        return value

    def number(self, key: str, default: Any = ..., *, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False, hi_open: bool = False, unit: str = "", why: str = "") -> float:
        """A finite number in the range from ``lo`` to ``hi`` (open ends excluded); ``why`` replaces the
        range's words (:func:`range_rule`) in the message."""
        def inside(v: float) -> bool:
            return ((lo is None or (v > lo if lo_open else v >= lo))
                    and (hi is None or (v < hi if hi_open else v <= hi)))

        rule = why or range_rule(lo, hi, lo_open=lo_open, hi_open=hi_open, unit=unit)
        return self.get(key, float, default, check=inside, why=rule)

    def choice(self, key: str, options: tuple[str, ...], default: Any = ...) -> str:
        """A string from ``options``."""
        value = self.get(key, str, default)
        if key in self.doc and value not in options:
            raise self._bad("not_in_set", key, value, options=", ".join(options))
        return value

    def table(self, key: str, default: Any = ...) -> Fields:
        """The sub-table at ``key`` (``default``, e.g. ``{}``, when absent)."""
        return self.sub(key, self.get(key, dict, default))

    def numbers(self, key: str) -> dict[str, float]:
        """A table of finite numbers, e.g. a pose (variable name -> value); empty when absent."""
        values = self.table(key, {})
        for name in values.doc:   # names of pose variables: printed in one-line messages and columns
            fault = name_fault(name)
            if fault:
                raise values._bad("broken_rule", name, name, why=f"names a variable that {fault}")
        return {name: values.number(name) for name in values.doc}

    def reject_unknown(self, known: set[str]) -> None:
        """Refuse the first field (alphabetically) not in ``known``."""
        extra = sorted(set(self.doc) - known)
        if extra:
            raise self._bad("unknown", extra[0], None)
