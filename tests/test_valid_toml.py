"""Known answers for flexmodal.checked_io.toml_fields, the one TOML field kit of the rig and session
loaders: each getter's accepted values, and each failure's one line in both wordings, with the caller's
error type."""

from __future__ import annotations

import math

import pytest

from flexmodal.checked_io.toml_fields import DOTTED_PATH, KEY_EQUALS, Fields, range_rule
from flexmodal.daq.errors import DaqError
from flexmodal.models.errors import ModelError

DOC = {"rate": 2048, "name": "adc", "flag": True, "port": 70000, "x": math.inf, "kind": "forse",
       "pose": {"theta_deg": 30, "payload_kg": 0.5}, "bad_pose": {"q": "up"}, "items": [1, 2]}


def session() -> Fields:
    return Fields(DOC, "s.toml: device 'adc'", DaqError, ranges={"port": (1, 65535)})


def rig() -> Fields:
    return Fields(DOC, "arm.toml", ModelError, path="link[0]", wording=DOTTED_PATH)


def test_values_are_typed_and_defaults_pass_through() -> None:
    t = session()
    rate = t.number("rate", lo=0, lo_open=True)
    assert rate == 2048.0 and isinstance(rate, float)  # a TOML integer is taken for a float
    assert t.get("name", str) == "adc" and t.get("flag", bool) is True
    assert t.get("absent", int, None) is None and t.number("absent", 0.2, lo=0) == 0.2
    assert t.choice("name", ("adc", "plc")) == "adc" and t.choice("absent", ("a",), "b") == "b"
    assert t.numbers("pose") == {"theta_deg": 30.0, "payload_kg": 0.5} and t.numbers("absent") == {}
    assert t.table("pose").field("theta_deg") == "pose.theta_deg"
    assert rig().field("length_m") == "link[0].length_m" and rig().field("") == "link[0]"
    t.reject_unknown(set(DOC))


@pytest.mark.parametrize("call,session_line,rig_line", [
    (lambda t: t.get("length_m", float), "s.toml: device 'adc': missing field 'length_m'",
     "arm.toml: link[0].length_m: missing required field"),
    (lambda t: t.number("name"), "s.toml: device 'adc': name = 'adc' is not a number",
     "arm.toml: link[0].name: must be a number (got 'adc')"),
    (lambda t: t.number("flag"), "s.toml: device 'adc': flag = True is not a number",
     "arm.toml: link[0].flag: must be a number (got True)"),
    (lambda t: t.get("flag", int), "s.toml: device 'adc': flag = True is not a whole number",
     "arm.toml: link[0].flag: must be a whole number (got True)"),
    (lambda t: t.number("x", lo=0, lo_open=True), "s.toml: device 'adc': x = inf is not a finite number",
     "arm.toml: link[0].x: must be > 0 (got inf)"),
    (lambda t: t.number("rate", lo=0, hi=1e3, lo_open=True, unit="Hz"),
     "s.toml: device 'adc': rate = 2048 must be in (0, 1000] Hz",
     "arm.toml: link[0].rate: must be in (0, 1000] Hz (got 2048)"),
    (lambda t: t.get("name", str, check=lambda v: v == "plc", why="is not the plc"),
     "s.toml: device 'adc': name = 'adc' is not the plc",
     "arm.toml: link[0].name: is not the plc (got 'adc')"),
    (lambda t: t.choice("kind", ("force", "acceleration")),
     "s.toml: device 'adc': kind = 'forse' is not one of force, acceleration",
     "arm.toml: link[0].kind: unknown value 'forse' (expected one of force, acceleration)"),
    (lambda t: t.table("items"), "s.toml: device 'adc': items = [1, 2] is not a table",
     "arm.toml: link[0].items: must be a table (got [1, 2])"),
    (lambda t: t.numbers("bad_pose"), "s.toml: device 'adc': bad_pose.q = 'up' is not a number",
     "arm.toml: link[0].bad_pose.q: must be a number (got 'up')"),
    (lambda t: t.reject_unknown({"rate"}), "s.toml: device 'adc': unknown field 'bad_pose'",
     "arm.toml: link[0].bad_pose: unknown field"),
    (lambda t: t.sub("section", 3), "s.toml: device 'adc': expected a table",
     "arm.toml: link[0].section: must be a table (got 3)"),
])
def test_each_failure_is_one_line_in_the_callers_type_and_wording(call, session_line, rig_line) -> None:
    with pytest.raises(DaqError) as got:
        call(session())
    assert str(got.value) == session_line
    with pytest.raises(ModelError) as got:
        call(rig())
    assert str(got.value) == rig_line


def test_whole_number_ranges_by_field_name() -> None:
    with pytest.raises(DaqError, match=r"^s.toml: device 'adc': port = 70000 is out of range 1..65535$"):
        session().get("port", int)
    assert rig().get("port", int) == 70000  # no range given for the rig


@pytest.mark.parametrize("bounds,words", [
    ({"lo": 0, "lo_open": True}, "must be > 0"), ({"lo": 0}, "must be >= 0"),
    ({"hi": 60, "unit": "s"}, "must be <= 60 s"), ({"lo": 0, "hi": 1, "hi_open": True}, "must be in [0, 1)"),
    ({"lo": 0, "hi": 86400, "unit": "s"}, "must be in [0, 86400] s"), ({}, ""),
])
def test_range_words(bounds, words) -> None:
    assert range_rule(**bounds) == words


def test_range_ends_are_open_or_closed_as_asked() -> None:
    t = Fields({"v": 1.0}, "f", ValueError, wording=KEY_EQUALS)
    assert t.number("v", lo=1.0) == t.number("v", hi=1.0) == 1.0
    for bounds in ({"lo": 1.0, "lo_open": True}, {"hi": 1.0, "hi_open": True}):
        with pytest.raises(ValueError, match="^f: v = 1.0 must be"):
            t.number("v", **bounds)
