"""Odd inputs of a seventh adversarial pass (stop 38, 27 Nov): an HDF5 file whose signature sits after
a user block (a MATLAB v7.3 ``.mat``), frequency axes in other units (lines 1e-300 Hz apart, or at
1e12 Hz), ragged lists given as arrays, DBC files in UTF-8 (a unit 'µV' read as cp1252) or naming a
message twice, rig quantities far outside physics (E_Pa = 1e-30, a length of 100 km), a duration shorter
than one sample, and option values that are empty (a script's unset variable).  Each had been replaced
in silence, a traceback, a silent answer or a line naming the wrong thing ('.: is a directory'); each
class is now one line naming the file, field or option, exit code 2 (or the family error / TypeError
from the Python API).  In-process, small files, a few seconds in all (NOTES-safety.md, stop 38)."""

from __future__ import annotations

import re
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
from flexmodal.checked_io.output import _is_hdf5, hdf5_output, output_file
from flexmodal.daq.dbc import load_messages
from flexmodal.daq.errors import DaqError
from flexmodal.modal.errors import ModalError
from flexmodal.modal.frf import MAX_LINE_HZ, MIN_LINE_SPACING_HZ, check_freq_axis
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import load_rig

RIG = REPO / "examples" / "rigs" / "seed003_two_link.toml"
MEASURED = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"
SESSIONS = REPO / "examples" / "sessions"
DBC = (REPO / "fixtures" / "flexmodal_sim.dbc").read_bytes()
SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _user_block_file(path: Path, user_block: int) -> Path:
    with h5py.File(path, "w", userblock_size=user_block) as h:
        h["x"] = np.arange(3.0)
    return path


# -- an HDF5 file is found where HDF5 finds it: after a user block too ------------------------------
@pytest.mark.parametrize("user_block", [512, 1024, 4096])
def test_an_hdf5_file_after_a_user_block_is_never_replaced(tmp_path: Path, user_block: int) -> None:
    mat = _user_block_file(tmp_path / "data.mat", user_block)
    before = mat.read_bytes()
    with pytest.raises(ValueError, match="data.mat: is an HDF5 file"):
        output_file(mat, ValueError, "table (--out)", inputs=())
    with pytest.raises(ValueError, match=f"data.mat: an HDF5 file after a {user_block}-byte user block"):
        hdf5_output(mat, ValueError)   # was accepted: frf --out wrote latest-format objects into it
    assert mat.read_bytes() == before


def test_frf_out_refuses_a_matlab_file_and_leaves_it_byte_identical(tmp_path: Path, capsys) -> None:
    from flexmodal.fixtures.examples import impact_run

    run = impact_run(tmp_path)
    mat = _user_block_file(tmp_path / "data.mat", 512)
    plain = tmp_path / "plain.h5"
    with h5py.File(plain, "w") as h:   # h5py's default: superblock 0
        h["x"] = np.arange(3.0)
    for target, words in ((mat, "data.mat: an HDF5 file after a 512-byte user block"),
                          (plain, "plain.h5: an HDF5 file of another tool (superblock version 0)")):
        before = target.read_bytes()
        _one_line(capsys, main(["frf", str(run), "--out", str(target)]), words)
        assert target.read_bytes() == before


def test_compare_refuses_a_matlab_file_as_its_table(tmp_path: Path, capsys) -> None:
    mat = _user_block_file(tmp_path / "data.mat", 512)
    before = mat.read_bytes()
    code = main(["compare", str(MEASURED), str(MEASURED), "--out", str(mat)])   # was replaced, rc 0
    _one_line(capsys, code, "data.mat: is an HDF5 file")
    assert mat.read_bytes() == before


