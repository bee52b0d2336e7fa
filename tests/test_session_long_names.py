"""A session file naming a path longer than the file system allows (a rig file, a serial port) is refused
in one line naming the field: pathlib's exists() raises OSError ENAMETOOLONG there instead of returning
False, and the hypothesis long fuzz of session files found it as a traceback (stop 41)."""
from __future__ import annotations

from pathlib import Path

import pytest

from flexmodal.daq.errors import DaqError
from flexmodal.daq.session import load_session

REPO = Path(__file__).resolve().parents[1]
LONG = "x" * 5000   # over NAME_MAX (255) and PATH_MAX (4096) of every common file system


@pytest.mark.parametrize("field, old, new", [
    ("rig file", 'rig = "../rigs/demo_arm.toml"', f'rig = "{LONG}"'),
    ("port", 'port = "@simulator"', f'port = "/dev/{LONG}"'),
])
def test_a_path_too_long_to_look_up_is_refused_naming_its_field(tmp_path: Path, field: str, old: str,
                                                                new: str) -> None:
    text = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text(encoding="utf-8")
    assert old in text
    rig = (REPO / "examples" / "rigs" / "demo_arm.toml").as_posix()   # the copy is read from tmp_path
    text = text.replace(old, new, 1).replace('rig = "../rigs/demo_arm.toml"', f'rig = "{rig}"')
    path = tmp_path / "session.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DaqError) as info:
        load_session(path)
    message = str(info.value)
    assert "\n" not in message and field in message and len(message) < 400, message
    assert "cannot be looked up (File name too long, " in message
