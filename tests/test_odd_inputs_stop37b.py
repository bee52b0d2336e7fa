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
from flexmodal.modal.errors import ModalError

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
    _one_line(capsys, code, "s.toml: simulator: drop_at_s 3 s", "(--duration 1 s)")
    assert not (tmp_path / "r.h5").exists()


def test_sim_hit_fault_past_the_record_is_refused() -> None:
    import flexmodal.api as fm
    from flexmodal.fixtures.errors import FixtureError

    with pytest.raises(FixtureError, match=r"double_hit_at_s \(--double-hit-at\) = 5000 s is past the end"):
        fm.serve_simulator("serial", duration=0.2, faults={"double_hit_at_s": 5000.0}, quiet=True)   # numpy


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


# -- a tracking hop longer than its window -------------------------------------------------------------
def test_track_hop_longer_than_the_window_is_refused(tmp_path: Path, capsys) -> None:
    from flexmodal.fixtures.examples import moving_run  # a simulated moving-arm record

    path = moving_run(tmp_path)
    code = main(["identify", str(path), "--track", "--out", str(tmp_path / "m.csv"), "--window", "2",
                 "--hop", "3"])   # was "no mode was followed over enough windows to map"
    _one_line(capsys, code, "--hop", "3 s is longer than the 2 s window (--window)")
    assert not (tmp_path / "m.csv").exists()


def test_track_hop_equal_to_the_window_is_planned() -> None:
    import numpy as np

    from flexmodal.modal.track import TrackOptions, window_plan

    plan = window_plan(8192, 1024.0, np.zeros((8192, 0)), 10.0, TrackOptions(window_s=2.0, hop_s=2.0))
    assert plan == (2048, 2048)
    with pytest.raises(ModalError, match="its default"):
        window_plan(8192, 1024.0, np.zeros((8192, 0)), 40.0, TrackOptions(hop_s=5.0))   # default 2 s


# -- a configuration measured and predicted over other pose variables -----------------------------------
def test_compare_refuses_a_config_of_other_pose_variables(tmp_path: Path, capsys) -> None:
    (tmp_path / "m.csv").write_text("config,mode,freq_hz,pose.theta_deg\nc1,1,25.5,30\n", encoding="utf-8")
    (tmp_path / "p.csv").write_text("config,mode,freq_hz,source,pose.phi_deg\nc1,1,25.0,fe,30\n",
                                    encoding="utf-8")
    code = main(["compare", str(tmp_path / "m.csv"), str(tmp_path / "p.csv")])   # was paired, rc 0
    _one_line(capsys, code, "config 'c1'", "pose theta_deg (", "pose phi_deg (", "differ")
    (tmp_path / "p.csv").write_text("config,mode,freq_hz,source,pose.theta_deg,pose.payload_kg\n"
                                    "c1,1,25.0,fe,30,0.5\n", encoding="utf-8")   # more fixed: compared
    assert main(["compare", str(tmp_path / "m.csv"), str(tmp_path / "p.csv")]) == 0


# -- --run chooses a run of an HDF5 store, never of a UFF file ---------------------------------------------
@pytest.mark.parametrize("track", [[], ["--track"]])
def test_identify_run_on_a_uff_file_is_refused(tmp_path: Path, capsys, track: list[str]) -> None:
    uff = REPO / "tests" / "data" / "realdata" / "ufffiles_analyser_frf" / "dataset58_FRF.unv"
    code = main(["identify", str(uff), *track, "--run", "r1", "--out", str(tmp_path / "m.csv")])   # ignored
    _one_line(capsys, code, "dataset58_FRF.unv: --run r1", "applies to HDF5 run stores")
    assert not (tmp_path / "m.csv").exists()


# -- pose variables differing only by case -----------------------------------------------------------------
@pytest.mark.parametrize("header", ["config,pose.theta_deg,pose.Theta_deg",
                                    "config,pose.THETA_DEG,pose.theta_deg"])
def test_pose_names_differing_only_by_case_are_refused(tmp_path: Path, capsys, header: str) -> None:
    import flexmodal.api as fm
    from flexmodal.contract.errors import ContractError

    (tmp_path / "poses.csv").write_text(f"{header}\nc1,0,30\n", encoding="utf-8")   # were two variables
    first, second = header.split(",")[1:]
    with pytest.raises(ContractError, match=f"columns '{first}' and '{second}' differ only by case"):
        fm.read_poses(tmp_path / "poses.csv")
    (tmp_path / "m.csv").write_text(f"{header},mode,freq_hz\nc1,0,30,1,25.5\n", encoding="utf-8")
    _one_line(capsys, main(["compare", str(tmp_path / "m.csv"), str(tmp_path / "m.csv")]), first, second,
              "differ only by case")


# -- a DBC signal's unit against the channel's sensitivity ------------------------------------------------
def test_a_dbc_signal_in_volts_under_a_sensitivity_in_mv_is_refused(tmp_path: Path, capsys) -> None:
    text = (REPO / "fixtures" / "flexmodal_sim.dbc").read_text(encoding="utf-8")
    old = 'SG_ a1 m0 : 32|16@1- (0.30517578125,0.0) [0|0] "mV"'
    assert old in text
    (tmp_path / "v.dbc").write_text(text.replace(old, old.replace('"mV"', '"V"')), encoding="utf-8")
    session = _session(tmp_path, "can-sim.toml", 'dbc = "', f'dbc = "{tmp_path / "v.dbc"}"  # ',)
    code = main(["acquire", "--config", str(session), "--out", str(tmp_path / "r.h5"), "--duration", "0.5"])
    _one_line(capsys, code, "s.toml: channel 'a1': source 'a1' is in V", "expects mV (100 mV/g)",
              "scale = 1000")   # was read as mV: accelerations 1000x too small, rc 0


def test_dbc_units_and_scale_of_the_documented_module() -> None:
    from flexmodal.daq.dbc import load_messages
    from flexmodal.daq.session import ChannelMap, source_unit_fault
    from flexmodal.daq.store import Channel

    signals = {s.name: s for lay in load_messages(str(SESSIONS / "can-module.dbc"), ["ScanA", "ScanB"])
               for s in lay.signals}
    assert signals["a0"].unit == "mm/s^2"   # docs/acquisition.md: can-module.toml gives scale = 0.001
    a0 = Channel("a0", "acceleration", "m/s^2")
    assert source_unit_fault(ChannelMap(a0, "canmod", "a0", scale=0.001), "mm/s^2") is None
    fault = source_unit_fault(ChannelMap(a0, "canmod", "a0"), "mm/s^2")
    assert "give scale = 0.001 (mm/s^2 to m/s^2)" in fault
    assert source_unit_fault(ChannelMap(a0, "canmod", "a0"), "counts") is None   # not judged


def test_session_pose_names_differing_only_by_case_are_refused(tmp_path: Path) -> None:
    with pytest.raises(DaqError, match="pose variables 'theta_deg' and 'Theta_deg' differ only by case"):
        load_session(_session(tmp_path, "serial-sim.toml", "pose = { theta_deg = 30.0 }",
                              "pose = { theta_deg = 30.0, Theta_deg = 60.0 }"))