@pytest.mark.parametrize("user_block", [0, 512])
def test_runs_are_not_appended_to_an_hdf5_file_without_swmr(tmp_path: Path, user_block: int) -> None:
    from flexmodal.daq.store import Channel, RunWriter

    path = tmp_path / "old.h5"
    with h5py.File(path, "w", userblock_size=user_block) as h:   # superblock 0: h5py's default, MATLAB
        h["x"] = np.arange(3.0)
    before = path.read_bytes()
    words = f"after a {user_block}-byte user block" if user_block else "of another tool .superblock version 0"
    with pytest.raises(DaqError, match=f"old.h5: an HDF5 file {words}"):
        RunWriter(path, "r1", sample_rate_hz=100.0, channels=[Channel("F", "force", "N")],
                  excitation="impact", pose={})
    assert path.read_bytes() == before   # was a RuntimeError traceback (SWMR) after adding runs/r1


@settings(max_examples=60, deadline=None)
@given(head=st.binary(max_size=3000), at=st.sampled_from([0, 512, 1024, 2048]))
def test_the_signature_is_found_at_the_places_hdf5_looks(tmp_path_factory, head: bytes, at: int) -> None:
    path = tmp_path_factory.mktemp("h") / "f"
    junk = head.replace(SIGNATURE, b"")
    path.write_bytes(junk)
    assert not _is_hdf5(path)
    data = bytearray(junk.ljust(at + 100, b"\0"))
    data[at:at + len(SIGNATURE)] = SIGNATURE
    path.write_bytes(bytes(data))
    assert _is_hdf5(path)


# -- frequency axes: one check for stored FRFs, UFF files and arrays --------------------------------
@settings(max_examples=80, deadline=None)
@given(start=st.floats(0, 1e10, allow_subnormal=False), step=st.floats(1e-320, 1e10),
       n=st.integers(2, 6))
def test_a_frequency_axis_is_accepted_exactly_within_its_bounds(start: float, step: float, n: int) -> None:
    f = start + step * np.arange(n)
    fine = bool((np.diff(f) >= MIN_LINE_SPACING_HZ).all() and f[-1] <= MAX_LINE_HZ
                and (np.diff(f) > 0).all() and np.isfinite(f).all())
    if fine:
        check_freq_axis(f, "x")
    else:
        with pytest.raises(ModalError, match="^x: freq_hz "):
            check_freq_axis(f, "x")


@pytest.mark.parametrize("scale", [1e-300, 1e-100, 1e12])
def test_frequencies_in_other_units_are_named_not_identified(scale: float) -> None:
    f = np.linspace(0.0, 100.0, 201) * scale   # 1e-100: a scipy ValueError inside the identification
    with pytest.raises(ModalError, match="frf_from_arrays: freq_hz .*is the axis in Hz"):
        fm.frf_from_arrays(f, np.exp(1j * f))


def test_a_uff_abscissa_1e300_times_too_fine_is_named(tmp_path: Path) -> None:
    import pyuff

    from flexmodal.modal.uff import read_uff

    record = dict(type=58, func_type=4, rsp_node=1, rsp_dir=3, ref_node=100, ref_dir=3,
                  x=np.arange(64) * 1e-300, data=np.exp(1j * np.arange(64.0)), id1="FRF",
                  rsp_ent_name="NONE", ref_ent_name="NONE",
                  abscissa_spacing=1, abscissa_spec_data_type=18, ordinate_spec_data_type=12,
                  orddenom_spec_data_type=13)
    pyuff.UFF(str(tmp_path / "u.uff")).write_sets([record], mode="overwrite")
    with pytest.raises(ModalError, match="u.uff: dataset 58 record 1: abscissa lines 1e-300 Hz apart"):
        read_uff(tmp_path / "u.uff")   # `identify u.uff` was a scipy traceback inside the identification


