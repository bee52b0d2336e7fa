"""Odd inputs of a sixth adversarial pass (stop 37, 27 Nov): a configuration called ``NA``, two
Modbus registers sharing an address word, a device naming one source twice, a stored FRF group naming
channels its run lacks, a joint called ``tip`` or named like a link, the fault log on the pty link, and
API arguments of the wrong type.  Each was a silent answer, a line naming the wrong thing or an
internal exception; each class is now one line naming the file and item, exit code 2 (or the family
error / TypeError from the Python API).  In-process, small files, a few seconds in all."""

from __future__ import annotations

import json
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
from flexmodal.checked_io.csv_tables import NA_WORDS, read_table
from flexmodal.daq.errors import DaqError
from flexmodal.daq.session import load_session
from flexmodal.daq.store import Channel, RunWriter
from flexmodal.fixtures.errors import FixtureError
from flexmodal.modal.errors import ModalError
from flexmodal.modal.runs_io import read_frf, write_frf
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import load_rig

RIG = (REPO / "examples" / "rigs" / "seed003_two_link.toml").read_text(encoding="utf-8")
MEASURED = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"
SESSIONS = REPO / "examples" / "sessions"


# -- text columns keep the words pandas reads as missing ----------------------------------------------
@pytest.mark.parametrize("word", [w for w in NA_WORDS if w])
def test_a_configuration_may_be_called_like_a_missing_value(tmp_path: Path, capsys, word: str) -> None:
    (tmp_path / "m.csv").write_text(f"config,mode,freq_hz,damping_ratio\n{word},1,25.5,NA\n",
                                    encoding="utf-8")
    (tmp_path / "p.csv").write_text(f"config,mode,freq_hz,source\n{word},1,25.0,fe\n", encoding="utf-8")
    assert main(["compare", str(tmp_path / "m.csv"), str(tmp_path / "p.csv"), "--format", "csv"]) == 0
    assert "1,25.0,25.5,-1.96" in capsys.readouterr().out   # was "line 2: empty 'config' cell"
    frame = fm.read_table(tmp_path / "m.csv").frame
    assert frame["config"].tolist() == [word] and np.isnan(frame["damping_ratio"].iloc[0])  # a number: NA


@settings(max_examples=60, deadline=None)
@given(names=st.lists(
    st.text(st.characters(codec="utf-8", exclude_categories=("Cc", "Cs", "Zs", "Zl", "Zp")), min_size=1,
            max_size=8).filter(lambda s: s.strip() and not set(s) & set(',"\r\n')),
    min_size=1, max_size=4, unique=True))
def test_text_columns_read_back_as_written(tmp_path_factory, names: list[str]) -> None:
    path = tmp_path_factory.mktemp("t") / "t.csv"
    path.write_text("config,freq_hz\n" + "".join(f"{n},1.5\n" for n in names), encoding="utf-8")
    frame = read_table(path, ValueError, required=("config",), text_columns=("config",))
    assert list(frame["config"]) == [n.strip() for n in names]
    assert frame["freq_hz"].tolist() == [1.5] * len(names)


def test_a_blank_configuration_cell_is_still_refused(tmp_path: Path, capsys) -> None:
    (tmp_path / "m.csv").write_text("config,mode,freq_hz\n  ,1,25.5\n", encoding="utf-8")
    _one_line(capsys, main(["compare", str(tmp_path / "m.csv"), str(tmp_path / "m.csv")]), "line 2", "empty")


# -- device sources: each named once, Modbus registers apart -------------------------------------------
def _session(tmp_path: Path, name: str, old: str, new: str) -> Path:
    text = (SESSIONS / name).read_text(encoding="utf-8")
    text = text.replace("../../fixtures/", str(REPO / "fixtures") + "/")
    text = text.replace("../rigs/", str(REPO / "examples" / "rigs") + "/")
    assert old in text
    (tmp_path / "s.toml").write_text(text.replace(old, new, 1), encoding="utf-8")
    return tmp_path / "s.toml"


