"""Fuzz every file loader: session and rig TOML, modal and poses CSV, UFF, HDF5 run files and their
stored FRF groups, diagnosis JSON; each also at depth and size extremes (nesting 10^5 deep, integers of
5001 digits, million-character values, 10^5 rows).

Each property mutates a valid file (or its parsed document) at random and asserts that the loader
either accepts it or raises its package's error type: nothing else escapes.  Known answers anchor the
mutations: the unmutated inputs load, and the loaders' results for them are checked.
"""

from __future__ import annotations

import copy
import math
import tempfile
import tomllib
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import REPO
from fuzz_support import LONG_EXAMPLES, prop, run_profile
from hypothesis import strategies as st

from flexmodal.contract.errors import ContractError
from flexmodal.contract.table import ModalTable, poses_from_csv
from flexmodal.daq.errors import DaqError
from flexmodal.daq.session import load_session, parse_session
from flexmodal.daq.store import Channel, RunWriter, list_runs, read_run
from flexmodal.modal.errors import ModalError
from flexmodal.modal.uff import read_uff
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import load_rig, parse_rig

SESSIONS = REPO / "examples" / "sessions"
RIGS = REPO / "examples" / "rigs"
MODES = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"
TEXT = st.characters(blacklist_categories=("Cs",))
VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-2**63, 2**63 - 1) | st.floats() | st.text(TEXT, max_size=12),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(TEXT, max_size=8), inner, max_size=3),
    max_leaves=6)


def _slots(node, out: list) -> list:
    """Every (container, key) of a nested dict/list document."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for key, value in items:
        out.append((node, key))
        _slots(value, out)
    return out


@st.composite
def mutated_doc(draw, doc: dict) -> dict:
    """``doc`` with 1-3 values replaced by random values or deleted."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        slots = _slots(doc, [])
        if not slots:
            break
        container, key = slots[draw(st.integers(0, len(slots) - 1))]
        if isinstance(container, dict) and draw(st.booleans()):
            del container[key]
        else:
            container[key] = draw(VALUES)
    return doc


@st.composite
def mutated_text(draw, text: str) -> bytes:
    """``text`` with lines deleted or duplicated, random text or bytes inserted, or cut short."""
    lines = text.splitlines(keepends=True)
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, max(len(lines) - 1, 0)))
        action = draw(st.sampled_from(["delete", "duplicate", "insert", "replace"]))
        if action == "delete" and lines:
            del lines[i]
        elif action == "duplicate" and lines:
            lines.insert(i, lines[i])
        elif action == "insert":
            lines.insert(i, draw(st.text(TEXT, max_size=30)))
        elif lines:
            lines[i] = draw(st.text(TEXT, max_size=30)) + "\n"
    data = "".join(lines).encode()
    if draw(st.booleans()):
        at = draw(st.integers(0, len(data)))
        data = data[:at] + draw(st.binary(max_size=8)) + data[at:]
    if draw(st.integers(0, 4)) == 0:
        data = data[:draw(st.integers(0, len(data)))]
    return data


def _loads_or(error: type[Exception], load, path: Path) -> None:
    try:
        load(path)
    except error:
        pass


def _with_file(data: bytes, name: str, check) -> None:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / name
        path.write_bytes(data)
        check(path)


# -- session TOML -----------------------------------------------------------------------------------
SESSION_FILE = SESSIONS / "serial-sim.toml"
SESSION_DOC = tomllib.loads(SESSION_FILE.read_text(encoding="utf-8"))


@prop(mutated_doc(SESSION_DOC))
def prop_session_doc(doc: dict) -> None:
    try:
        parse_session(doc, SESSION_FILE)
    except DaqError:
        pass


@prop(mutated_text(SESSION_FILE.read_text(encoding="utf-8")))
def prop_session_text(data: bytes) -> None:
    _with_file(data, "session.toml", lambda p: _loads_or(DaqError, load_session, p))


# -- rig TOML ---------------------------------------------------------------------------------------
RIG_FILE = RIGS / "demo_arm.toml"
RIG_DOC = tomllib.loads(RIG_FILE.read_text(encoding="utf-8"))