@pytest.mark.parametrize("arg", ["freq_hz", "H", "coherence"])
def test_ragged_lists_are_a_type_error_naming_the_argument(arg: str) -> None:
    given_ = {"freq_hz": [0.0, 1.0, 2.0], "H": [1j, 2j, 3j], "coherence": [[0.5, 0.5, 0.5]]}
    given_[arg] = [[1.0, 2.0], [1.0]]   # numpy: "setting an array element with a sequence" (ValueError)
    with pytest.raises(TypeError, match=f"frf_from_arrays: {arg} must be an array of numbers"):
        fm.frf_from_arrays(given_["freq_hz"], given_["H"], coherence=given_["coherence"])


@settings(max_examples=40, deadline=None)
@given(h=st.lists(st.floats(-1e6, 1e6), min_size=3, max_size=3), as_decimal=st.booleans())
def test_a_real_h_held_as_objects_is_refused_as_a_float_one_is(h: list, as_decimal: bool) -> None:
    from decimal import Decimal

    items = [Decimal(x) for x in h] if as_decimal else h
    with pytest.raises(ModalError, match="holds no phase"):   # was taken with zero phase, silently
        fm.frf_from_arrays([0.0, 1.0, 2.0], np.array(items, dtype=object))
    frf = fm.frf_from_arrays([0.0, 1.0, 2.0], np.array([complex(x, 1.0) for x in h], dtype=object))
    np.testing.assert_array_equal(frf.H[0, 0], np.array(h) + 1j)   # complex objects: kept exactly


@pytest.mark.parametrize("freq_hz, shape", [([[0.0, 1.0, 2.0]], "(1, 3)"), ([5.0], "(1,)")])
def test_a_frequency_axis_of_the_wrong_shape_names_the_shape(freq_hz: list, shape: str) -> None:
    with pytest.raises(ModalError, match=re.escape(f"freq_hz of shape {shape} must be one axis of at least")):
        fm.frf_from_arrays(freq_hz, np.ones(3, complex))


# -- DBC files: their encoding, and one message per name and id --------------------------------------
@pytest.mark.parametrize("encode, prefix", [("utf-8", b""), ("utf-8", b"\xef\xbb\xbf"), ("cp1252", b"")])
def test_a_dbc_unit_reads_as_written_in_utf8_or_cp1252(tmp_path: Path, encode: str, prefix: bytes) -> None:
    path = tmp_path / "x.dbc"
    path.write_bytes(prefix + DBC.replace(b'"mV"', '"µV"'.encode(encode)))   # utf-8 was read 'Âµ V'
    (layout,) = load_messages(str(path), ["FlexScan"])
    assert {s.unit for s in layout.signals} - {""} == {"µV"}


@pytest.mark.parametrize("old, new, what", [(b"BO_ 257 FlexScan", b"BO_ 258 FlexScan", "message name"),
                                            (b"BO_ 257 FlexScan", b"BO_ 257 Other", "frame id")])
def test_a_dbc_giving_a_name_or_id_to_two_messages_is_refused(tmp_path: Path, old, new, what) -> None:
    block = DBC[DBC.index(old):].split(b"\n\n")[0]
    path = tmp_path / "x.dbc"
    path.write_bytes(DBC + b"\n" + block.replace(old, new).replace(b" SG_ ", b" SG_ z") + b"\n")
    with pytest.raises(DaqError, match=f"x.dbc: {what} .* is given to two messages"):
        load_messages(str(path), ["FlexScan"])   # cantools kept both; the lookup took one in silence


TWO_FRAMES_0X100 = """VERSION ""

BU_: N

BO_ 256 Std: 2 N
 SG_ s : 0|16@1+ (1,0) [0|65535] "" N

BO_ 2147483904 Ext: 2 N
 SG_ e : 0|16@1+ (1,0) [0|65535] "" N

BO_ 512 Other: 2 N
 SG_ o1 : 0|16@1+ (1,0) [0|65535] "" N

BO_ 513 Other: 2 N
 SG_ o2 : 0|16@1+ (1,0) [0|65535] "" N
"""


