"""Odd inputs of a fourth adversarial pass (stop 35, 26 Nov, night): names that are blank or hold a
control character, FRF groups of another tool (real H, coherence of 2), Welch segments that never
advance, a rig's Poisson ratio, a run written onto a full disk.  Each was a traceback, a crash, a hang
or a silent answer; each class is now one line naming the file and item, exit code 2 (or the family
error from the Python API).  In-process, small files, a few seconds in all."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import REPO
from conftest import one_line as _one_line
from hypothesis import given, settings
from hypothesis import strategies as st

import flexmodal.api as fm
from flexmodal.app import main
from flexmodal.checked_io.text import name_fault
from flexmodal.daq import store
from flexmodal.daq.errors import DaqError
from flexmodal.daq.store import Channel, RunWriter
from flexmodal.modal.errors import ModalError

RIG = (REPO / "examples" / "rigs" / "seed003_two_link.toml").read_text(encoding="utf-8")
SESSION = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text(encoding="utf-8")
POSES = "config,pose.theta_deg\ntheta0,0\n"


def _run(path: Path, names=("F", "a1"), run_id: str = "r1", n: int = 2048) -> Path:
    chans = [Channel(names[0], "force", "N"), Channel(names[1], "acceleration", "m/s^2")]
    rng = np.random.default_rng(0)
    with RunWriter(path, run_id, sample_rate_hz=1024.0, channels=chans, excitation="random",
                   pose={"theta_deg": 0.0}) as w:
        x = rng.standard_normal(n)
        w.append(np.column_stack([x, np.convolve(x, np.exp(-np.arange(50) / 9.0))[:n]]))
    return path


def _rename_channel(g: h5py.Group, name: str) -> None:
    table = g["channels"][...]
    table["name"][1] = name.encode()
    del g["channels"]
    g.create_dataset("channels", data=table)


# -- names: blank, or holding a control character (tab, newline, NUL) ---------------------------------
@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.text(max_size=12))
def test_name_fault_is_total_and_refuses_exactly_blank_and_control_characters(text: str) -> None:
    fault = name_fault(text)
    bad = not text.strip() or any(c in text for c in "\n\r\t\x00\x0b\x0c\x1b\x7f\x85\u2028\u2029")
    assert (fault is not None) == (bad or any(ord(c) < 32 or 127 <= ord(c) < 160 for c in text))


@pytest.mark.parametrize(("change", "words"), [
    (lambda g, f: _rename_channel(g, "a\nb"), ("channel name", "control character")),
    (lambda g, f: _rename_channel(g, "   "), ("channel name", "blank")),
    (lambda g, f: f["runs"].move("r1", "r\t1"), ("run id", "control character")),
    (lambda g, f: f["runs"].move("r1", "  "), ("run id", "blank")),
])
def test_run_files_whose_names_break_lines(tmp_path: Path, capsys, change, words) -> None:
    run = _run(tmp_path / "run.h5")
    with h5py.File(run, "r+") as f:
        change(f["runs/r1"], f)
    code = main(["frf", str(run), "--workers", "0"])   # was: written, and a two-line warning later
    _one_line(capsys, code, "run.h5", *words)


@pytest.mark.parametrize(("file", "text", "argv", "words"), [
    ("m.csv", 'config,mode,freq_hz\n"the\nta0",1,25\n', ["compare", "{d}/m.csv", "{d}/m.csv"],
     ("m.csv", "config", "control character")),
    ("m.csv", 'config,mode,freq_hz,"shape.a\tb"\nt,1,25,1\n', ["compare", "{d}/m.csv", "{d}/m.csv"],
     ("m.csv", "shape.a", "control character")),
    ("p.csv", 'config,pose.theta_deg\n"t\x1b1",0\n',
     ["predict", "{d}/rig.toml", "--model", "fe", "--poses", "{d}/p.csv", "--out", "{d}/o.csv"],
     ("p.csv", "control character")),
    ("rig.toml", RIG.replace('name = "', 'name = "a\\nb', 1),
     ["predict", "{d}/rig.toml", "--model", "fe", "--poses", "{d}/poses.csv", "--out", "{d}/o.csv"],
     ("rig.toml", "name", "control character")),
    ("s.toml", SESSION.replace('name = "a1"', 'name = "  "'),
     ["acquire", "--config", "{d}/s.toml", "--out", "{d}/r.h5", "--duration", "1"],
     ("s.toml", "channel", "blank")),
    ("s.toml", SESSION.replace("pose = { theta_deg = 30.0 }", 'pose = { "a\\tb" = 30.0 }'),
     ["acquire", "--config", "{d}/s.toml", "--out", "{d}/r.h5", "--duration", "1"],
     ("s.toml", "pose", "control character")),
    ("s.toml", SESSION, ["acquire", "--config", "{d}/s.toml", "--out", "{d}/r.h5", "--run-id", "a\nb"],
     ("--run-id", "control character")),
], ids=["config-newline", "shape-tab", "poses-escape", "rig-name-newline", "session-channel-blank",
        "session-pose-tab", "run-id-newline"])
def test_text_files_and_options_whose_names_break_lines(tmp_path: Path, capsys, file, text, argv,
                                                         words) -> None:
    (tmp_path / "rig.toml").write_text(RIG)
    (tmp_path / "poses.csv").write_text(POSES)
    (tmp_path / file).write_text(text.replace('rig = "../rigs/', f'rig = "{REPO}/examples/rigs/'))
    code = main([a.format(d=tmp_path) for a in argv])
    _one_line(capsys, code, *words)


def test_the_api_refuses_a_configuration_named_with_a_newline() -> None:
    with pytest.raises(fm.FlexmodalError, match="control character"):
        fm.predict(REPO / "examples" / "rigs" / "seed003_two_link.toml", {"t\n1": {"theta_deg": 0.0}}, "fe")


# -- a rig's Poisson ratio ---------------------------------------------------------------------------
@pytest.mark.parametrize("nu", ["5", "-1", '"x"', "nan"])
def test_poisson_ratio_out_of_its_range(tmp_path: Path, capsys, nu: str) -> None:
    (tmp_path / "rig.toml").write_text(RIG.replace("rho_kg_m3", f"nu = {nu}\nrho_kg_m3", 1))
    (tmp_path / "poses.csv").write_text(POSES)
    code = main(["predict", str(tmp_path / "rig.toml"), "--model", "fe", "--poses",
                 str(tmp_path / "poses.csv"), "--out", str(tmp_path / "o.csv")])
    _one_line(capsys, code, "rig.toml", ".nu", "(-1, 0.5)")


# -- FRFs of another tool: real H, coherence outside [0, 1] -------------------------------------------
def _frf_group(run: Path, H: np.ndarray, coherence: np.ndarray) -> None:
    with h5py.File(run, "r+") as f:
        g = f["runs/r1"].create_group("frf")
        g.create_dataset("H", data=H)
        g.create_dataset("freq_hz", data=np.arange(H.shape[-1], dtype=float))
        g.create_dataset("coherence", data=coherence)
        g.attrs.update({"estimator": "H1", "window": "hann", "nfft": 64, "n_averages": 4})


@pytest.mark.parametrize(("H", "coherence", "words"), [
    (np.ones((1, 1, 33)), np.ones((1, 33)), ("'H'", "complex")),                # was: identified, phase 0
    (np.ones((1, 1, 33), complex), np.full((1, 33), 2.0), ("'coherence'", "holds 2")),
    (np.ones((1, 1, 33), complex), np.full((1, 33), -np.inf), ("'coherence'", "-inf")),
])
def test_stored_frfs_that_are_not_frfs(tmp_path: Path, capsys, H, coherence, words) -> None:
    run = _run(tmp_path / "run.h5")
    _frf_group(run, H, coherence)
    code = main(["identify", str(run), "--out", str(tmp_path / "m.csv")])
    _one_line(capsys, code, "run.h5", "frf group", *words)


def test_frf_from_arrays_refuses_real_frfs_and_impossible_coherence() -> None:
    f = np.arange(1.0, 5.0)
    with pytest.raises(ModalError, match="holds no phase"):
        fm.frf_from_arrays(f, np.ones((1, 1, 4)))
    with pytest.raises(ModalError, match="outside"):
        fm.frf_from_arrays(f, np.ones((1, 1, 4), complex), coherence=np.full((1, 4), 1.5))


# -- Welch segments that never advance (was ZeroDivisionError) ------------------------------------------
def test_an_overlap_that_leaves_no_step(tmp_path: Path, capsys) -> None:
    run = _run(tmp_path / "run.h5")
    code = main(["frf", str(run), "--workers", "0", "--overlap", "0.999999"])
    _one_line(capsys, code, "--overlap", "0.984375")
    with pytest.raises(ModalError, match="only 0 samples apart"):
        fm.compute_frf(run, nfft=8, overlap=0.95)


# -- a run written onto a full disk (was: a segmentation fault at exit) ---------------------------------
def test_a_full_disk_under_a_run_writer_is_one_error_and_a_closed_file(tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / "run.h5"
    room = iter([10 << 20] * 3 + [1000] * 100)     # room for a few chunks, then the disk is full
    monkeypatch.setattr(store, "disk_room", lambda _path: next(room))
    chans = [Channel(f"c{i}", "acceleration", "m/s^2") for i in range(7)]
    failed = r"run\.h5: run .r.: writing failed after \d+ samples \((No space|File too large)"
    with pytest.raises(DaqError, match=failed):
        with RunWriter(path, "r", sample_rate_hz=2048.0, channels=chans, excitation="impact", pose={}) as w:
            for _ in range(40):
                w.append(np.ones((8192, 7)))
    with h5py.File(path, "r") as f:   # closed, readable; what was flushed is there
        assert f["runs/r/samples"].shape[0] >= 1


# -- SIGTERM and SIGHUP: one line and 128 + N (were: silent exits 143 and 129) -------------------------
STOPPED_INSIDE = """
import signal, sys
import flexmodal.api as api
from flexmodal.app import main
def stopped(*args, **kwargs):
    signal.raise_signal(signal.{name})
    raise AssertionError("the signal did not stop the command")
