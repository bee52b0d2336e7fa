"""Issue 24: the argparse option types (checked_io/options.py) and the typed TOML fields
(checked_io/toml_fields.py) accept only numbers a command can compute with.

For any text, an option type either returns a value inside its range that is finite, not subnormal
and not -0.0, or raises ``argparse.ArgumentTypeError`` (one line naming the value); nothing else
escapes.  The texts come from Hypothesis: the extremes of the doubles (subnormals, the largest
finite, signed zeros, nan, inf) written as Python and as TOML writes them, integers of thousands of
digits, and arbitrary text.
"""

from __future__ import annotations

import argparse
import math
import sys

import pytest
from hypothesis import given
from hypothesis import strategies as st

from flexmodal.checked_io import options as opt
from flexmodal.checked_io.errors import FlexmodalError
from flexmodal.checked_io.toml_fields import DOTTED_PATH, KEY_EQUALS, Fields

REALS = {name: getattr(opt, name) for name in ("seconds", "hertz", "rate_hz", "fraction", "overlap",
                                                "instant", "probability", "finite", "positive_hz")}
REALS["bin"] = opt.real(0.0, lo_open=True)
INTEGERS = {name: getattr(opt, name) for name in ("tcp_port", "workers", "seed", "model_order")}
EXTREMES = ["5e-324", "-5e-324", "2.2250738585072014e-308", "2.225073858507201e-308", "1e-300", "1e308",
            "1.7976931348623157e308", "1.8e308", "-0", "-0.0", "+0", "0", "nan", "-nan", "inf", "-inf",
            "Infinity", "1e-9", "9" * 5001, "0x10", "1_000", " 5 ", ""]
numbers = st.one_of(st.floats().map(repr), st.floats().map(str), st.floats(width=32).map(repr),
                    st.integers().map(str), st.sampled_from(EXTREMES), st.text(max_size=40))


def _parsed(parse, text: str):
    """What ``parse`` makes of ``text``, or None when it refused it in one line naming the text."""
    try:
        return parse(text)
    except argparse.ArgumentTypeError as exc:
        assert "\n" not in str(exc) and repr(text) in str(exc)
        return None


def _in_range(parse, value: float, text: str) -> None:
    assert math.isfinite(value), text
    assert value == 0 or abs(value) >= sys.float_info.min, f"{text!r} gave the subnormal {value!r}"
    assert math.copysign(1.0, value) > 0 or value != 0, f"{text!r} gave -0.0"
    assert parse(repr(value)) == value   # what it accepts, it accepts again as written back


@pytest.mark.parametrize("name", sorted(REALS))
@given(text=numbers)
def test_real_options(name: str, text: str) -> None:
    parse = REALS[name]
    value = _parsed(parse, text)
    if value is not None:
        _in_range(parse, value, text)


@pytest.mark.parametrize("name", sorted(INTEGERS))
@given(text=numbers)
def test_integer_options(name: str, text: str) -> None:
    parse = INTEGERS[name]
    value = _parsed(parse, text)
    if value is not None:
        assert isinstance(value, int) and parse(str(value)) == value


@pytest.mark.parametrize(("text", "value"), [("-0", 0.0), ("1e-300", 1e-300), ("2.2250738585072014e-308",
                                                                                 2.2250738585072014e-308)])
def test_zero_and_tiny_normal_numbers_are_taken(text: str, value: float) -> None:
    got = opt.hertz(text)
    assert got == value and math.copysign(1.0, got) == 1.0


@pytest.mark.parametrize("text", ["5e-324", "-4e-320", "2.225073858507201e-308", "1e308", "nan", "inf"])
def test_subnormal_huge_and_not_finite_durations_are_refused(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=text.replace("-", r"\-").replace(".", r"\.")):
        opt.seconds(text)


class _Bad(FlexmodalError):
    pass


@pytest.mark.parametrize("wording", [KEY_EQUALS, DOTTED_PATH], ids=["key-equals", "dotted-path"])
@given(value=st.one_of(st.floats(), st.integers(), st.booleans(), st.text(max_size=10), st.none()))
def test_toml_numbers(wording, value) -> None:
    """A TOML number field (as tomllib hands them: int, float, bool, str) is a finite, normal float (or
    0.0, never -0.0), or one line naming the file and the field."""
    fields = Fields({"x": value}, "f.toml", _Bad, wording=wording)
    try:
        got = fields.number("x")
    except _Bad as exc:
        assert "\n" not in str(exc) and "f.toml" in str(exc) and "x" in str(exc)
        return
    assert isinstance(got, float) and math.isfinite(got)
    assert got == 0 or abs(got) >= sys.float_info.min
    assert math.copysign(1.0, got) == 1.0 or got != 0