@pytest.mark.parametrize(("name", "old", "new", "words"), [
    ("modbus-sim.toml", "address = 2", "address = 1", ("register 'F'", "overlaps register 'counter'")),
    ("modbus-sim.toml", "address = 3", "address = 2", ("register 'a1'", "overlaps register 'F'")),
    ("serial-sim.toml", '"ch0", "ch1"', '"ch1", "ch1"', ("device 'adc'", "'ch1' is named twice")),
])
def test_a_device_value_is_read_from_one_place(tmp_path: Path, name, old, new, words) -> None:
    with pytest.raises(DaqError) as err:   # was: F decoded from the counter's low word, rc 0
        load_session(_session(tmp_path, name, old, new))
    assert all(w in str(err.value) for w in words), err.value


def test_registers_of_two_tables_may_share_an_address(tmp_path: Path) -> None:
    s = load_session(_session(tmp_path, "modbus-sim.toml", 'address = 2\ntype = "int16"',
                              'address = 0\ntable = "input"\ntype = "int16"'))
    assert [r.address for r in s.devices[0].config.registers][:2] == [0, 0]


# -- a stored FRF group names channels of its run --------------------------------------------------------
def _run_with_frf(tmp_path: Path) -> Path:
    path = tmp_path / "run.h5"
    chans = (Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2"))
    rng = np.random.default_rng(0)
    with RunWriter(path, "r1", sample_rate_hz=512.0, channels=chans, excitation="random", pose={}) as w:
        w.append(rng.standard_normal((4096, 2)))
    write_frf(path, "r1", fm.compute_frf(path, nfft=256))
    return path


@pytest.mark.parametrize(("key", "value", "words"), [
    ("inputs", '["F2"]', ("inputs names 'F2'", "not a channel")),
    ("outputs", '["zz"]', ("outputs names 'zz'", "not a channel")),
])
def test_frf_names_are_channels_of_the_run(tmp_path: Path, capsys, key, value, words) -> None:
    path = _run_with_frf(tmp_path)
    assert read_frf(path, "r1").inputs == ("F",)
    with h5py.File(path, "r+") as f:
        f["runs/r1/frf"].attrs[key] = value
    _one_line(capsys, main(["identify", str(path), "--out", str(tmp_path / "m.csv")]), "frf group", *words)


def test_an_frf_name_given_twice_is_refused(tmp_path: Path) -> None:
    path = _run_with_frf(tmp_path)
    with h5py.File(path, "r+") as f:
        g = f["runs/r1/frf"]
        H = g["H"][()]
        del g["H"]
        g["H"] = np.concatenate([H, H], axis=1)
        g.attrs["inputs"] = json.dumps(["F", "F"])
    with pytest.raises(ModalError, match="inputs names 'F' twice"):
        read_frf(path, "r1")


# -- rig places: one name, one place ---------------------------------------------------------------------
@pytest.mark.parametrize(("old", "new", "words"), [
    ('name = "elbow"', 'name = "tip"', ("joint name 'tip'", "reserved")),        # 'tip' meant the free end
    ('name = "elbow"', 'name = "link2"', ("joint 'link2'", "name of a link")),   # ambiguous location
    ('name = "link1"\n', 'name = "base"\n', ("link name 'base'", "reserved")),
])
def test_a_place_name_names_one_place(tmp_path: Path, old, new, words) -> None:
    (tmp_path / "rig.toml").write_text(RIG.replace(old, new, 1).replace('"link1"', '"base"'
                                       if new == 'name = "base"\n' else '"link1"'), encoding="utf-8")
    with pytest.raises(ModelError) as err:
        load_rig(tmp_path / "rig.toml")
    assert all(w in str(err.value) for w in words), err.value


def test_a_member_named_like_a_joint_is_refused(tmp_path: Path, capsys) -> None:
    member = ('[[member]]\nname = "elbow"\nfrom = "link1@0.3"\nto = "link2@0.1"\nmaterial = "aluminium"\n'
              'section = { shape = "solid_rect", width_m = 0.01, height_m = 0.01 }\n')
    (tmp_path / "rig.toml").write_text(RIG + "\n" + member, encoding="utf-8")
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\nt0,0\n", encoding="utf-8")
    code = main(["predict", str(tmp_path / "rig.toml"), "--model", "fe",
                 "--poses", str(tmp_path / "poses.csv"), "--out", str(tmp_path / "p.csv")])
    _one_line(capsys, code, "rig.toml", "member 'elbow' has the name of a joint")


def test_every_stored_rig_keeps_its_names() -> None:
    for path in sorted((REPO / "examples" / "rigs").glob("*.toml")):
        assert load_rig(path).links


# -- outputs of one command -------------------------------------------------------------------------------
def test_the_fault_log_is_not_the_pty_link(tmp_path: Path) -> None:
    # was "x: exists and is not a pty link" (the log had been created first)
    with pytest.raises(FixtureError, match="is also an input or output"):
        fm.serve_simulator("serial", duration=0.1, link=str(tmp_path / "x"), fault_log=str(tmp_path / "x"))
    assert not (tmp_path / "x").exists()


# -- API argument types ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("call", "words"), [
    (lambda: fm.track("moving.h5", pose_from="theta_deg"), "pose_from must map"),   # AttributeError
    (lambda: fm.track("moving.h5", pose_from={"theta_deg": 3}), "pose_from must map"),
    (lambda: fm.frf_from_arrays(np.linspace(1, 2, 3), None), "H must be an array"),  # "type object: no phase"
    (lambda: fm.frf_from_arrays("1,2,3", np.ones(3, complex)), "freq_hz must be an array"),
])
def test_api_arguments_of_the_wrong_type(call, words: str) -> None:
    with pytest.raises(TypeError, match=words):
        call()