def test_a_standard_and_an_extended_frame_of_one_id_are_two_messages(tmp_path: Path) -> None:
    path = tmp_path / "two.txt"   # any name: the file is read once, as DBC text
    path.write_text(TWO_FRAMES_0X100, encoding="cp1252")
    std, ext = load_messages(str(path), ["Std", "Ext"])   # were "frame id 0x100 is given to two messages"
    assert [(m.frame_id, m.is_extended_frame) for m in (std, ext)] == [(256, False), (256, True)]
    with pytest.raises(DaqError, match="two.txt: message name Other is given to two messages"):
        load_messages(str(path), ["Other"])   # a duplicate the session reads is still refused
    path.write_text(TWO_FRAMES_0X100.replace("BO_ 513 Other", "BO_ 256 Third"), encoding="cp1252")
    with pytest.raises(DaqError, match=r"two.txt: frame id 0x100 is given to two messages"):
        load_messages(str(path), ["Std"])   # another message sharing the read one's id


def test_the_can_driver_keeps_standard_and_extended_frames_of_one_id_apart(tmp_path: Path) -> None:
    import can

    from flexmodal.daq.can_driver import CanConfig, CanDriver
    from flexmodal.daq.devices import Device

    (tmp_path / "two.dbc").write_text(TWO_FRAMES_0X100, encoding="cp1252")
    channel = f"flexmodal-ext-{tmp_path.name}"
    driver = CanDriver(Device("bus", "can", CanConfig("virtual", channel, str(tmp_path / "two.dbc"),
                                                      messages=("Std",), counter="")), 100.0)
    driver.open()
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        for k in range(12):   # the extended 0x100 frame was decoded as the standard one's samples
            sender.send(can.Message(arbitration_id=0x100, data=(7).to_bytes(2, "little"), timestamp=k / 100,
                                    is_extended_id=False))
            sender.send(can.Message(arbitration_id=0x100, data=(9).to_bytes(2, "little"), timestamp=k / 100,
                                    is_extended_id=True))
        values: list = []
        for _ in range(200):
            values.extend(v for b in driver.read() for v in b.values[:, 0])
            if len(values) >= 10:
                break
    finally:
        sender.shutdown()
        driver.close()
    assert len(values) >= 10 and set(values) == {7.0}   # the newest scan may be held back (unfinished)


# -- CSV lines: the first line after opening, judged by the first good line after it -----------------
@settings(max_examples=60, deadline=None)
@given(first=st.integers(0, 10**6), n=st.integers(4, 30), data=st.data())
def test_a_whole_first_csv_line_before_a_corrupt_one_is_kept_and_the_corrupt_one_counted(
        first: int, n: int, data) -> None:
    from flexmodal.daq.serial_frames import CsvDecoder, encode_csv

    x = np.arange(n * 2, dtype=float).reshape(n, 2)
    lines = encode_csv(first, x, "sum8").splitlines(keepends=True)
    bad = data.draw(st.sets(st.integers(1, n - 3), min_size=1, max_size=n - 3))
    for i in bad:   # a bad checksum: one flipped value digit
        lines[i] = lines[i].replace(b",", b",9", 1)
    runs = CsvDecoder(2, "sum8").feed(b"".join(lines))
    got = {seq + k: row.tolist() for seq, rows, _ in runs for k, row in enumerate(rows)}
    kept = sorted(set(range(n)) - bad)
    assert sorted(got) == [first + i for i in kept]   # line 0 was dropped when line 1 was corrupt
    assert all(got[first + i] == x[i].tolist() for i in kept)
    assert sum(c for _, _, c in runs) == len(bad)   # the corrupt line after it was not counted


def test_a_cut_first_csv_line_is_still_dropped_uncounted() -> None:
    from flexmodal.daq.serial_frames import CsvDecoder, encode_csv

    x = np.arange(8.0).reshape(4, 2)
    stream = encode_csv(760, x)[1:]   # '60,0,1' : cut inside its counter, parses as sample 60
    runs = CsvDecoder(2).feed(stream + encode_csv(764, x[:1]))
    assert [(seq, len(rows), c) for seq, rows, c in runs] == [(761, 4, 0)]