@prop(mutated_doc(RIG_DOC))
def prop_rig_doc(doc: dict) -> None:
    try:
        rig = parse_rig(doc, "rig.toml")
    except ModelError:
        return
    for link in rig.links:  # what is accepted is physically meaningful
        s = link.section
        assert all(math.isfinite(v) and v > 0 for v in (link.length_m, s.EA_N, s.EI_Nm2, s.mass_per_m_kg))
        assert link.elements is None or 1 <= link.elements <= 500


@prop(mutated_text(RIG_FILE.read_text(encoding="utf-8")))
def prop_rig_text(data: bytes) -> None:
    _with_file(data, "rig.toml", lambda p: _loads_or(ModelError, load_rig, p))


# -- modal and poses CSV ----------------------------------------------------------------------------
@prop(mutated_text(MODES.read_text(encoding="utf-8")))
def prop_modal_csv(data: bytes) -> None:
    def check(p: Path) -> None:
        try:
            table = ModalTable.read_csv(p)
        except ContractError:
            return
        frame = table.frame
        assert frame["config"].map(lambda c: isinstance(c, str) and c.strip() != "").all()
        assert np.isfinite(frame["freq_hz"].to_numpy(float)).all()
        assert (frame["mode"] >= 1).all()
    _with_file(data, "modes.csv", check)


POSES = "config,pose.theta_deg,pose.payload_kg\ntheta0,0,0\ntheta60,60,0.5\ntheta90,90,1\n"


@prop(mutated_text(POSES))
def prop_poses_csv(data: bytes) -> None:
    def check(p: Path) -> None:
        try:
            poses = poses_from_csv(p)
        except ContractError:
            return
        values = [v for pose in poses.values() for v in pose.values()]
        assert all(isinstance(v, float) and math.isfinite(v) for v in values)
    _with_file(data, "poses.csv", check)


# -- UFF --------------------------------------------------------------------------------------------
def _uff_text() -> str:
    import pyuff

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "frf.uff"
        f = np.linspace(0.0, 200.0, 41)
        H = 1.0 / (1.0 - (f / 80.0) ** 2 + 0.04j * f / 80.0)
        sets = [pyuff.prepare_58(func_type=4, rsp_node=k, rsp_dir=3, ref_node=9, ref_dir=3,
                                 ordinate_spec_data_type=12, orddenom_spec_data_type=13,
                                 abscissa_spec_data_type=18, data=H * k, x=f, abscissa_spacing=1,
                                 abscissa_min=0.0, abscissa_inc=5.0, num_pts=41) for k in (1, 2)]
        pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
        return path.read_text()


UFF_TEXT = _uff_text()


@prop(mutated_text(UFF_TEXT))
def prop_uff(data: bytes) -> None:
    _with_file(data, "frf.uff", lambda p: _loads_or(ModalError, read_uff, p))