# -- session roles: a pose from an encoder, a live H1 over a force -------------------------------------
@pytest.mark.parametrize(("old", "new", "words"), [
    ("notes =", 'pose_from = { theta_deg = "a1" }\nnotes =',
     ("pose_from.theta_deg = 'a1'", "'acceleration'")),
    ("pretrigger_samples = 64", 'pretrigger_samples = 64\nresponse = "F"', ("response = 'F'", "force")),
])
def test_session_channels_in_their_roles(tmp_path: Path, old: str, new: str, words) -> None:
    with pytest.raises(DaqError) as err:   # was rc 0: the pose the mean of m/s^2; an H1 of F/F = 1
        load_session(_session(tmp_path, "serial-sim.toml", old, new))
    assert all(w in str(err.value) for w in words), err.value


def test_a_pose_given_and_taken_from_an_encoder_is_refused(tmp_path: Path) -> None:
    path = _session(tmp_path, "can-moving-sim.toml", "pose_from = {",
                    "pose = { theta_deg = 3.0 }\npose_from = {")
    with pytest.raises(DaqError, match="'theta_deg' is given in pose and in pose_from"):
        load_session(path)


def test_track_pose_variable_is_one_of_the_run(tmp_path: Path, capsys) -> None:
    from flexmodal.fixtures.examples import moving_run  # a simulated moving-arm record

    path = moving_run(tmp_path)
    code = main(["identify", str(path), "--track", "--out", str(tmp_path / "m.csv"),
                 "--pose-from", "payload_kg=enc_elbow"])   # was rc 0: a map over "payload_kg"
    _one_line(capsys, code, "--pose-from payload_kg", "not a pose variable of the run", "theta_deg")


# -- options that nothing uses, and API types ---------------------------------------------------------------
def test_report_band_without_a_run_is_refused(tmp_path: Path, capsys) -> None:
    code = main(["report", "--measured", str(REPO / "examples/measured/seed003_table3_f1f2.csv"),
                 "--out", str(tmp_path / "r.html"), "--fmin", "10"])   # was rc 0, --fmin unused
    _one_line(capsys, code, "fmin", "no run")
    assert not (tmp_path / "r.html").exists()


def test_diagnose_effects_of_the_wrong_type() -> None:
    with pytest.raises(TypeError, match="effects must be"):   # was "can only join an iterable"
        fm.diagnose(REPO / "examples/rigs/seed003_two_link.toml",
                    REPO / "examples/measured/seed003_table3_f1f2.csv", effects=None)


def test_plot_stabilisation_band_is_checked_first() -> None:
    frf = fm.frf_from_arrays(np.linspace(0, 100, 201), np.exp(1j * np.linspace(0, 1, 201)))
    with pytest.raises(ModalError, match="--fmin 200 Hz must lie below --fmax 100 Hz"):
        fm.plot_stabilisation(frf, fmin=200, fmax=100)