# -- rig quantities within physics ------------------------------------------------------------------
@pytest.mark.parametrize("old, new, field", [
    ("E_Pa = 75e9", "E_Pa = 1e-30", "material.aluminium.E_Pa"),
    ("rho_kg_m3 = 2700", "rho_kg_m3 = 1e-300", "material.aluminium.rho_kg_m3"),
    ("length_m = 0.60", "length_m = 1e5", "link[0].length_m"),
    ("length_m = 0.60", "length_m = 1e-12", "link[0].length_m"),
    ("outer_m = 0.040, wall_m = 0.0011", "outer_m = 1e-12, wall_m = 1e-13", "link[0].section.outer_m"),
])
def test_rig_quantities_outside_physics_name_the_field(tmp_path: Path, old: str, new: str,
                                                       field: str) -> None:
    text = RIG.read_text(encoding="utf-8")
    assert old in text
    (tmp_path / "r.toml").write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(ModelError, match=f"r.toml: {re.escape(field)}: .*out of range"):
        load_rig(tmp_path / "r.toml")


# -- a duration shorter than one sample --------------------------------------------------------------
def test_acquire_for_less_than_one_sample_names_the_duration(tmp_path: Path, capsys) -> None:
    code = main(["acquire", "--config", str(SESSIONS / "serial-sim.toml"), "--out", str(tmp_path / "r.h5"),
                 "--duration", "1e-9"])   # was "no samples arrived from adc" after starting the device
    _one_line(capsys, code, "--duration 1e-09 s is shorter than one sample")
    assert not (tmp_path / "r.h5").exists()


# -- option values that are empty: refused, never the default nor the folder '.' ---------------------
@pytest.mark.parametrize("argv, words", [
    (["predict", str(RIG), "--model", "fe", "--poses", "P", "--out", "O", "--source", ""], ["--source"]),
    (["frf", "R", "--window", ""], ["--window"]),
    (["sim", "serve", "--protocol", "serial", "--rig", " "], ["--rig"]),
    (["sim", "serve", "--protocol", "serial", "--link", ""], ["--link"]),
    (["sim", "serve", "--protocol", "serial", "--fault-log", ""], ["--fault-log"]),
    (["sim", "serve", "--protocol", "serial", "--pose", ""], ["--pose ''"]),
    (["demo", "--rig", ""], ["--rig"]),
    (["identify", "M", "--track", "--out", "O", "--orders", ""], ["--orders ''"]),
    (["identify", "M", "--track", "--out", "O", "--pose-from", ""], ["--pose-from ''"]),
    (["compare", "", str(MEASURED)], ["modal table path is empty"]),
    (["predict", "", "--model", "fe", "--poses", str(MEASURED), "--out", "O"], ["rig file path is empty"]),
    (["acquire", "--config", "", "--out", "O"], ["path is empty"]),
])
def test_an_empty_option_value_is_refused(tmp_path: Path, monkeypatch, capsys, argv, words) -> None:
    monkeypatch.chdir(tmp_path)   # relative names of no file: each command stops before reading them
    line = _one_line(capsys, main(argv), *words)
    assert "'.'" not in line and ".: is a directory" not in line
    assert list(tmp_path.iterdir()) == []