# -- HDF5 run files ---------------------------------------------------------------------------------
def _run_bytes() -> bytes:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "run.h5"
        channels = [Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2")]
        with RunWriter(path, "r1", sample_rate_hz=512.0, channels=channels, excitation="random",
                       pose={"theta_deg": 30.0}) as w:
            w.append(np.random.default_rng(0).standard_normal((1024, 2)))
        return path.read_bytes()


RUN_BYTES = _run_bytes()
ATTR_TEXT = st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00")  # HDF5 strings
ATTR_VALUES = (st.integers(-2**31, 2**31) | st.floats() | st.text(ATTR_TEXT, max_size=20)
               | st.lists(st.floats(allow_nan=False), min_size=1, max_size=3).map(np.array))
DATASETS = st.sampled_from([
    np.arange(6.0), np.zeros((3, 2)), np.zeros((3, 5), "i4"), np.array([b"a", b"bc"]),
    np.zeros(2, [("name", "S4"), ("kind", "S8")]), np.zeros(0), np.zeros((0, 2)),
    np.zeros(2, [("kind", "f8"), ("sample_index", "i8"), ("count", "i8"), ("detail", "S4")]),
])


@st.composite
def run_mutation(draw):
    kind = draw(st.sampled_from(["set_attr", "del_attr", "dataset", "del_dataset", "truncate", "runs"]))
    if kind in ("set_attr", "del_attr"):
        name = draw(st.sampled_from(["sample_rate_hz", "start_time", "excitation", "pose"]))
        return kind, name, draw(ATTR_VALUES) if kind == "set_attr" else None
    if kind in ("dataset", "del_dataset"):
        name = draw(st.sampled_from(["samples", "channels", "events"]))
        return kind, name, draw(DATASETS) if kind == "dataset" else None
    if kind == "truncate":
        return kind, None, draw(st.integers(0, len(RUN_BYTES) - 1))
    return kind, None, draw(DATASETS)


def _apply(path: Path, mutation) -> None:
    kind, name, value = mutation
    if kind == "truncate":
        path.write_bytes(RUN_BYTES[:value])
        return
    path.write_bytes(RUN_BYTES)
    with h5py.File(path, "r+") as f:
        g = f["runs/r1"]
        if kind == "set_attr":
            g.attrs[name] = value
        elif kind == "del_attr":
            del g.attrs[name]
        elif kind == "runs":
            del f["runs"]
            f["runs"] = value
        else:
            del g[name]
            if kind == "dataset":
                g[name] = value


@prop(run_mutation())
def prop_run_file(mutation) -> None:
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "run.h5"
        _apply(path, mutation)
        try:
            for rid in list_runs(path):
                run = read_run(path, rid)
                assert run.samples.ndim == 2 and run.samples.shape[1] == len(run.channels)
                assert math.isfinite(run.sample_rate_hz) and run.sample_rate_hz > 0
        except DaqError:
            pass


# -- depth and size extremes (issue 24): every parser refuses them with its own error or copes ------------
DEPTHS = st.sampled_from([99, 100, 101, 1_000, 100_000])
DIGITS = st.sampled_from([4300, 4301, 5001, 100_000])


@st.composite
def extreme_value(draw, syntax: str) -> str:
    """A TOML or JSON value at a parser's limits: nested arrays or tables DEPTHS deep, an integer of
    DIGITS digits, a string of 200 000 characters, an exponent beyond float range."""
    kind = draw(st.sampled_from(["array", "table", "int", "string", "float"]))
    if kind in ("array", "table"):
        n = draw(DEPTHS)
        if kind == "array":
            return "[" * n + "1" + "]" * n
        key = "a = " if syntax == "toml" else '"a": '
        return ("{" + key) * n + "1" + "}" * n
    if kind == "int":
        return draw(st.sampled_from(["", "-"])) + "9" * draw(DIGITS)
    if kind == "string":
        return '"' + "x" * 200_000 + '"'
    return draw(st.sampled_from(["1e999", "-1e999", "1e-999", "9" * 400 + ".5"]))


@st.composite
def extreme_toml(draw, text: str) -> bytes:
    """``text`` with one top-level value (a known key, or a new one) replaced by an extreme value."""
    keys = [line.split("=", 1)[0].strip() for line in text.splitlines()
            if "=" in line and not line.startswith(("#", " ", "["))]
    key = draw(st.sampled_from(keys + ["extra_key"]))
    value = draw(extreme_value("toml"))
    lines = [f"{key} = {value}" if line.split("=", 1)[0].strip() == key and not line.startswith("#")
             else line for line in text.splitlines()]
    if key == "extra_key":
        lines.insert(0, f"{key} = {value}")
    return "\n".join(lines).encode()


@st.composite
def extreme_csv(draw, text: str) -> bytes:
    """``text`` with an extreme cell, line or table size: a cell longer than the csv module's field
    limit (200 000 characters), a number of DIGITS digits, 20 000 rows, 2 000 columns, or a line of
    200 000 commas."""
    header, *rows = text.splitlines()
    kind = draw(st.sampled_from(["cell", "digits", "rows", "columns", "commas"]))
    if kind == "cell":
        rows[0] = "x" * 200_000 + rows[0][rows[0].index(","):]
    elif kind == "digits":
        cells = rows[0].split(",")
        cells[draw(st.integers(1, len(cells) - 1))] = "9" * draw(DIGITS)
        rows[0] = ",".join(cells)
    elif kind == "rows":
        rows = rows * (20_000 // len(rows))
    elif kind == "columns":
        header += "".join(f",shape.s{i}" for i in range(2_000))
        rows = [r + ",1" * 2_000 for r in rows]
    else:
        rows.append("," * 200_000)
    return "\n".join([header, *rows, ""]).encode()


@prop(extreme_toml(SESSION_FILE.read_text(encoding="utf-8")))
def prop_session_extreme(data: bytes) -> None:
    _with_file(data, "session.toml", lambda p: _loads_or(DaqError, load_session, p))


@prop(extreme_toml(RIG_FILE.read_text(encoding="utf-8")))
def prop_rig_extreme(data: bytes) -> None:
    _with_file(data, "rig.toml", lambda p: _loads_or(ModelError, load_rig, p))


@prop(extreme_csv(MODES.read_text(encoding="utf-8")))
def prop_modal_csv_extreme(data: bytes) -> None:
    _with_file(data, "modes.csv", lambda p: _loads_or(ContractError, ModalTable.read_csv, p))


@prop(extreme_csv(POSES))
def prop_poses_csv_extreme(data: bytes) -> None:
    _with_file(data, "poses.csv", lambda p: _loads_or(ContractError, poses_from_csv, p))


@prop(extreme_value("json"))
def prop_diagnosis_json_extreme(text: str) -> None:
    from flexmodal.reports.errors import ReportError
    from flexmodal.reports.html import load_diagnosis

    _with_file(text.encode(), "diagnosis.json", lambda p: _loads_or(ReportError, load_diagnosis, p))


@prop(st.sampled_from(["pose", "start_time", "excitation"]), extreme_value("json"))
def prop_run_attribute_extreme(name: str, text: str) -> None:
    _attribute_loads_or(RUN_BYTES, "runs/r1", name, text, DaqError, lambda p: read_run(p, "r1"))


def _attribute_loads_or(run_bytes: bytes, group: str, name: str, text: str, error: type[Exception],
                        load) -> None:
    """A copy of the run file ``run_bytes`` with attribute ``name`` of ``group`` set to ``text``:
    ``load`` reads it or raises ``error``."""
    def check(path: Path) -> None:
        with h5py.File(path, "r+") as f:
            f[group].attrs[name] = text
        _loads_or(error, load, path)

    _with_file(run_bytes, "run.h5", check)


@prop(st.sampled_from(["provenance", "outputs", "inputs", "nfft", "estimator"]), extreme_value("json"))
def prop_frf_attribute_extreme(name: str, text: str) -> None:
    from flexmodal.modal.runs_io import read_frf

    _attribute_loads_or(FRF_RUN_BYTES, "runs/r1/frf", name, text, ModalError, lambda p: read_frf(p, "r1"))


@prop(st.sampled_from(["num_pts", "abscissa_inc"]), st.sampled_from(["999999999999", "0", "-5", "1e308"]))
def prop_uff_header_extreme(field: str, value: str) -> None:
    """A dataset-58 header announcing absurd sizes (line 7 of the set: number of points, spacing)."""
    lines = UFF_TEXT.splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip() == "58") + 7
    cells = lines[at].split()
    cells[1 if field == "num_pts" else 4] = value
    lines[at] = " ".join(cells)
    _with_file("\n".join(lines).encode(), "frf.uff", lambda p: _loads_or(ModalError, read_uff, p))


def _frf_run_bytes() -> bytes:
    from flexmodal.api import compute_frf

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "run.h5"
        path.write_bytes(RUN_BYTES)
        compute_frf(path, store=True, nfft=256)
        return path.read_bytes()


FRF_RUN_BYTES = _frf_run_bytes()


# -- stored stabilisation diagrams (modal/diagrams.py, MODES.diagram.npz) ------------------------------
def _diagram_arrays() -> dict:
    from flexmodal.modal.diagrams import FORMAT

    return {"format": np.array(FORMAT), "d0.key": np.array("0" * 64), "d0.config": np.array("c"),
            "d0.order_note": np.array("order 4"), "d0.order": np.array([2, 4, 4]),
            "d0.freq_hz": np.array([30.0, 30.1, 54.0]), "d0.damping_ratio": np.full(3, 0.02),
            "d0.pole": np.array([-3.8 + 188.5j, -3.8 + 189.1j, -6.8 + 339.3j]),
            "d0.stable_freq": np.ones(3, bool), "d0.stable_damping": np.ones(3, bool),
            "d0.stable_shape": np.ones(3, bool), "d0.previous": np.array([-1, 0, -1])}


def _diagram_bytes(arrays: dict, compressed: bool = False) -> bytes:
    import io

    buf = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buf, **arrays)
    return buf.getvalue()


