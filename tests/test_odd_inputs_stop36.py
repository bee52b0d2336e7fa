"""Odd inputs of a fifth adversarial pass (stop 36, 27 Nov, night): a mass or spring placed on the
ground, NaN/Infinity/null in a diagnosis.json, an API GIF written over its own modal table, a path
string where a list of runs belongs, comma lists with an empty item, bytes that are not UTF-8 in a
run's tables, a gzipped run file, a device counter that starts again.  Each was a traceback, a lost
input, a silent answer or a line naming the wrong thing; each class is now one line naming the file
and item, exit code 2 (or the family error / TypeError from the Python API).  In-process, small
files, a few seconds in all."""

from __future__ import annotations

import argparse
import gzip
import inspect
import json
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
from flexmodal.checked_io import options as opt
from flexmodal.checked_io.output import output_file
from flexmodal.compare.errors import CompareError
from flexmodal.compare.result import Diagnosis
from flexmodal.daq import store
from flexmodal.daq.devices import Block
from flexmodal.daq.errors import DaqError
from flexmodal.daq.store import Channel, Event, RunWriter
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import _parse_point, load_rig
from flexmodal.reports.errors import ReportError

RIG = (REPO / "examples" / "rigs" / "seed003_two_link.toml").read_text(encoding="utf-8")
MODES = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"
DIAGNOSIS = (REPO / "tests" / "data" / "diagnosis" / "demo.json").read_text(encoding="utf-8")
BAR = 'section = { shape = "solid_rect", width_m = 0.01, height_m = 0.01 }\nmaterial = "aluminium"'


# -- rig points: ground@x,y only for a member's end, and finite ---------------------------------------
@pytest.mark.parametrize(("extra", "words"), [
    ('[[mass]]\nat = "ground@0,0"\nmass_kg = 1.0', ("mass[0].at", "ground point")),         # KeyError: None
    ('[[spring]]\nat = "ground@0.2,0"\nk_N_per_m = 100.0', ("spring[0].at", "ground point")),
    ('[[sensor]]\nname = "g"\nat = "ground@0,0"', ("sensor[3].at", "ground point")),
    (f'[[member]]\nname = "p"\nfrom = "ground@inf,0"\nto = "link2@0.1"\n{BAR}',             # "0 modes"
     ("member[0].from", "finite")),
    (f'[[member]]\nname = "p"\nfrom = "ground@0.1,nan"\nto = "link2@0.1"\n{BAR}',
     ("member[0].from", "finite")),
    (f'[[member]]\nname = "p"\nfrom = "ground@1"\nto = "link2@0.1"\n{BAR}', ("member[0].from", "position")),
])
def test_points_on_the_ground(tmp_path: Path, capsys, extra: str, words: tuple[str, ...]) -> None:
    (tmp_path / "rig.toml").write_text(RIG + "\n" + extra + "\n", encoding="utf-8")
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\nt0,0\n", encoding="utf-8")
    code = main(["predict", str(tmp_path / "rig.toml"), "--model", "fe",
                 "--poses", str(tmp_path / "poses.csv"), "--out", str(tmp_path / "p.csv")])
    _one_line(capsys, code, "rig.toml", *words)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.one_of(st.text(max_size=16), st.from_regex(r"(ground|link1|link2|elbow|tip)@[-0-9.,naife+]{0,10}",
                                                     fullmatch=True)),
       st.booleans())
def test_point_parser_is_total(text: str, ground: bool) -> None:
    """Any text is a point or a ModelError: never a KeyError or a point at an infinite place."""
    links = load_rig_links()
    try:
        p = _parse_point(text, links, "at", "rig.toml", ground=ground)
    except ModelError:
        return
    if p.link is None:
        assert ground and all(np.isfinite(p.ground_xy_m))
    else:
        assert p.link in links[0] and 0.0 <= p.fraction <= 1.0


def load_rig_links():
    rig = _rig_cache.get("rig")
    if rig is None:
        import tempfile

        path = Path(tempfile.mkdtemp()) / "rig.toml"
        path.write_text(RIG, encoding="utf-8")
        rig = _rig_cache.setdefault("rig", load_rig(path))
    return {lk.name: lk for lk in rig.links}, {j.name: j for j in rig.joints}