api.read_table = stopped
sys.argv = ["flexmodal", "compare", "m.csv", "p.csv"]
sys.exit(main())
"""


@pytest.mark.parametrize(("name", "code"), [("SIGTERM", 143), ("SIGHUP", 129)])
def test_a_command_stopped_by_sigterm_or_sighup_says_so(tmp_path: Path, name: str, code: int) -> None:
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", STOPPED_INSIDE.replace("{name}", name)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == code and done.stderr == f"flexmodal: stopped by {name}\n", done.stderr


# -- options and entries the Python API took without a word --------------------------------------------
def test_simulator_options_the_device_does_not_use(capsys) -> None:
    from flexmodal.daq.faults import Faults
    from flexmodal.fixtures.sim_serve import ServeOptions

    for protocol, option, words in [("serial", {"transport": "rtu"}, "--transport applies to modbus"),
                                    ("modbus", {"link": "x"}, "--link applies to serial"),
                                    ("can", {"port": 5020}, "--port applies to modbus over TCP"),
                                    ("can", {"framing": "csv"}, "--framing applies to serial")]:
        with pytest.raises(fm.FlexmodalError, match=words):
            ServeOptions(protocol, **option)
    ServeOptions("modbus", transport="rtu", link="x")   # RTU runs over a pty: its link is used
    with pytest.raises(DaqError, match=r"corrupt_rate = 5\.0 is not a number in \[0, 1\)"):
        Faults(corrupt_rate=5.0)
    with pytest.raises(DaqError, match="drop_s"):
        Faults(drop_s=0.0)


def test_run_entries_named_twice_or_of_three_items(tmp_path: Path, capsys) -> None:
    import os

    run = _run(tmp_path / "run.h5")
    os.link(run, tmp_path / "same.h5")
    code = main(["frf", str(run), str(tmp_path / "same.h5"), "--workers", "0"])
    _one_line(capsys, code, "same.h5:r1", "named twice", "also as")
    with pytest.raises(TypeError, match="run entry"):
        fm.compute_frfs([(run, "r1", "extra")])
    with pytest.raises(TypeError, match="run_id"):
        fm.read_run(run, 5)
    with pytest.raises(TypeError, match="nfft must be a whole number"):
        fm.compute_frf(run, nfft=1024.5)


def test_report_pdf_prints_only_an_html_page(tmp_path: Path) -> None:
    (tmp_path / "m.csv").write_text("config,mode,freq_hz\nt,1,25\n")
    with pytest.raises(fm.FlexmodalError, match="not an HTML page"):
        fm.report_pdf(tmp_path / "m.csv")
    assert not (tmp_path / "m.pdf").exists()


def test_uff_frfs_of_an_ordinate_type_no_frf_has(tmp_path: Path, capsys) -> None:
    import pyuff

    f = np.arange(257) * 0.5
    w, wn = 2 * np.pi * f, 2 * np.pi * 40.0
    records = [dict(type=58, func_type=4, rsp_node=r + 1, rsp_dir=3, ref_node=100, ref_dir=3, x=f,
                    data=-w**2 / (wn**2 - w**2 + 0.04j * wn * w) * (r + 1), id1=f"FRF {r}",
                    rsp_ent_name="NONE", ref_ent_name="NONE", abscissa_spacing=1, abscissa_spec_data_type=18,
                    ordinate_spec_data_type=99 if r else 12, orddenom_spec_data_type=13) for r in range(2)]
    pyuff.UFF(str(tmp_path / "in.uff")).write_sets(records, mode="overwrite")
    code = main(["identify", str(tmp_path / "in.uff"), "--out", str(tmp_path / "m.csv")])
    _one_line(capsys, code, "in.uff", "FRF 2+z", "ordinate data type 99")


# -- a silent device's late samples (were written seconds after their time, as a "restart") ------------
TWO_DEVICES = "sample_rate_hz = 100.0\n" + "".join(
    f'[[device]]\nname = "{d}"\nprotocol = "serial"\nport = "loop://"\nsources = ["ch0"]\n'
    f'[[channel]]\nname = "{d}_x"\nkind = "{k}"\nunit = "N"\ndevice = "{d}"\nsource = "ch0"\n'
    for d, k in (("left", "force"), ("right", "force")))


def test_late_samples_of_a_silent_device_are_dropped_not_placed_now(tmp_path: Path) -> None:
    from flexmodal.daq.devices import Block
    from flexmodal.daq.session import load_session
    from flexmodal.daq.timeline import Timeline

    (tmp_path / "s.toml").write_text(TWO_DEVICES)
    tl = Timeline(load_session(tmp_path / "s.toml"), {"left": ("ch0",), "right": ("ch0",)})

    def block(device: str, first: int, n: int) -> Block:
        return Block(device, first, np.full((n, 1), 1.0 if device == "right" else 2.0), first / 100.0, 0)

    tl.add(block("left", 0, 100))
    tl.add(block("right", 0, 100))
    tl.add(block("left", 100, 300))
    tl.pad("right", 400)                      # right silent: its rows 100..399 released as NaN
    tl.take()
    gap = tl.add(block("right", 100, 50))     # its buffered samples arrive late, in two blocks
    assert [(e.kind, e.sample_index, e.count) for e in gap] == [("gap", 100, 300)]
    assert tl.add(block("right", 150, 50)) == [] and tl.tracks["right"].rows == 400   # dropped, no "restart"
    tl.add(block("right", 400, 100))         # and it goes on where it is due
    tl.add(block("left", 400, 100))
    rows = tl.take()
    assert np.isfinite(rows).all() and rows.shape == (100, 2)
    restart = tl.add(block("right", 0, 10))   # a counter that starts again: a break (NaN row + gap)
    assert [(e.kind, e.sample_index, e.count) for e in restart] == [("gap", 500, 1)]
    assert tl.tracks["right"].rows == 511


@pytest.mark.parametrize("length", [0.001, 0.0])
def test_uff_data_in_other_units_than_si(tmp_path: Path, capsys, length: float) -> None:
    import pyuff

    f = np.arange(257) * 0.5
    w, wn = 2 * np.pi * f, 2 * np.pi * 40.0
    records = [dict(type=164, units_code=2, units_description="mm", temp_mode=2, length=length, force=1.0,
                    temp=1.0, temp_offset=273.15)]
    records += [dict(type=58, func_type=4, rsp_node=r + 1, rsp_dir=3, ref_node=100, ref_dir=3, x=f,
                     data=-w**2 / (wn**2 - w**2 + 0.04j * wn * w) * (r + 1), id1=f"FRF {r}",
                     rsp_ent_name="NONE", ref_ent_name="NONE", abscissa_spacing=1, abscissa_spec_data_type=18,
                     ordinate_spec_data_type=12, orddenom_spec_data_type=13) for r in range(2)]
    pyuff.UFF(str(tmp_path / "in.uff")).write_sets(records, mode="overwrite")
    code = main(["identify", str(tmp_path / "in.uff"), "--out", str(tmp_path / "m.csv")])
    _one_line(capsys, code, "in.uff", "dataset 164", f"length factor {length!r}")   # was read as metres


def test_api_file_arguments_of_another_kind_are_named() -> None:
    for call, words in [(lambda: fm.load_rig(b"rig.toml"), "load_rig: path"),
                        (lambda: fm.list_runs(3), "list_runs: path"),
                        (lambda: fm.read_table(None), "read_table: path"),
                        (lambda: fm.report_pdf(["r.html"]), "report_pdf: html")]:
        with pytest.raises(TypeError, match=f"{words} must be a file path"):
            call()


@pytest.mark.parametrize("refs", ["", "a1,,a2", " , "])
def test_an_empty_name_list_is_not_all_names(tmp_path: Path, capsys, refs: str) -> None:
    code = main(["identify", str(_run(tmp_path / "run.h5")), "--out", str(tmp_path / "m.csv"),
                 "--method", "ssi", "--references", refs])   # "" was taken as every output
    _one_line(capsys, code, "--references", "no empty name")


# -- a set of outputs is complete or absent (was: the modal table left without its sidecars) -----------
def test_outputs_written_together_are_all_or_none(tmp_path: Path, monkeypatch) -> None:
    import errno

    import flexmodal.modal.uff as uff
    import flexmodal.reports.html as report_html

    def disk_full(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device (nothing was written)", str(path))

    f = np.linspace(1.0, 100.0, 397)
    s, w0 = 2j * np.pi * f, 2 * np.pi * 40.0
    ident = fm.identify(fm.frf_from_arrays(f, s**2 / (s**2 + 0.08 * w0 * s + w0**2), outputs=["tip"]))
    monkeypatch.setattr(uff, "write_modes", disk_full)
    with pytest.raises(OSError, match="m.uff"):
        ident.write(tmp_path / "m.csv", uff=tmp_path / "m.uff")
    assert sorted(p.name for p in tmp_path.iterdir()) == []   # no table, synthesis or diagrams, no .part
    result = fm.read_diagnosis(REPO / "tests" / "data" / "diagnosis" / "demo.json")
    monkeypatch.setattr(report_html, "write_report", disk_full)
    with pytest.raises(OSError, match="diagnosis.html"):
        fm.write_diagnosis(result, tmp_path / "D")
    assert list((tmp_path / "D").iterdir()) == []