# -- a channel's unit is of its kind --------------------------------------------------------------------
@pytest.mark.parametrize(("kind", "unit", "ok"), [
    ("force", "m/s^2", False), ("force", "g", False), ("acceleration", "N", False),
    ("acceleration", "kN", False), ("encoder", "N", False), ("strain", "deg", False),
    ("voltage", "m/s2", False),
    ("force", "N", True), ("force", "lbf", True), ("acceleration", "m/s²", True),
    ("acceleration", "in/s^2", True),
    ("voltage", "count", True), ("other", "N", True), ("strain", "με", True), ("encoder", "rad", True),
])
def test_channel_kind_and_unit_agree(kind: str, unit: str, ok: bool) -> None:
    if ok:
        assert Channel("c", kind, unit).unit == unit
    else:
        with pytest.raises(DaqError, match=re.escape(f"channel 'c': unit '{unit}' is a unit of")):
            Channel("c", kind, unit)


def test_a_force_stored_in_m_per_s2_is_refused_by_every_reader(tmp_path: Path, capsys) -> None:
    path = _run_with_frf(tmp_path)
    with h5py.File(path, "r+") as f:   # was: FRFs of two accelerations identified as accelerance, rc 0
        ch = f["runs/r1/channels"][()]
        ch[0]["unit"] = b"m/s^2"
        f["runs/r1/channels"][...] = ch
    _one_line(capsys, main(["identify", str(path), "--out", str(tmp_path / "m.csv")]),
              "run.h5: run 'r1': channel 'F': unit 'm/s^2' is a unit of acceleration, not of force")
    session = _session(tmp_path, "serial-sim.toml", 'unit = "N"\ndevice = "adc"\nsource = "ch0"',
                       'unit = "g"\ndevice = "adc"\nsource = "ch0"')
    with pytest.raises(DaqError, match="s.toml: channel 'F': unit 'g' is a unit of acceleration"):
        load_session(session)


# -- UFF: the abscissa of a function is of its type -----------------------------------------------------
@pytest.mark.parametrize(("func_type", "axis", "words"), [
    (4, 17, "function type 4 on an abscissa of time"),
    (1, 18, "function type 1 on an abscissa of frequency"),
])
def test_uff_abscissa_of_the_function_type(tmp_path: Path, capsys, func_type: int, axis: int,
                                           words: str) -> None:
    import pyuff

    x = np.arange(64) * 0.5
    data = np.exp(1j * x) if func_type == 4 else np.sin(x)
    records = [pyuff.prepare_58(func_type=func_type, rsp_node=n, rsp_dir=3, ref_node=9, ref_dir=3, x=x,
                                data=data * n, abscissa_spec_data_type=axis, ordinate_spec_data_type=12,
                                orddenom_spec_data_type=13, abscissa_spacing=1, id1=f"r{n}")
               for n in (1, 2)]
    pyuff.UFF(str(tmp_path / "u.uff")).write_sets(records, mode="overwrite")
    _one_line(capsys, main(["identify", str(tmp_path / "u.uff"), "--out", str(tmp_path / "m.csv")]),
              "u.uff: dataset 58 record 1", words)


# -- a stored FRF group is of its run's sampling; events reaching past the end ------------------------------
@pytest.mark.parametrize(("change", "words"), [
    (lambda g: g.attrs.__setitem__("sample_rate_hz", 4096.0), "sample_rate_hz = 4096 Hz is not its run's"),
    (lambda g: (g.__delitem__("freq_hz"), g.create_dataset("freq_hz", data=np.linspace(0, 400, 129))),
     "'freq_hz' reaches 400 Hz, above the Nyquist frequency 256 Hz"),
])
def test_frf_group_of_another_sampling_is_refused(tmp_path: Path, capsys, change, words: str) -> None:
    path = _run_with_frf(tmp_path)
    with h5py.File(path, "r+") as f:   # was rc 0: modes up to 875 Hz from a run sampled at 1024 Hz
        change(f["runs/r1/frf"])
    _one_line(capsys, main(["identify", str(path), "--out", str(tmp_path / "m.csv")]), "frf group", words)