_rig_cache: dict = {}


# -- diagnosis.json: numbers a strict document cannot hold ---------------------------------------------
def _mutated(key_path: tuple[str, ...], raw: str) -> str:
    doc = json.loads(DIAGNOSIS)
    node = doc
    for k in key_path[:-1]:
        node = node[k]
    node[key_path[-1]] = "@@"
    return json.dumps(doc).replace('"@@"', raw)


@pytest.mark.parametrize(("key_path", "raw", "words"), [
    (("baseline", "rms_rel_error"), "NaN", "baseline.rms_rel_error: expected a number"),   # TypeError later
    (("baseline", "rms_rel_error"), "Infinity", "baseline.rms_rel_error: expected a number"),
    (("verdict", "heldout_rms_rel_error_before"), "null", "verdict.heldout_rms_rel_error_before"),
    (("baseline", "max_rel_error"), "-5", "is negative"),                                 # silently drawn
    (("baseline", "per_mode"), '{"one": 0.1}', "key 'one' is not a mode number"),
    (("baseline", "per_mode"), '{"' + "1" * 5000 + '": 0.1}', "...' is not a mode number"),  # no int()
    (("baseline", "per_mode"), '{"0": 0.1}', "key '0' is not a mode number"),
])
def test_a_diagnosis_document_with_impossible_numbers(tmp_path: Path, capsys, key_path, raw, words) -> None:
    with pytest.raises(CompareError, match=words):
        Diagnosis.from_json(_mutated(key_path, raw))
    (tmp_path / "d.json").write_text(_mutated(key_path, raw), encoding="utf-8")
    code = main(["report", "--measured", str(MODES), "--diagnosis", str(tmp_path / "d.json"),
                 "--out", str(tmp_path / "r.html")])
    _one_line(capsys, code, "d.json", words)
    assert not (tmp_path / "r.html").exists()


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.one_of(st.none(), st.booleans(), st.floats(allow_nan=True, allow_infinity=True), st.integers(),
                 st.text(max_size=5), st.lists(st.integers(), max_size=2)))
def test_diagnosis_reader_is_total_on_a_number_field(value) -> None:
    """Whatever stands for ``baseline.rms_rel_error``: a finite number >= 0 is read, all else is a
    CompareError (never a None that a report compares later)."""
    raw = json.dumps(value) if not isinstance(value, float) or np.isfinite(value) else \
        ("NaN" if np.isnan(value) else ("Infinity" if value > 0 else "-Infinity"))
    try:
        d = Diagnosis.from_json(_mutated(("baseline", "rms_rel_error"), raw))
    except CompareError:
        return
    assert isinstance(d.baseline.rms_rel_error, float) and 0 <= d.baseline.rms_rel_error < float("inf")


def test_format_and_write_diagnosis_take_what_the_other_functions_take(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="expected a diagnosis"):
        fm.format_diagnosis(None)                      # AttributeError: 'NoneType' ... 'verdict'
    with pytest.raises(TypeError, match="expected a diagnosis"):
        fm.write_diagnosis(None, tmp_path / "D")
    assert not (tmp_path / "D").exists()
    assert fm.format_diagnosis(json.loads(DIAGNOSIS)).startswith("verdict: ")


# -- API writers name their inputs; GIF arguments ------------------------------------------------------
def test_every_output_file_call_names_its_inputs() -> None:
    assert inspect.signature(output_file).parameters["inputs"].default is inspect.Parameter.empty


@pytest.mark.parametrize(("kwargs", "words"), [
    ({}, "is also an input"),                                          # the table was replaced by a GIF
    ({"mode": True}, "mode = True"), ({"frames": 0}, "frames = 0"),    # IndexError
    ({"fps": -5}, "fps = -5"),                                         # OverflowError
])
def test_animate_mode_never_writes_over_its_table(tmp_path: Path, kwargs, words) -> None:
    table = tmp_path / "p.csv"
    table.write_text("config,mode,freq_hz,pose.theta_deg,shape.a1,shape.a2,shape.a3\n"
                     "t0,1,25.3,0,0.57,1.56,2.52\n", encoding="utf-8")
    before = table.read_bytes()
    out = table if not kwargs else tmp_path / "a.gif"
    with pytest.raises(ReportError, match=words):
        fm.animate_mode(out, table, "t0", **{"mode": 1, **kwargs},
                        rig=REPO / "examples/rigs/seed003_two_link.toml")
    assert table.read_bytes() == before and not (tmp_path / "a.gif").exists()