DIAGRAM_BYTES = _diagram_bytes(_diagram_arrays())


@prop(st.lists(st.tuples(st.integers(0, len(DIAGRAM_BYTES) - 1), st.integers(0, 255)), min_size=1,
               max_size=8), st.integers(0, len(DIAGRAM_BYTES)))
def prop_diagram_bytes(flips: list, keep: int) -> None:
    """A stored diagram with bytes overwritten and cut short: read whole or one ModalError."""
    from flexmodal.modal.diagrams import read_diagrams

    data = bytearray(DIAGRAM_BYTES)
    for at, value in flips:
        data[at] = value
    _with_file(bytes(data[:max(keep, 1)]), "m.diagram.npz", lambda p: _loads_or(ModalError, read_diagrams, p))


@prop(st.sampled_from(["order", "freq_hz", "damping_ratio", "pole", "previous", "key", "stable_freq"]),
      st.sampled_from([np.nan, np.inf, -np.inf, -1, 0, 10**18, 1e308, "text"]), st.booleans())
def prop_diagram_values_extreme(name: str, value, whole: bool) -> None:
    """One entry of a stored diagram set to an extreme value (one element, or the whole entry as a
    0-d array): read whole or one ModalError."""
    from flexmodal.modal.diagrams import read_diagrams

    arrays = _diagram_arrays()
    if whole or isinstance(value, str) or arrays[f"d0.{name}"].ndim == 0:
        arrays[f"d0.{name}"] = np.array(value)
    else:
        entry = arrays[f"d0.{name}"]
        try:
            entry[0] = value
        except (OverflowError, ValueError):   # a value the entry's dtype cannot hold: the whole entry then
            arrays[f"d0.{name}"] = np.array(value)
    _with_file(_diagram_bytes(arrays, compressed=whole), "m.diagram.npz",
               lambda p: _loads_or(ModalError, read_diagrams, p))