def test_an_overload_reaching_far_past_the_end_is_one_interval(tmp_path: Path) -> None:
    from flexmodal.daq.store import Event

    path = tmp_path / "hit.h5"
    force = np.zeros(4096)
    force[1000:1010] = np.hanning(10) * 50
    resp = np.convolve(force, np.exp(-np.arange(400) / 60.0) * np.sin(np.arange(400) / 2.0))[:4096]
    with RunWriter(path, "r1", sample_rate_hz=512.0, excitation="impact", pose={},
                   channels=(Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2"))) as w:
        w.append(np.column_stack([force, resp]))
        w.add_events([Event("trigger", 1000), Event("overload", 900, 10**12, "a1")])   # frf hung (a list)
    with pytest.raises(ModalError, match="hit at sample 1000: overload"):
        fm.compute_frf(path)


def test_a_dbc_signal_of_factor_zero_is_refused(tmp_path: Path) -> None:
    from flexmodal.daq.dbc import load_message

    text = (REPO / "fixtures" / "flexmodal_sim.dbc").read_text(encoding="utf-8")
    old = "SG_ a2 m0 : 48|16@1- (0.30517578125,0.0)"
    assert old in text   # a factor 0 recorded a channel of zeros, rc 0
    (tmp_path / "x.dbc").write_text(text.replace(old, "SG_ a2 m0 : 48|16@1- (0,0.0)"), encoding="utf-8")
    with pytest.raises(DaqError, match=r"x\.dbc: DBC signal 'a2': factor 0 "):
        load_message(str(tmp_path / "x.dbc"), "FlexScan")


@pytest.mark.parametrize(("call", "error", "words"), [
    (lambda: fm.report("r.html", measured=MEASURED, repeats=str(MEASURED)), TypeError,
     "repeats must be a list"),                                    # was "m: modal table not found"
    (lambda: fm.report("r.html", measured=MEASURED, predictions=str(MEASURED)), TypeError,
     "predictions must be a list"),
])
def test_api_one_table_where_a_list_belongs(call, error, words: str) -> None:
    with pytest.raises(error, match=words):
        call()


def test_api_numpy_whole_numbers_and_sets_are_numbers() -> None:
    rig = REPO / "examples" / "rigs" / "seed003_two_link.toml"
    table = fm.predict(rig, {"t": {"theta_deg": 0.0}}, "fe", np.int64(2))   # was "not a whole number"
    assert sorted(table.frame["mode"]) == [1, 2]
    f = np.linspace(0.0, 100.0, 401)
    s, w0 = 2j * np.pi * f, 2 * np.pi * 40.0                       # one mode at 40 Hz, 2 % damping
    frf = fm.frf_from_arrays(f, s**2 / (s**2 + 2 * 0.02 * w0 * s + w0**2), outputs=["tip"])
    modes = fm.identify(frf, poles_hz={40.0}).table                 # a set: float() of the set, TypeError
    assert modes.frame["freq_hz"].tolist() == pytest.approx([40.0], rel=1e-3)


@pytest.mark.parametrize(("where", "driving"), [(("tip", "y"), True), ((" Tip", "Y "), True),
                                                (("tip", "x"), False), (("link1@1", "y"), False)])
def test_the_driving_point_ignores_case(tmp_path: Path, where: tuple[str, str], driving: bool) -> None:
    """A response at 'Tip'/'Y' under a force at 'tip'/'y' was no driving point: shapes scaled to unit
    maximum, not mass-normalised, without a word."""
    from flexmodal.daq.store import read_run
    from flexmodal.modal.compute import compute_frf
    from flexmodal.modal.sources import _driving_point

    chans = [Channel("F", "force", "N", location="tip", direction="y"),
             Channel("a1", "acceleration", "m/s^2", location=where[0], direction=where[1])]
    with RunWriter(tmp_path / "run.h5", "r1", sample_rate_hz=1024.0, channels=chans, excitation="random",
                   pose={}) as w:
        w.append(np.random.default_rng(0).standard_normal((1024, 2)))
    run = read_run(tmp_path / "run.h5", "r1")
    assert (_driving_point(run, compute_frf(run, nfft=256)) == 0) is driving