# -- a path string where a list of runs belongs --------------------------------------------------------
@pytest.mark.parametrize("call", [
    lambda p: fm.compute_frfs(str(p)),               # each letter was taken as a file: "r: not found"
    lambda p: fm.compute_frfs(p),
    lambda p: fm.report(p.parent / "r.html", runs=str(p)),
    lambda p: store.expand_runs(str(p)),
])
def test_one_path_where_a_list_of_runs_belongs(tmp_path: Path, call) -> None:
    with pytest.raises(TypeError, match="runs must be a list of run entries"):
        call(tmp_path / "run.h5")


# -- comma lists: an empty item is a slip, not "nothing" -----------------------------------------------
@settings(max_examples=80, deadline=None, derandomize=True)
@given(st.text(alphabet="ab ,", max_size=8))
def test_comma_names_never_yield_an_empty_name(text: str) -> None:
    try:
        items = opt.names(text)
    except argparse.ArgumentTypeError:
        assert not text.strip() or any(not t.strip() for t in text.split(","))
        return
    assert items and all(items) and len(items) == text.count(",") + 1


@pytest.mark.parametrize(("argv", "words"), [
    (["diagnose", "--rig", "R", "--measured", "M", "--out", "D", "--effects", "joint_stiffness,"],
     ("--effects", "no empty name")),                                  # ran with joint_stiffness alone
    (["identify", "run.h5", "--out", "m.csv", "--poles", "40,,130"], ("--poles",)),   # ran with 40,130
    (["sim", "serve", "--protocol", "serial", "--pose", "theta_deg=30,", "--duration", "1"], ("--pose",)),
    (["sim", "serve", "--protocol", "serial", "--effect", "joint_stiffness@elbow:k_Nm_per_rad=9,",
      "--duration", "1"], ("--effect",)),
    (["identify", "run.h5", "--out", "m.csv", "--track", "--orders", "8,,16"], ("--orders",)),
    (["identify", "run.h5", "--out", "m.csv", "--track", "--pose-from", "theta_deg=enc,"], ("--pose-from",)),
])
def test_comma_lists_with_an_empty_item(tmp_path: Path, capsys, monkeypatch, argv, words) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "R").write_text(RIG, encoding="utf-8")
    (tmp_path / "M").write_text(MODES.read_text(encoding="utf-8"), encoding="utf-8")
    _run(tmp_path / "run.h5")
    _one_line(capsys, main(argv), *words)
    assert not (tmp_path / "D").exists() and not (tmp_path / "m.csv").exists()


def test_api_duration_that_is_not_a_number(tmp_path: Path) -> None:
    for bad in (float("nan"), float("inf"), "5"):
        with pytest.raises(DaqError, match="must be a number of seconds"):   # "nan samples, more than..."
            fm.acquire(REPO / "examples/sessions/serial-sim.toml", tmp_path / "r.h5", duration_s=bad)
    assert not (tmp_path / "r.h5").exists()