# -- known answers: the unmutated inputs load ---------------------------------------------------------
def test_unmutated_inputs_load(tmp_path: Path) -> None:
    assert parse_session(SESSION_DOC, SESSION_FILE).sample_rate_hz == 2048.0
    assert [lk.name for lk in parse_rig(RIG_DOC, "rig.toml").links] == ["link1", "link2"]
    assert ModalTable.read_csv(MODES).freq_hz("theta60").tolist() == [27.0, 74.5]
    (tmp_path / "poses.csv").write_text(POSES)
    assert poses_from_csv(tmp_path / "poses.csv")["theta60"] == {"theta_deg": 60.0, "payload_kg": 0.5}
    (tmp_path / "frf.uff").write_text(UFF_TEXT)
    frfs = read_uff(tmp_path / "frf.uff")
    assert frfs.H.shape == (2, 1, 41) and abs(frfs.H[1, 0, 0] - 2.0) < 1e-9
    (tmp_path / "run.h5").write_bytes(RUN_BYTES)
    assert read_run(tmp_path / "run.h5", "r1").samples.shape == (1024, 2)
    (tmp_path / "m.diagram.npz").write_bytes(DIAGRAM_BYTES)
    from flexmodal.modal.diagrams import read_diagrams

    stored = read_diagrams(tmp_path / "m.diagram.npz")["0" * 64]
    assert stored.stabilisation.freq_hz.tolist() == [30.0, 30.1, 54.0]


DEFAULT = {prop_session_doc: 150, prop_session_text: 80, prop_rig_doc: 150, prop_rig_text: 80,
           prop_modal_csv: 100, prop_poses_csv: 100, prop_uff: 60, prop_run_file: 80,
           prop_session_extreme: 12, prop_rig_extreme: 12, prop_modal_csv_extreme: 6,
           prop_poses_csv_extreme: 6, prop_diagnosis_json_extreme: 12, prop_run_attribute_extreme: 12,
           prop_frf_attribute_extreme: 12, prop_uff_header_extreme: 8, prop_diagram_bytes: 60,
           prop_diagram_values_extreme: 30}


@pytest.mark.parametrize("fn", list(DEFAULT), ids=[p.__name__ for p in DEFAULT])
def test_fuzz(fn) -> None:
    run_profile(fn, DEFAULT[fn])


@pytest.mark.slow
@pytest.mark.parametrize("fn", list(DEFAULT), ids=[p.__name__ for p in DEFAULT])
def test_long_fuzz(fn) -> None:
    run_profile(fn, LONG_EXAMPLES, long=True)