# -- links and endpoints that never answer: bounded ---------------------------------------------------
def test_a_run_linked_to_a_fifo_in_another_file_is_never_opened(tmp_path: Path) -> None:
    import os
    import threading

    from flexmodal.daq.store import Channel, RunWriter
    from flexmodal.modal.batch import run_bytes

    path, fifo = tmp_path / "run.h5", tmp_path / "fifo"
    with RunWriter(path, "r1", sample_rate_hz=100.0, channels=[Channel("F", "force", "N")],
                   excitation="impact", pose={}) as w:
        w.append(np.zeros((8, 1)))
    os.mkfifo(fifo)
    with h5py.File(path, "a") as h:
        h["runs"]["r2"] = h5py.ExternalLink(str(fifo), "/runs/r1")   # HDF5 would open() the FIFO: blocks
    sizes: list = []
    worker = threading.Thread(target=lambda: sizes.extend(run_bytes([(str(path), "r1"), (str(path), "r2")])),
                              daemon=True)
    worker.start()
    worker.join(60)
    if worker.is_alive():   # `frf run.h5` hung here for ever, SIGTERM included: release it, then fail
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail("run_bytes followed the external link into the FIFO")
    assert sizes[0] > 0 and sizes[1] == 0   # the job of r2 itself names the link ("not followed")


def test_a_scheduler_that_never_answers_is_named(monkeypatch) -> None:
    import threading

    from flexmodal.modal import batch

    monkeypatch.setattr(batch, "SCHEDULER_WAIT_S", 0.2)
    silent = threading.Event()   # dask's Client(timeout=) bounds the TCP connect, not the handshake
    with pytest.raises(ModalError, match="--scheduler 'tcp://127.0.0.1:9': cannot connect .no answer within"):
        batch._client(lambda *args, **kwargs: silent.wait(), "tcp://127.0.0.1:9")
    silent.set()


def test_a_scheduler_that_answers_after_the_wait_is_closed_not_left_as_the_default(monkeypatch) -> None:
    import threading

    from flexmodal.modal import batch

    monkeypatch.setattr(batch, "SCHEDULER_WAIT_S", 0.2)
    late, closed = threading.Event(), threading.Event()

    class LateClient:   # stands in for distributed.Client: registered as the default once made
        def __init__(self, *args, **kwargs) -> None:
            late.wait(120)

        def close(self) -> None:
            closed.set()

    with pytest.raises(ModalError, match="no answer within 0.2 s"):
        batch._client(LateClient, "tcp://127.0.0.1:9")
    late.set()   # it connects after all: the thread closes it
    assert closed.wait(120)


def test_an_empty_serial_port_names_the_session_key(tmp_path: Path) -> None:
    from flexmodal.daq.session import load_session

    text = (SESSIONS / "serial-sim.toml").read_text(encoding="utf-8")
    (tmp_path / "s.toml").write_text(text.replace('port = "@simulator"', 'port = ""').replace(
        "../rigs/", str(REPO / "examples" / "rigs") + "/"), encoding="utf-8")
    with pytest.raises(DaqError, match=r"s.toml: device 'adc': port is empty"):   # was pyserial's line
        load_session(tmp_path / "s.toml")


@settings(max_examples=80, deadline=None)
@given(text=st.text(max_size=8))
def test_a_nonempty_option_takes_exactly_the_texts_with_a_visible_character(text: str) -> None:
    import argparse

    from flexmodal.checked_io.options import nonempty

    if text.strip():
        assert nonempty(text) == text
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="expected a non-empty value"):
            nonempty(text)


@settings(max_examples=80, deadline=None)
@given(text=st.text(st.characters(codec="cp1252"), max_size=12), bom=st.booleans())
def test_a_dbc_text_decodes_back_as_written(text: str, bom: bool) -> None:
    import codecs

    from flexmodal.daq.dbc import _encoding

    data = (codecs.BOM_UTF8 if bom else b"") + text.encode("utf-8")
    assert data.decode(_encoding(data)) == text   # UTF-8, with or without a byte-order mark
    legacy = text.encode("cp1252")   # a Vector tool's file: read as cp1252 unless its bytes are UTF-8
    chosen = _encoding(legacy)
    assert chosen in (None, "utf-8") and (chosen is not None or legacy.decode("cp1252") == text)