# -- run files: texts that are not UTF-8, a gzipped run file --------------------------------------------
def _run(path: Path) -> Path:
    chans = [Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2")]
    rng = np.random.default_rng(0)
    with RunWriter(path, "r1", sample_rate_hz=1024.0, channels=chans, excitation="random",
                   pose={"theta_deg": 0.0}) as w:
        x = rng.standard_normal(2048)
        w.append(np.column_stack([x, np.convolve(x, np.exp(-np.arange(50) / 9.0))[:2048]]))
        w.add_event(Event("note", 5, 1, "fine"))
    return path


@pytest.mark.parametrize(("table", "field", "row"), [("channels", "unit", 1), ("channels", "location", 0),
                                                     ("events", "detail", 0), ("events", "kind", 0)])
def test_run_table_texts_that_are_not_utf8(tmp_path: Path, capsys, table: str, field: str, row: int) -> None:
    run = _run(tmp_path / "run.h5")
    with h5py.File(run, "r+") as f:
        data = f[f"runs/r1/{table}"][...]
        data[field][row] = b"m/s\xb2"
        del f[f"runs/r1/{table}"]
        f.create_dataset(f"runs/r1/{table}", data=data)
    code = main(["frf", str(run), "--workers", "0"])   # was "cannot read ('utf-8' codec ...)"
    _one_line(capsys, code, "run.h5", f"'{table}' row {row} field '{field}'", "not UTF-8")


@pytest.mark.parametrize(("name", "pack", "words"), [
    ("run.h5", gzip.compress, "gzip-compressed"),
    ("m.diagram.npz", lambda b: b"PK\x03\x04" + b, "NumPy .npz archive"),   # was "zip-compressed: unpack it"
])
def test_a_packed_input_is_named_so(tmp_path: Path, capsys, name: str, pack, words: str) -> None:
    run = _run(tmp_path / "run.h5")
    (tmp_path / name).write_bytes(pack(run.read_bytes()))
    code = main(["identify", str(tmp_path / name), "--out", str(tmp_path / "x.csv")])   # "text outside ..."
    _one_line(capsys, code, name, words)


# -- a device counter that starts again: the record breaks there ---------------------------------------
def test_a_restarted_counter_breaks_the_record_with_a_nan_row() -> None:
    """A foreign device on a reused pty (or a reset device) restarts the counter: one NaN row and a
    ``gap`` event, so that no Welch segment spans the splice (a ``note`` alone joined the streams)."""
    from types import SimpleNamespace

    from flexmodal.daq.session import ChannelMap
    from flexmodal.daq.timeline import Timeline
    from flexmodal.modal.compute import SKIPPED_EVENTS

    session = SimpleNamespace(sample_rate_hz=100.0, devices=(SimpleNamespace(name="adc"),),
                              channels=(ChannelMap(Channel("v", "voltage", "V"), "adc", "s0"),))
    tl = Timeline(session, {"adc": ("s0",)})
    tl.add(Block("adc", 0, np.full((500, 1), 1.0), 0.0))
    events = tl.add(Block("adc", 3, np.full((50, 1), 2.0), 9.0))   # another stream, counter from 3
    rows = tl.take()
    assert [(e.kind, e.sample_index, e.count) for e in events] == [("gap", 500, 1)]
    assert events[0].kind in SKIPPED_EVENTS and "another device" in events[0].detail
    assert rows.shape == (551, 1) and np.isnan(rows[500, 0]) and (rows[501:, 0] == 2.0).all()


# -- second batch: a session simulator no device speaks, a source name, a rig without sensors, real FRFs
def test_a_session_simulator_of_a_protocol_no_device_speaks(tmp_path: Path) -> None:
    from flexmodal.daq.session import load_session

    text = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text(encoding="utf-8")
    text = text.replace('[simulator]\nprotocol = "serial"', '[simulator]\nprotocol = "can"')
    (tmp_path / "s.toml").write_text(text.replace("../rigs/", str(REPO / "examples" / "rigs") + "/"),
                                     encoding="utf-8")
    with pytest.raises(DaqError, match=r"simulator: protocol = 'can' but no \[\[device\]\] speaks it"):
        load_session(tmp_path / "s.toml")                    # was StopIteration inside acquire


@pytest.mark.parametrize("source", ["fe\nx", "   ", "a\tb"])
def test_a_source_name_that_breaks_lines(source: str) -> None:
    with pytest.raises(Exception, match="source") as err:   # was written as a two-line CSV cell
        fm.predict(REPO / "examples/rigs/seed003_two_link.toml", {"t0": {"theta_deg": 0.0}}, "fe", 2,
                   source=source)
    assert isinstance(err.value, fm.FlexmodalError)


def test_a_simulated_rig_without_sensors(tmp_path: Path) -> None:
    (tmp_path / "r.toml").write_text(RIG.split("[[sensor]]")[0], encoding="utf-8")
    from flexmodal.fixtures.errors import FixtureError

    with pytest.raises(FixtureError, match=r"r.toml: the rig has no \[\[sensor\]\]"):
        fm.demo(tmp_path / "D", rig=tmp_path / "r.toml")    # was "no response channel" after 20 s


def test_uff_frfs_of_real_values(tmp_path: Path, capsys) -> None:
    import pyuff

    f = np.arange(1, 129) * 0.5
    recs = [dict(type=58, func_type=4, rsp_node=r + 1, rsp_dir=3, ref_node=9, ref_dir=3, data=1 / (40.25 - f),
                 x=f, id1="FRF", rsp_ent_name="NONE", ref_ent_name="NONE", abscissa_spacing=1,
                 abscissa_spec_data_type=18, ordinate_spec_data_type=12, orddenom_spec_data_type=13)
            for r in range(2)]
    pyuff.UFF(str(tmp_path / "u.uff")).write_sets(recs, mode="overwrite")
    code = main(["identify", str(tmp_path / "u.uff"), "--out", str(tmp_path / "m.csv")])
    _one_line(capsys, code, "u.uff", "real values")   # was "no stable poles between ..."


def test_an_error_line_quoting_binary_bytes_is_escaped(tmp_path: Path, capsys) -> None:
    """A DBC file of binary bytes: cantools quotes them; ESC would drive the terminal (one line, but
    not plain text).  app._say escapes what is not printable, for every error line."""
    session = (REPO / "examples" / "sessions" / "can-module.toml").read_text(encoding="utf-8")
    (tmp_path / "s.toml").write_text(session.replace('interface = "socketcan"', 'interface = "virtual"'),
                                     encoding="utf-8")
    (tmp_path / "can-module.dbc").write_bytes(b"\x1b[2J\x07\x9b0m junk\n")
    code = main(["acquire", "--config", str(tmp_path / "s.toml"), "--out", str(tmp_path / "r.h5"),
                 "--duration", "1"])
    line = _one_line(capsys, code, "can-module.dbc", "not a readable DBC file")
    assert "\\x1b" in line and not any(c in line for c in "\x1b\x07\x9b")


def test_a_predicted_table_of_two_models(tmp_path: Path, capsys) -> None:
    """fe mode 1 and blevins mode 2 in one PRED.csv were paired as one model's modes 1 and 2."""
    (tmp_path / "p.csv").write_text("config,mode,freq_hz,source\ntheta0,1,25.3,fe\ntheta0,2,158.4,blevins\n",
                                    encoding="utf-8")
    code = main(["compare", str(MODES), str(tmp_path / "p.csv")])
    _one_line(capsys, code, "p.csv", "2 sources", "one model per file")


def test_a_report_title_that_is_not_text(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="report: title must be text"):   # the page was titled "None"
        fm.report(tmp_path / "r.html", measured=MODES, title=None)
    assert not (tmp_path / "r.html").exists()


# -- third batch: a live run file, an OMA band above Nyquist, a name given twice ------------------------
def test_frf_write_back_into_a_run_being_acquired(tmp_path: Path, capsys) -> None:
    """HDF5's own words suggested h5clear, which would damage the run being written."""
    import subprocess
    import sys

    run = _run(tmp_path / "run.h5")
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time, h5py\nfrom flexmodal.daq.lock import WriterLock\n"
        f"lock = WriterLock({str(run)!r})\nf = h5py.File({str(run)!r}, 'a', libver='latest')\n"
        "f.swmr_mode = True\nprint('ready', flush=True)\ntime.sleep(60)\n")],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "ready"
        code = main(["frf", str(run), "--workers", "0"])
    finally:
        holder.kill()
        holder.wait()
    line = _one_line(capsys, code, "run.h5", "being written by a running acquire", f"pid {holder.pid}")
    assert "h5clear" not in line


