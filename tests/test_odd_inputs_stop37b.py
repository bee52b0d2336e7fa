"""Odd inputs left by the sixth adversarial pass (stop 37, docs: NOTES-safety "Left"): a simulator
fault timed after the end of the stream, a serial layout without its byte order, ...  Each was a
silent answer or a line not naming its cause; each is now one line naming the option, field or value,
exit code 2.  In-process, small files, a few seconds in all."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import REPO
from conftest import one_line as _one_line

from flexmodal.app import main
from flexmodal.daq.errors import DaqError
from flexmodal.daq.serial_frames import FrameSpec
from flexmodal.daq.session import load_session

SESSIONS = REPO / "examples" / "sessions"


def _session(tmp_path: Path, name: str, old: str, new: str, *more: tuple[str, str]) -> Path:
    text = (SESSIONS / name).read_text(encoding="utf-8")
    for a, b in more:
        text = text.replace(a, b)
    text = text.replace("../../fixtures/", str(REPO / "fixtures") + "/")
    text = text.replace("../rigs/", str(REPO / "examples" / "rigs") + "/")
    assert old in text
    (tmp_path / "s.toml").write_text(text.replace(old, new, 1), encoding="utf-8")
    return tmp_path / "s.toml"


# -- a fault timed at or after the end of the stream never happens ---------------------------------------
@pytest.mark.parametrize(("fault", "words"), [
    (["--drop-at", "2"], ("--drop-at 2 s", "--duration 1 s")),
    (["--disconnect-after", "1"], ("--disconnect-after 1 s", "--duration 1 s")),
])
def test_sim_fault_after_the_duration_is_refused(capsys, fault: list[str], words) -> None:
    code = main(["sim", "serve", "--protocol", "serial", "--duration", "1", *fault])   # was: rc 0, no fault
    _one_line(capsys, code, *words, "never happen")


def test_session_fault_after_the_duration_is_refused(tmp_path: Path, capsys) -> None:
    session = _session(tmp_path, "serial-sim.toml", "[simulator]\n", "[simulator]\ndrop_at_s = 3.0\n")
    code = main(["acquire", "--config", str(session), "--out", str(tmp_path / "r.h5"), "--duration", "1"])
    _one_line(capsys, code, "s.toml: simulator: drop_at_s 3 s", "duration 1 s")
    assert not (tmp_path / "r.h5").exists()


# -- a declared serial layout starts with its byte order --------------------------------------------------
@pytest.mark.parametrize("layout", ["12h", "=12h", "!12h", "<", ""])
def test_serial_layout_needs_its_byte_order(layout: str) -> None:
    with pytest.raises(ValueError, match="is not a byte order < or >"):   # '12h' was read as '<12h'
        FrameSpec(b"\xa5\x5a", layout)
    assert FrameSpec(b"\xa5\x5a", ">4h2f").order == ">"


def test_session_serial_layout_without_order_names_the_field(tmp_path: Path) -> None:
    with pytest.raises(DaqError, match=r"s\.toml: .*frame: layout '12h' is not a byte order"):
        load_session(_session(tmp_path, "mcu-serial.toml", 'layout = "<12h"', 'layout = "12h"',
                              ('port = "/dev/ttyACM0"', 'port = "loop://"')))