@pytest.mark.parametrize("where", ["samples", "channels", "run", "runs"])
def test_a_soft_link_to_an_external_link_is_never_followed(tmp_path: Path, where: str) -> None:
    import os
    import threading

    from flexmodal.daq.store import Channel, RunWriter

    path, fifo = tmp_path / "run.h5", tmp_path / "fifo"
    with RunWriter(path, "r1", sample_rate_hz=100.0, channels=[Channel("F", "force", "N")],
                   excitation="impact", pose={}) as w:
        w.append(np.zeros((8, 1)))
    os.mkfifo(fifo)
    with h5py.File(path, "a") as h:   # member -> /ext -> the FIFO: HDF5 follows both and blocks in open()
        h["ext"] = h5py.ExternalLink(str(fifo), "/x")
        if where == "runs":
            h.move("runs", "kept")
            h["runs"] = h5py.SoftLink("/ext")
        elif where == "run":
            h.move("runs/r1", "kept")
            h["runs/r1"] = h5py.SoftLink("/ext")
        else:
            del h["runs/r1"][where]
            h["runs/r1"][where] = h5py.SoftLink("/ext")
    caught: list = []

    def read() -> None:
        try:
            fm.read_run(path, "r1")
        except DaqError as exc:
            caught.append(str(exc))

    worker = threading.Thread(target=read, daemon=True)
    worker.start()
    worker.join(60)
    if worker.is_alive():   # hung for ever before (SIGTERM deferred): release it, then fail
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail("a soft link was followed into an external link to a FIFO")
    assert len(caught) == 1 and "is a soft link to /ext, which reaches an external link to" in caught[0]


def _bounded(fifo: Path, call) -> BaseException | None:
    """What ``call()`` raised (None if nothing) within 60 s; a call that blocks opening ``fifo`` is
    released (a writer end opened) and the test fails."""
    import os
    import threading

    raised: list[BaseException | None] = []

    def run() -> None:
        try:
            call()
            raised.append(None)
        except BaseException as exc:   # handed to the test thread
            raised.append(exc)

    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(60)
    if worker.is_alive():
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail("the check followed an external link into the FIFO")
    return raised[0]


def test_an_out_file_whose_run_links_to_a_fifo_is_refused_not_opened(tmp_path: Path) -> None:
    import os

    from flexmodal.daq.store import Channel, RunWriter
    from flexmodal.modal.batch import _check_out_runs

    src, out, fifo = tmp_path / "in.h5", tmp_path / "other.h5", tmp_path / "fifo"
    for path in (src, out):
        with RunWriter(path, "r0", sample_rate_hz=100.0, channels=[Channel("F", "force", "N")],
                       excitation="impact", pose={}) as w:
            w.append(np.zeros((8, 1)))
    os.mkfifo(fifo)
    with h5py.File(out, "a") as h:
        h["runs"]["r1"] = h5py.ExternalLink(str(fifo), "/runs/r1")   # `frf in.h5 --out other.h5` hung
    exc = _bounded(fifo, lambda: _check_out_runs(out, [(str(src), "r1")]))
    assert isinstance(exc, ModalError) and "'r1' is an external link to" in str(exc), exc
    assert _bounded(fifo, lambda: _check_out_runs(out, [(str(src), "r0")])) is not None   # own samples


def test_a_run_file_whose_runs_group_links_to_a_fifo_is_refused_not_opened(tmp_path: Path) -> None:
    import os

    from flexmodal.daq.store import Channel, RunWriter

    path, fifo = tmp_path / "run.h5", tmp_path / "fifo"
    os.mkfifo(fifo)
    with h5py.File(path, "w", libver="latest") as h:
        h["runs"] = h5py.ExternalLink(str(fifo), "/runs")
    before = path.read_bytes()
    exc = _bounded(fifo, lambda: RunWriter(path, "r1", sample_rate_hz=100.0,
                                           channels=[Channel("F", "force", "N")], excitation="impact",
                                           pose={}))
    assert isinstance(exc, DaqError) and "'runs' is an external link to" in str(exc), exc
    assert path.read_bytes() == before