def test_an_output_only_band_above_nyquist() -> None:
    from flexmodal.modal.errors import ModalError
    from flexmodal.modal.fdd import fdd
    from flexmodal.modal.oma import identify_output_only

    y = np.random.default_rng(0).standard_normal((4096, 2))
    with pytest.raises(ModalError, match="no frequency line between 100000 and 256 Hz"):  # ValueError before
        fdd(y, 512.0, fmin=1e5)
    with pytest.raises(ModalError, match="at or above the Nyquist frequency, 256 Hz"):
        identify_output_only(y, 512.0, ("a1", "a2"), ("acceleration",) * 2, method="ssi", fmin=1e5,
                             where="r")


@pytest.mark.parametrize(("argv", "words"), [
    (["identify", "run.h5", "--out", "m.csv", "--track", "--pose-from", "theta_deg=a1,theta_deg=F"],
     ("--pose-from", "given twice")),
    (["sim", "serve", "--protocol", "serial", "--duration", "1",
      "--effect", "joint_stiffness@elbow:k_Nm_per_rad=5,k_Nm_per_rad=9"],
     ("--effect", "parameter is given twice")),
    (["sim", "serve", "--protocol", "serial", "--duration", "1",
      "--effect", "joint_stiffness@elbow:k_Nm_per_rad=5", "--effect", "joint_stiffness@elbow:k_Nm_per_rad=9"],
     ("--effect", "joint_stiffness@elbow is given twice")),
])
def test_a_name_given_twice_where_the_last_one_won(tmp_path: Path, capsys, monkeypatch, argv, words) -> None:
    monkeypatch.chdir(tmp_path)
    _run(tmp_path / "run.h5")
    _one_line(capsys, main(argv), *words)


# -- fourth batch: API numbers checked by the option kinds the command line uses ------------------------
@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.one_of(st.none(), st.booleans(), st.text(max_size=4), st.integers(-10, 10**12),
                 st.floats(allow_nan=True, allow_infinity=True)))
def test_given_accepts_what_the_option_accepts(value) -> None:
    """opt.given(value, kind) is kind(str(value)) for a real number, else one error naming the value."""
    class Bad(Exception):
        pass

    try:
        got = opt.given(value, opt.model_order, "max_order", Bad)
    except Bad as exc:
        assert "max_order" in str(exc) and repr(value) in str(exc)
        return
    assert not isinstance(value, bool) and got == opt.model_order(str(value))


@pytest.mark.parametrize(("call", "error", "words"), [
    (lambda d: fm.identify(d / "run.h5", poles_hz=[40, "a"]), fm.ModalError, "poles_hz = .a."),  # ValueError
    (lambda d: fm.identify(d / "run.h5", poles_hz=[float("nan")]), fm.ModalError, "poles_hz = nan"),  # ran
    (lambda d: fm.identify(d / "run.h5", max_order=1.5), fm.ModalError, "max_order = 1.5"),
    (lambda d: fm.identify(d / "run.h5", method="ssi", references="a1"), TypeError,
     "references must be a list"),
    (lambda d: fm.track(d / "run.h5", max_order=True), fm.ModalError, "max_order = True"),
    (lambda d: fm.compute_frf(d / "run.h5", averaging="median"), fm.ModalError, "averaging 'median'"),  # ran
    (lambda d: fm.compute_frf(d / "run.h5", window="force:0.05"), fm.ModalError, "is for impact hits"),  # ran
    (lambda d: fm.predict(REPO / "examples/rigs/seed003_two_link.toml", {"t": {"theta_deg": 0.0}}, "fe", 2,
                          elements_per_link=0), fm.ModelError, "elements_per_link = 0"),           # ran
    (lambda d: fm.predict(REPO / "examples/rigs/seed003_two_link.toml", {"t": {"theta_deg": 0.0}}, "fe", 2,
                          banana=3), fm.ModelError, "unknown option 'banana'"),                     # ran
    (lambda d: fm.selftest(1, seed=-1), fm.FixtureError, "seed = -1"),                            # ValueError
    (lambda d: fm.serve_simulator("serial", rate=0), fm.FixtureError, "rate = 0"),   # ZeroDivisionError
])
def test_api_numbers_the_command_line_refuses(tmp_path: Path, call, error, words) -> None:
    _run(tmp_path / "run.h5")
    with pytest.raises(error, match=words):
        call(tmp_path)
