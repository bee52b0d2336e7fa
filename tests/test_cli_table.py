"""Issue 13: every bad input of every command ends in one line on stderr naming it, and exit 2.

Each row is one malformed input (a file, an option value or an output path) given to the ``flexmodal``
console script in a process of its own with a time limit; rows run in a few threads at once.  The
control rows start the installed console script cold; the others start it warm (tests/warm_cli.py: a
process forked from a server that has imported numpy, scipy, pandas, h5py and matplotlib, then running
the script's own body), which saves 0.3-1 s of CPU per row.  (The installed console script started cold
runs every command in other default tests: frf, identify, report, predict and acquire in
tests/test_interrupt_commands.py, demo in tests/test_cli_interrupt.py, ``sim serve`` as the child of every
simulated acquire; diagnose started cold in tests/test_demo.py's chain.)
A row passes when the command exits 2 within the limit, prints no traceback, prints exactly one line on
stderr, and that line holds the row's expected words (the file, field or value and what is wrong).
The control rows at the end use the same base files unmodified and must exit 0, so a row's exit 2
comes from its own mutation, not from a broken base file.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from queue import Queue

import h5py
import numpy as np
import pytest
from conftest import REPO
from warm_cli import WarmCli

pytestmark = pytest.mark.timeout(3600)  # all rows run in the first row's set-up (a module fixture)
ROW_TIMEOUT_S = 300.0  # a hang guard: rows take 2-8 s at load 11; a niced process at load 20 needs
# 10-20 s just to import acquire's libraries (26 Nov), so 30 s could call a slow row a hang (and 120 s
# one that starts a simulator at load 40)
THREADS = 2
RIG = (REPO / "examples" / "rigs" / "seed003_two_link.toml").read_text(encoding="utf-8")
MODES = (REPO / "examples" / "measured" / "seed003_table3_f1f2.csv").read_text(encoding="utf-8")
SESSION = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text(encoding="utf-8").replace(
    'rig = "../rigs/demo_arm.toml"', f'rig = "{REPO / "examples" / "rigs" / "demo_arm.toml"}"')
MODBUS_SESSION = (REPO / "examples" / "sessions" / "modbus-sim.toml").read_text(encoding="utf-8").replace(
    'rig = "../rigs/demo_arm.toml"', f'rig = "{REPO / "examples" / "rigs" / "demo_arm.toml"}"')
MCU = (REPO / "examples" / "sessions" / "mcu-serial.toml").read_text(encoding="utf-8").replace(
    'port = "/dev/ttyACM0" ', 'port = "loop://" ')
CAN = (REPO / "examples" / "sessions" / "can-module.toml").read_text(encoding="utf-8")
DBC = (REPO / "examples" / "sessions" / "can-module.dbc").read_text(encoding="utf-8")
POSES = "config,pose.theta_deg\ntheta0,0\ntheta60,60\n"
BINARY = bytes(range(256)) * 4
LATIN1_COMMENT = "# accelerometer sensitivity in mV/(m/s²) µ\n".encode("latin-1")


def write_run(path: Path, *, channel_names: tuple[str, str] = ("F", "a1")) -> None:
    """A small valid run: a random force and a response, 1024 Hz, 8 s."""
    from flexmodal.daq.store import Channel, RunWriter

    channels = [Channel(channel_names[0], "force", "N", location="tip", direction="transverse"),
                Channel(channel_names[1], "acceleration", "m/s^2", location="tip", direction="transverse")]
    rng = np.random.default_rng(1)
    force = rng.standard_normal(8192)
    response = np.convolve(force, np.exp(-np.arange(200) / 40.0) * np.sin(np.arange(200) / 3.0))[:8192]
    with RunWriter(path, "r1", sample_rate_hz=1024.0, channels=channels, excitation="random",
                   pose={"theta_deg": 30.0}) as writer:
        writer.append(np.column_stack([force, response]))


def mutate_run(change: Callable[[h5py.Group], None]) -> Callable[[Path], None]:
    """A writer of a valid run file followed by ``change`` applied to its run group."""
    def make(path: Path) -> None:
        write_run(path)
        with h5py.File(path, "r+") as f:
            change(f["runs/r1"])
    return make


def set_attr(name: str, value) -> Callable[[h5py.Group], None]:
    def change(g: h5py.Group) -> None:
        g.attrs[name] = value
    return change


def del_attr(name: str) -> Callable[[h5py.Group], None]:
    def change(g: h5py.Group) -> None:
        del g.attrs[name]
    return change


def replace_dataset(name: str, data) -> Callable[[h5py.Group], None]:
    def change(g: h5py.Group) -> None:
        del g[name]
        g.create_dataset(name, data=data)
    return change


def truncated_run(path: Path) -> None:
    write_run(path)
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 3])


def truncated_live_run(path: Path) -> None:
    """A truncated file whose superblock still says a writer has it open (a killed writer's file)."""
    from flexmodal.daq.h5file import _lookup3

    write_run(path)
    data = bytearray(path.read_bytes()[:60000])
    data[11] = 0x05  # write access + SWMR write
    data[44:48] = _lookup3(bytes(data[:44])).to_bytes(4, "little")
    path.write_bytes(bytes(data))


def foreign_hdf5(path: Path) -> None:
    with h5py.File(path, "w") as f:
        f["data"] = np.arange(10.0)


def runs_dataset(path: Path) -> None:
    with h5py.File(path, "w") as f:
        f["runs"] = np.arange(10.0)


def uff_flat(path: Path) -> None:
    """A dataset-58 FRF that is 1 at every one of its 101 lines: no mode to find."""
    import pyuff

    x = np.linspace(0.0, 100.0, 101)
    sets = [pyuff.prepare_58(func_type=4, rsp_node=1, rsp_dir=3, ref_node=2, ref_dir=3,
                             ordinate_spec_data_type=12, orddenom_spec_data_type=13,
                             abscissa_spec_data_type=18, data=np.ones(101, complex), x=x,
                             abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=1.0, num_pts=101)]
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")


def uff_cut_short(path: Path) -> None:
    """A dataset-58 FRF whose data block ends after 14 of the 101 points its header announces."""
    uff_flat(path)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:20] + lines[-1:]) + "\n")


def fifo(path: Path) -> None:
    os.mkfifo(path)


def link_to(name: str) -> Callable[[Path], None]:
    """A symlink to the row folder's ``name``."""
    def make(path: Path) -> None:
        path.symlink_to(path.parent / name)
    return make


def hard_link_to(name: str) -> Callable[[Path], None]:
    def make(path: Path) -> None:
        os.link(path.parent / name, path)
    return make


def sparse(head: str, size: int) -> Callable[[Path], None]:
    """A file that starts with ``head`` and is ``size`` bytes long (a hole: no disk used)."""
    def make(path: Path) -> None:
        path.write_text(head)
        os.truncate(path, size)
    return make


def h5_file(path: Path) -> None:
    """An HDF5 file that is not a table (a run store where a CSV would go)."""
    write_run(path)


def soft_link_loop(path: Path) -> None:
    write_run(path)
    with h5py.File(path, "r+") as f:
        del f["runs/r1"]
        f["runs/r1"] = h5py.SoftLink("/runs/r2")
        f["runs/r2"] = h5py.SoftLink("/runs/r1")


def soft_link_self_loop(path: Path) -> None:
    """One run whose link points at itself: one bad run, one line (a loop of two names is two bad runs,
    each named on its line by frf, which goes on past a bad run: tests/test_bad_runs_batch)."""
    write_run(path)
    with h5py.File(path, "r+") as f:
        del f["runs/r1"]
        f["runs/r1"] = h5py.SoftLink("/runs/r1")


def external_link(name: str) -> Callable[[h5py.Group], None]:
    def change(g: h5py.Group) -> None:
        del g[name]
        g[name] = h5py.ExternalLink("missing.h5", "/x")
    return change


def dangling_soft(name: str) -> Callable[[h5py.Group], None]:
    def change(g: h5py.Group) -> None:
        del g[name]
        g[name] = h5py.SoftLink("/nowhere")
    return change


def _rechunk(g: h5py.Group, **options) -> h5py.Dataset:
    data, attrs = g["samples"][()], dict(g["samples"].attrs)
    del g["samples"]
    d = g.create_dataset("samples", data=data, chunks=(1024, data.shape[1]), **options)
    d.attrs.update(attrs)
    return d


def damaged_chunk(path: Path) -> None:
    """Samples stored gzip-compressed in chunks, one chunk's bytes overwritten."""
    write_run(path)
    with h5py.File(path, "r+") as f:
        d = _rechunk(f["runs/r1"], compression="gzip")
        offset = d.id.get_chunk_info(3).byte_offset
    data = bytearray(path.read_bytes())
    data[offset + 10:offset + 60] = b"\xff" * 50
    path.write_bytes(bytes(data))


def missing_filter(path: Path) -> None:
    """Samples whose chunks need filter 32004 (LZ4, not installed here): written raw with the chunks'
    filter masks saying it was applied, then the filter marked required in the pipeline message."""
    write_run(path)
    with h5py.File(path, "r+") as f:
        g = f["runs/r1"]
        data = g["samples"][()]
        del g["samples"]
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_chunk((1024, data.shape[1]))
        dcpl.set_filter(32004, h5py.h5z.FLAG_OPTIONAL, (0,))
        space = h5py.h5s.create_simple(data.shape)
        d = h5py.h5d.create(g.id, b"samples", h5py.h5t.NATIVE_DOUBLE, space, dcpl=dcpl)
        for r in range(0, data.shape[0], 1024):
            d.write_direct_chunk((r, 0), np.ascontiguousarray(data[r:r + 1024]).tobytes(), filter_mask=0)
    raw = bytearray(path.read_bytes())
    at = raw.find(b"\x04\x7d\x00\x00\x01\x00")   # filter id 32004, no name, flags = optional
    raw[at + 4:at + 6] = b"\x00\x00"                # flags = required
    path.write_bytes(bytes(raw))


def with_frf(change: Callable[[h5py.Group], None]) -> Callable[[Path], None]:
    """A valid run with its FRFs stored, then ``change`` applied to the run group."""
    def make(path: Path) -> None:
        from flexmodal.api import compute_frf

        write_run(path)
        compute_frf(path, store=True)
        with h5py.File(path, "r+") as f:
            change(f["runs/r1"])
    return make


def duplicate_channel(g: h5py.Group) -> None:
    table = g["channels"][()]
    table[1]["name"] = table[0]["name"]
    g["channels"][...] = table


def stored_diagram(change: Callable[[dict], None] | None = None) -> Callable[[Path], None]:
    """A stabilisation-diagram store (modal/diagrams.py) of 3 poles under a key no input has, then
    ``change`` applied to its arrays."""
    def make(path: Path) -> None:
        from flexmodal.modal.diagrams import FORMAT

        arrays = {"format": np.array(FORMAT), "d0.key": np.array("0" * 64), "d0.config": np.array("r1"),
                  "d0.order_note": np.array("model order 4"), "d0.order": np.array([2, 4, 4]),
                  "d0.freq_hz": np.array([30.0, 30.1, 54.0]), "d0.damping_ratio": np.full(3, 0.02),
                  "d0.pole": np.array([-3.8 + 188.5j, -3.8 + 189.1j, -6.8 + 339.3j]),
                  "d0.stable_freq": np.ones(3, bool), "d0.stable_damping": np.ones(3, bool),
                  "d0.stable_shape": np.ones(3, bool), "d0.previous": np.array([-1, 0, -1])}
        if change is not None:
            change(arrays)
        with open(path, "wb") as f:
            np.savez_compressed(f, **arrays)
    return make


def diagram_declaring(shape: tuple[int, ...]) -> Callable[[Path], None]:
    """A diagram store whose freq_hz entry declares ``shape`` in its header and holds 64 bytes."""
    def make(path: Path) -> None:
        import io
        import zipfile

        stored_diagram()(path)
        with np.load(path) as npz:
            arrays = {k: npz[k] for k in npz.files}
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": shape})
        with zipfile.ZipFile(path, "w") as zf:
            for k, a in arrays.items():
                member = io.BytesIO()
                np.save(member, a)
                declared = header.getvalue() + bytes(64)
                zf.writestr(k + ".npy", declared if k == "d0.freq_hz" else member.getvalue())
    return make


def _half_the_memory() -> int:
    """A size [bytes] twice what a reader bounded to a quarter of the available memory accepts."""
    from flexmodal.checked_io.text import available_memory_bytes

    return available_memory_bytes() // 2


def encoder_run(path: Path) -> None:
    """A small operational run: two responses and an elbow encoder turning 0 -> 80 deg, 1024 Hz, 8 s."""
    from flexmodal.daq.store import Channel, RunWriter

    channels = [Channel("a1", "acceleration", "m/s^2", location="tip", direction="transverse"),
                Channel("a2", "acceleration", "m/s^2", location="mid", direction="transverse"),
                Channel("enc", "encoder", "deg", location="elbow", direction="rotation")]
    rng = np.random.default_rng(2)
    mode = np.exp(-np.arange(200) / 40.0) * np.sin(np.arange(200) / 3.0)   # one mode near 54 Hz
    a = [np.convolve(rng.standard_normal(8192), mode)[:8192] for _ in range(2)]
    samples = np.column_stack([*a, np.linspace(0.0, 80.0, 8192)])
    with RunWriter(path, "r1", sample_rate_hz=1024.0, channels=channels, excitation="operational",
                   pose={"theta_deg": 0.0}) as writer:
        writer.append(samples)


def user_npz(path: Path) -> None:
    with open(path, "wb") as f:
        np.savez(f, my_data=np.arange(5.0))


def never_written(path: Path) -> None:
    """A run whose samples dataset declares 10^11 rows (1.5 TB) and stores none (6 kB on disk)."""
    write_run(path)
    with h5py.File(path, "r+") as f:
        g = f["runs/r1"]
        attrs = dict(g["samples"].attrs)
        del g["samples"]
        g.create_dataset("samples", shape=(10**11, 2), dtype="f8", chunks=(4096, 2)).attrs.update(attrs)


DEEP_TOML = "deep = " + "[" * 100_000 + "]" * 100_000 + "\n"
DEEP_INLINE = "deep = " + "{a = " * 100_000 + "1" + "}" * 100_000 + "\n"
LONG_INT = "big = " + "9" * 5001 + "\n"


def big_rig(links: int) -> str:
    """A clamped chain of ``links`` straight links (the seed-003 section), one sensor at the tip."""
    head = RIG[:RIG.index("[[link]]")]
    parts = [head] + [f'[[link]]\nname = "l{i}"\nlength_m = 0.5\nmaterial = "aluminium"\n'
                      'section = { shape = "square_tube", outer_m = 0.040, wall_m = 0.0011 }\n'
                      for i in range(links)]
    parts.append('[base]\nsupport = "clamped"\n')
    parts += [f'[[joint]]\nname = "j{i}"\nparent = "l{i - 1}"\nchild = "l{i}"\nangle = "theta_deg"\n'
              'kind = "rigid"\n' for i in range(1, links)]
    parts.append(f'[[sensor]]\nname = "a1"\nat = "l{links - 1}@1.0"\ndirection = "transverse"\n')
    return "\n".join(parts)


@dataclass(frozen=True)
class Row:
    """One malformed input: ``files`` are written into the row's folder, ``{d}`` in ``args`` is it."""

    name: str
    args: tuple[str, ...]
    words: tuple[str, ...]
    files: dict = field(default_factory=dict)
    code: int = 2


def rig(text: str = RIG) -> dict:
    return {"rig.toml": text}


def row(name: str, args: str, words: str | tuple[str, ...], files: dict | None = None, code: int = 2) -> Row:
    words = (words,) if isinstance(words, str) else words
    return Row(name, tuple(args.split()), words, dict(files or {}), code)


BASE = {"rig.toml": RIG, "modes.csv": MODES, "poses.csv": POSES, "session.toml": SESSION,
        "run.h5": write_run}
PREDICT = "predict {d}/rig.toml --model fe --poses {d}/poses.csv --out {d}/pred.csv"
DIAGNOSE = "diagnose --rig {d}/rig.toml --measured {d}/modes.csv --out {d}/diag"
COMPARE = "compare {d}/modes.csv {d}/modes.csv"
ACQUIRE = "acquire --config {d}/session.toml --out {d}/out.h5 --duration 1"
REPORT = "report {d}/run.h5 --out {d}/report.html"
IDENTIFY = "identify {d}/run.h5 --out {d}/modes-out.csv"
DIAGRAM = "modes-out.diagram.npz"   # the stabilisation diagrams IDENTIFY stores beside its --out
FROM_DIAGRAM = IDENTIFY + " --poles 30 --from-diagram"
MODES_STD_NEGATIVE = "\n".join([MODES.splitlines()[0] + ",freq_std_hz"] + [
    line + (",-0.5" if i == 0 else ",0.1") for i, line in enumerate(MODES.splitlines()[1:])]) + "\n"

ROWS: list[Row] = [
    # -- text files that are not UTF-8, binary files as TOML/CSV/JSON -----------------------------
    row("rig-latin1", PREDICT, ("rig.toml", "line 1", "not UTF-8"), rig(LATIN1_COMMENT + RIG.encode())),
    row("session-latin1", ACQUIRE, ("session.toml", "not UTF-8"),
        {"session.toml": LATIN1_COMMENT + SESSION.encode()}),
    row("modes-latin1", COMPARE, ("modes.csv", "not UTF-8"), {"modes.csv": MODES.encode() + "x,µ\n".encode(
        "latin-1")}),
    row("poses-latin1", PREDICT, ("poses.csv", "line 4", "not UTF-8"),
        {"poses.csv": (POSES + "théta,5\n").encode("latin-1")}),
    row("rig-binary-predict", PREDICT, ("rig.toml", "binary"), rig(BINARY)),
    row("rig-binary-diagnose", DIAGNOSE, ("rig.toml", "binary"), rig(BINARY)),
    row("rig-binary-demo", "demo --rig {d}/rig.toml --out {d}/demo", ("rig.toml", "binary"), rig(BINARY)),
    row("rig-binary-report", "report --measured {d}/modes.csv --rig {d}/rig.toml --out {d}/r.html",
        ("rig.toml", "binary"), rig(BINARY)),
    row("rig-binary-sim", "sim serve --protocol serial --rig {d}/rig.toml --duration 1",
        ("rig.toml", "binary"), rig(BINARY)),
    row("session-binary", ACQUIRE, ("session.toml", "binary"), {"session.toml": BINARY}),
    row("modes-binary-compare", COMPARE, ("modes.csv", "binary"), {"modes.csv": BINARY}),
    row("modes-binary-diagnose", DIAGNOSE, ("modes.csv", "binary"), {"modes.csv": BINARY}),
    row("modes-binary-report", "report --measured {d}/modes.csv --out {d}/r.html", ("modes.csv", "binary"),
        {"modes.csv": BINARY}),
    row("poses-binary", PREDICT, ("poses.csv", "binary"), {"poses.csv": BINARY}),
    row("diagnosis-binary", "report --diagnosis {d}/d.json --out {d}/r.html", ("d.json", "binary"),
        {"d.json": BINARY}),
    row("diagnosis-latin1", "report --diagnosis {d}/d.json --out {d}/r.html", ("d.json", "not UTF-8"),
        {"d.json": '{"baseline": "µ"}'.encode("latin-1")}),
    row("diagnosis-not-json", "report --diagnosis {d}/d.json --out {d}/r.html", ("d.json", "JSON"),
        {"d.json": "{baseline"}),
    # -- empty / ragged CSV, empty config cell ----------------------------------------------------
    row("modes-empty-compare", COMPARE, ("modes.csv", "empty"), {"modes.csv": ""}),
    row("modes-empty-diagnose", DIAGNOSE, ("modes.csv", "empty"), {"modes.csv": "\n\n"}),
    row("pred-empty-report", "report --pred {d}/p.csv --out {d}/r.html", ("p.csv", "empty"), {"p.csv": ""}),
    row("poses-empty", PREDICT, ("poses.csv", "empty"), {"poses.csv": ""}),
    row("poses-header-only", PREDICT, ("poses.csv", "no configurations"), {"poses.csv": "config\n"}),
    row("modes-ragged-long", COMPARE, ("modes.csv", "line 3", "6 fields", "header has 5"),
        {"modes.csv": MODES.replace("theta0,2,92.2,experiment,0", "theta0,2,92.2,experiment,0,7")}),
    row("modes-ragged-short", COMPARE, ("modes.csv", "line 3", "4 fields"),
        {"modes.csv": MODES.replace("theta0,2,92.2,experiment,0", "theta0,2,92.2,experiment")}),
    row("poses-ragged", PREDICT, ("poses.csv", "line 4", "1 fields"), {"poses.csv": POSES + "theta90\n"}),
    row("modes-empty-config", COMPARE, ("modes.csv", "line 2", "empty 'config'"),
        {"modes.csv": MODES.replace("theta0,1,25.5", ",1,25.5")}),
    row("modes-empty-config-diagnose", DIAGNOSE, ("modes.csv", "empty 'config'"),
        {"modes.csv": MODES.replace("theta0,1,25.5", ",1,25.5")}),
    row("poses-empty-config", PREDICT, ("poses.csv", "line 2", "empty 'config'"),
        {"poses.csv": POSES.replace("theta0,0", ",0")}),
    row("modes-duplicate-column", COMPARE, ("modes.csv", "'freq_hz' appears twice"),
        {"modes.csv": MODES.replace("source,", "freq_hz,", 1)}),
    row("modes-missing-freq", COMPARE, ("modes.csv", "freq_hz"),
        {"modes.csv": MODES.replace("freq_hz", "f_hz", 1)}),
    row("modes-freq-text", COMPARE, ("modes.csv", "freq_hz", "not a number"),
        {"modes.csv": MODES.replace("25.5,experiment,0\n", "fast,experiment,0\n", 1)}),
    row("modes-unclosed-quote", COMPARE, ("modes.csv",), {"modes.csv": MODES + '"theta9,1,2,e,0\n'}),
    row("poses-not-number", PREDICT, ("poses.csv", "pose.theta_deg", "not a number"),
        {"poses.csv": POSES.replace("theta60,60", "theta60,sixty")}),
    # -- numbers: durations, rates, ports, session and rig values ---------------------------------
    row("acquire-duration-inf", ACQUIRE.replace("1", "inf"), ("--duration", "inf")),
    row("acquire-duration-nan", ACQUIRE.replace("1", "nan"), ("--duration", "nan")),
    row("acquire-duration-zero", ACQUIRE.replace("1", "0"), ("--duration", "'0'")),
    row("session-baud-negative", ACQUIRE, ("session.toml", "baud", "-5"),
        {"session.toml": SESSION.replace("baud = 3000000", "baud = -5")}),
    row("session-scale-nan", ACQUIRE, ("session.toml", "scale", "nan"),
        {"session.toml": SESSION.replace("scale = 0.30517578125", "scale = nan", 1)}),
    row("session-rate-inf", ACQUIRE, ("session.toml", "sample_rate_hz"),
        {"session.toml": SESSION.replace("sample_rate_hz = 2048.0", "sample_rate_hz = inf")}),
    row("session-level-nan", ACQUIRE, ("session.toml", "level", "nan"),
        {"session.toml": SESSION.replace("level = 5.0", "level = nan")}),
    row("session-modbus-port", ACQUIRE, ("session.toml", "port", "99999"),
        {"session.toml": MODBUS_SESSION.replace('port = "@simulator"', "port = 99999")}),
    row("session-pose-nan", ACQUIRE, ("session.toml", "pose.theta_deg", "nan"),
        {"session.toml": SESSION.replace("theta_deg = 30.0", "theta_deg = nan")}),
    row("sim-port", "sim serve --protocol modbus --port 99999 --duration 1", ("--port", "99999")),
    row("sim-rate-nan", "sim serve --protocol serial --rate nan --duration 1", ("--rate", "nan")),
    row("sim-duration-inf", "sim serve --protocol serial --duration inf", ("--duration", "inf")),
    row("sim-scans-zero", "sim serve --protocol serial --scans-per-frame 0 --duration 1",
        ("--scans-per-frame", "'0'")),
    row("rig-outer-huge", PREDICT, ("rig.toml", "link[0].section", "1e+300"),
        rig(RIG.replace("outer_m = 0.040, wall_m = 0.0011 }", "outer_m = 1e300, wall_m = 0.0011 }", 1))),
    row("rig-material-number", PREDICT, ("rig.toml", "link[0].material"),
        rig(RIG.replace('material = "aluminium"', "material = 5", 1))),
    row("rig-base-string", PREDICT, ("rig.toml", "base", "'x'"),
        rig(RIG.replace('[base]\nsupport = "clamped"\n', "").replace(
            'name = "seed003-two-link"', 'name = "seed003-two-link"\nbase = "x"'))),
    row("rig-elements-huge", PREDICT, ("rig.toml", "link[0].elements", "2000000000"),
        rig(RIG.replace('length_m = 0.60\n', "length_m = 0.60\nelements = 2000000000\n"))),
    row("rig-elements-float", PREDICT, ("rig.toml", "link[0].elements"),
        rig(RIG.replace('length_m = 0.60\n', "length_m = 0.60\nelements = 2e9\n"))),
    row("rig-length-nan", PREDICT, ("rig.toml", "link[0].length_m", "nan"),
        rig(RIG.replace("length_m = 0.60", "length_m = nan"))),
    row("rig-E-inf", PREDICT, ("rig.toml", "E_Pa", "inf"), rig(RIG.replace("E_Pa = 75e9", "E_Pa = inf"))),
    row("rig-angle-number", PREDICT, ("rig.toml", "joint[0].angle"),
        rig(RIG.replace('angle = "theta_deg"', "angle = 5"))),
    row("rig-angle-deg-text", PREDICT, ("rig.toml", "joint[0].angle_deg"),
        rig(RIG.replace('angle = "theta_deg"', 'angle_deg = "x"'))),
    row("rig-link-table", PREDICT, ("rig.toml", "link"), rig(RIG.replace("[[link]]", "[link]", 1).replace(
        "[[link]]", "[link2]"))),
    row("rig-not-toml", PREDICT, ("rig.toml", "not valid TOML", "line"), rig(RIG + "\nname = = 3\n")),
    row("rig-joint-not-table", PREDICT, ("rig.toml", "joint"),
        rig(RIG.replace("[[joint]]\nname", "joint = 3\n[[jnt]]\nname"))),
    # -- options ------------------------------------------------------------------------------------
    row("predict-modes-zero", PREDICT + " --modes 0", "--modes"),
    row("predict-elements-zero", PREDICT + " --elements 0", "--elements"),
    row("predict-elements-huge", PREDICT + " --elements 2000000000", ("--elements", "2000000000")),
    row("predict-masses-zero", PREDICT.replace("fe", "lumped-mass") + " --masses-per-link 0",
        "--masses-per-link"),
    row("identify-max-order-0", IDENTIFY + " --max-order 0", ("--max-order", "'0'")),
    row("identify-max-order-1", IDENTIFY + " --max-order 1", ("--max-order", "'1'")),
    row("identify-fmin-nan", IDENTIFY + " --fmin nan", ("--fmin", "nan")),
    row("identify-fmin-above-fmax", IDENTIFY + " --fmin 300 --fmax 100", ("--fmin", "--fmax")),
    row("identify-fmax-negative", IDENTIFY + " --fmax -5", ("--fmax", "-5")),
    row("identify-mpc-min", IDENTIFY + " --mpc-min 2", ("--mpc-min", "'2'")),
    row("identify-poles-text", IDENTIFY + " --poles abc", ("--poles", "abc")),
    row("identify-decay-nan", IDENTIFY + " --exp-window-decay nan", ("--exp-window-decay", "nan")),
    row("frf-nfft-zero", "frf {d}/run.h5 --nfft 0", ("--nfft", "'0'")),
    row("frf-nfft-huge", "frf {d}/run.h5 --nfft 1048576", ("run.h5:", "nfft", "1048576")),
    row("frf-overlap-one", "frf {d}/run.h5 --overlap 1", ("--overlap", "'1'")),
    row("frf-overlap-nan", "frf {d}/run.h5 --overlap nan", ("--overlap", "nan")),
    row("frf-workers-negative", "frf {d}/run.h5 --workers -1", ("--workers", "-1")),
    row("frf-window-unknown", "frf {d}/run.h5 --window bogus", ("window", "bogus")),
    row("compare-min-mac-nan", COMPARE + " --min-mac nan", ("--min-mac", "nan")),
    row("diagnose-scatter-nan", DIAGNOSE + " --scatter nan", ("--scatter", "nan")),
    row("diagnose-effects-unknown", DIAGNOSE + " --effects bogus", ("bogus",)),
    row("diagnose-holdout-unknown", DIAGNOSE + " --holdout theta999", ("theta999",)),
    row("diagnose-selftest-zero", "diagnose --selftest 0", ("--selftest",)),
    row("sim-corrupt-nan", "sim serve --protocol serial --corrupt-rate nan --duration 1",
        ("--corrupt-rate", "nan")),
    row("sim-pose-bad", "sim serve --protocol serial --pose theta_deg --duration 1", ("--pose",)),
    # -- HDF5 run files -----------------------------------------------------------------------------
    row("run-truncated-identify", IDENTIFY, ("run.h5", "truncated")),
    row("run-truncated-frf", "frf {d}/run.h5", ("run.h5", "truncated")),
    row("run-truncated-report", REPORT, ("run.h5", "truncated")),
    row("run-truncated-acquire", ACQUIRE.replace("out.h5", "run.h5"), ("run.h5", "truncated")),
    row("run-truncated-live", IDENTIFY, ("run.h5", "truncated")),
    row("run-foreign-hdf5", IDENTIFY, ("run.h5", "no runs")),
    row("run-runs-dataset", "frf {d}/run.h5", ("run.h5", "/runs")),
    row("run-no-rate-identify", IDENTIFY, ("run.h5", "sample_rate_hz")),
    row("run-no-rate-frf", "frf {d}/run.h5", ("run.h5", "sample_rate_hz")),
    row("run-no-rate-report", REPORT, ("run.h5", "sample_rate_hz")),
    row("run-rate-text", IDENTIFY, ("run.h5", "sample_rate_hz", "fast")),
    row("run-rate-negative", "frf {d}/run.h5", ("run.h5", "sample_rate_hz", "-1")),
    row("run-pose-not-json", IDENTIFY, ("run.h5", "pose", "JSON")),
    row("run-excitation-unknown", "frf {d}/run.h5", ("run.h5", "excitation", "hammer")),
    row("run-no-start-time", REPORT, ("run.h5", "start_time")),
    row("run-samples-text", IDENTIFY, ("run.h5", "samples")),
    row("run-samples-1d", "frf {d}/run.h5", ("run.h5", "samples")),
    row("run-channels-floats", IDENTIFY, ("run.h5", "channels")),
    row("run-no-events", REPORT, ("run.h5", "events")),
    row("run-channel-kind", IDENTIFY, ("run.h5", "kind", "hammer")),
    row("run-missing-run", "identify {d}/run.h5 --run nope --out {d}/m.csv", ("run.h5", "nope")),
    row("run-text-file", IDENTIFY, ("run.h5",), {"run.h5": "not a run\n"}),
    row("run-empty-file", "frf {d}/run.h5", ("run.h5",), {"run.h5": b""}),
    row("acquire-out-not-hdf5", ACQUIRE.replace("out.h5", "notes.txt"), ("notes.txt", "not an HDF5 file"),
        {"notes.txt": "my notes\n"}),
    row("frf-out-not-hdf5", "frf {d}/run.h5 --out {d}/notes.txt", ("notes.txt", "not an HDF5 file"),
        {"notes.txt": "my notes\n"}),
    # -- output paths -------------------------------------------------------------------------------
    row("out-demo-no-dir", "demo --out {d}/file.txt/demo", ("file.txt",), {"file.txt": "x"}),
    row("out-demo-is-file", "demo --out {d}/file.txt", ("file.txt", "not a directory"), {"file.txt": "x"}),
    row("out-predict-missing-dir", PREDICT.replace("{d}/pred.csv", "{d}/no/such/pred.csv"),
        ("pred.csv", "does not exist")),
    row("out-compare-missing-dir", COMPARE + " --out {d}/no/table.md", ("table.md", "does not exist")),
    row("out-diagnose-is-file", DIAGNOSE.replace("{d}/diag", "{d}/file.txt"), ("file.txt", "not a directory"),
        {"file.txt": "x"}),
    row("out-diagnose-proc", DIAGNOSE.replace("{d}/diag", "/proc/flexmodal-diag"), ("/proc/flexmodal-diag",)),
    row("out-identify-proc", IDENTIFY.replace("{d}/modes-out.csv", "/proc/modes.csv"), ("/proc/modes.csv",)),
    row("out-identify-dir", IDENTIFY.replace("{d}/modes-out.csv", "{d}"), ("is a directory",)),
    row("out-identify-uff", IDENTIFY + " --uff {d}/no/modes.uff", ("modes.uff", "does not exist")),
    row("out-report-proc", REPORT.replace("{d}/report.html", "/proc/report.html"), ("/proc/report.html",)),
    row("out-frf-missing-dir", "frf {d}/run.h5 --out {d}/no/frf.h5", ("frf.h5", "does not exist")),
    row("out-acquire-missing-dir", ACQUIRE.replace("{d}/out.h5", "{d}/no/out.h5"),
        ("out.h5", "does not exist")),
    # -- UFF, mathtext, missing inputs --------------------------------------------------------------
    row("uff-lengths", "identify {d}/f.uff --out {d}/m.csv", ("f.uff", "num_pts = 101")),
    row("uff-flat", "identify {d}/f.uff --out {d}/m.csv", ("f.uff:", "no stable poles")),
    row("uff-garbage", "identify {d}/f.uff --out {d}/m.csv", ("f.uff",), {"f.uff": BINARY}),
    row("uff-empty", "identify {d}/f.uff --out {d}/m.csv", ("f.uff",), {"f.uff": ""}),
    row("report-mathtext-channel", REPORT, code=0, words=()),
    row("missing-rig", "predict {d}/nope.toml --model fe --poses {d}/poses.csv --out {d}/p.csv", "nope.toml"),
    row("missing-run", "frf {d}/nope.h5", "nope.h5"),
    row("missing-session", "acquire --config {d}/nope.toml --out {d}/o.h5", "nope.toml"),
    row("rig-is-dir", "predict {d} --model fe --poses {d}/poses.csv --out {d}/p.csv", "directory"),
    # -- issue 24: outputs never destroy inputs ------------------------------------------------------
    row("identify-out-is-input", "identify {d}/run.h5 --out {d}/run.h5", ("run.h5", "input")),
    row("identify-out-link-to-input", "identify {d}/run.h5 --out {d}/l.csv", ("l.csv", "input"),
        {"l.csv": link_to("run.h5")}),
    row("identify-out-hdf5", "identify {d}/run.h5 --out {d}/other.h5", ("other.h5", "HDF5 file"),
        {"other.h5": h5_file}),
    row("identify-out-fifo", "identify {d}/run.h5 --out {d}/fifo", ("fifo", "FIFO"), {"fifo": fifo}),
    row("identify-out-dev-null", "identify {d}/run.h5 --out /dev/null", ("/dev/null", "device")),
    row("identify-out-dev-stdout", "identify {d}/run.h5 --out /dev/stdout", ("/dev/stdout", "device")),
    row("identify-uff-is-out", IDENTIFY + " --uff {d}/modes-out.csv", ("modes-out.csv", "output")),
    row("identify-uff-is-input", IDENTIFY + " --uff {d}/run.h5", ("run.h5",)),
    row("identify-uff-fifo", IDENTIFY + " --uff {d}/fifo", ("fifo", "FIFO"), {"fifo": fifo}),
    row("identify-synthesis-is-input", "identify {d}/run.h5 --out {d}/m.csv", ("m.synthesis.csv", "HDF5"),
        {"m.synthesis.csv": h5_file}),
    row("compare-out-run", COMPARE + " --out {d}/run.h5", ("run.h5", "HDF5 file")),
    row("compare-out-measured", COMPARE + " --out {d}/modes.csv", ("modes.csv", "input")),
    row("compare-out-hard-link", COMPARE + " --out {d}/h.csv", ("h.csv", "input"),
        {"h.csv": hard_link_to("modes.csv")}),
    row("compare-out-fifo", COMPARE + " --out {d}/fifo", ("fifo", "FIFO"), {"fifo": fifo}),
    row("compare-out-dev-full", COMPARE + " --out /dev/full", ("/dev/full", "device")),
    row("compare-out-dir", COMPARE + " --out {d}", ("is a directory",)),
    row("predict-out-run", PREDICT.replace("{d}/pred.csv", "{d}/run.h5"), ("run.h5", "HDF5 file")),
    row("predict-out-rig", PREDICT.replace("{d}/pred.csv", "{d}/rig.toml"), ("rig.toml", "input")),
    row("predict-out-poses-link", PREDICT.replace("{d}/pred.csv", "{d}/l.csv"), ("l.csv", "input"),
        {"l.csv": link_to("poses.csv")}),
    row("predict-out-fifo", PREDICT.replace("{d}/pred.csv", "{d}/fifo"), ("fifo", "FIFO"), {"fifo": fifo}),
    row("report-out-run", "report {d}/run.h5 --out {d}/run.h5", ("run.h5", "input")),
    row("report-out-measured", "report --measured {d}/modes.csv --out {d}/modes.csv", ("modes.csv", "input")),
    row("report-out-fifo", "report --measured {d}/modes.csv --out {d}/fifo", ("fifo", "FIFO"),
        {"fifo": fifo}),
    row("report-out-dev-null", "report --measured {d}/modes.csv --out /dev/null", ("/dev/null", "device")),
    row("diagnose-out-json-is-input", DIAGNOSE, ("diagnosis.json", "input"),
        {"diag/diagnosis.json": link_to("../modes.csv")}),
    row("diagnose-out-json-fifo", DIAGNOSE, ("diagnosis.json", "FIFO"), {"diag/diagnosis.json": fifo}),
    row("diagnose-out-html-hdf5", DIAGNOSE, ("diagnosis.html", "HDF5"), {"diag/diagnosis.html": h5_file}),
    row("acquire-out-fifo", ACQUIRE.replace("{d}/out.h5", "{d}/fifo"), ("fifo", "FIFO"), {"fifo": fifo}),
    row("acquire-out-dev-null", ACQUIRE.replace("{d}/out.h5", "/dev/null"), ("/dev/null", "device")),
    row("acquire-out-session", ACQUIRE.replace("{d}/out.h5", "{d}/session.toml"),
        ("session.toml", "not an HDF5 file")),
    row("acquire-out-dir", ACQUIRE.replace("{d}/out.h5", "{d}"), ("is a directory",)),
    row("frf-out-fifo", "frf {d}/run.h5 --out {d}/fifo", ("fifo", "FIFO"), {"fifo": fifo}),
    row("frf-out-dev-null", "frf {d}/run.h5 --out /dev/null", ("/dev/null", "device")),
    row("sim-fault-log-fifo", "sim serve --protocol serial --duration 1 --fault-log {d}/fifo",
        ("fifo", "FIFO"), {"fifo": fifo}),
    row("sim-fault-log-run", "sim serve --protocol serial --duration 1 --fault-log {d}/run.h5",
        ("run.h5", "HDF5 file")),
    row("sim-fault-log-rig", "sim serve --protocol serial --rig {d}/rig.toml --duration 1 --fault-log "
        "{d}/rig.toml", ("rig.toml", "input")),
    row("demo-out-fifo", "demo --out {d}/fifo", ("fifo", "not a directory"), {"fifo": fifo}),
    # -- issue 24: inputs that would block or never end: FIFOs, devices, folders ----------------------
    row("compare-measured-fifo", "compare {d}/fifo {d}/modes.csv", ("fifo", "FIFO"), {"fifo": fifo}),
    row("compare-predicted-dev-zero", "compare {d}/modes.csv /dev/zero", ("/dev/zero", "character device")),
    row("compare-measured-dir", "compare {d} {d}/modes.csv", ("is a directory",)),
    row("predict-rig-fifo", PREDICT.replace("{d}/rig.toml", "{d}/fifo"), ("fifo", "FIFO"), {"fifo": fifo}),
    row("predict-rig-dev-zero", PREDICT.replace("{d}/rig.toml", "/dev/zero"), ("/dev/zero", "device")),
    row("predict-poses-fifo", PREDICT.replace("{d}/poses.csv", "{d}/fifo"), ("fifo", "FIFO"), {"fifo": fifo}),
    row("predict-poses-dev-zero", PREDICT.replace("{d}/poses.csv", "/dev/zero"), ("/dev/zero", "device")),
    row("acquire-session-fifo", ACQUIRE.replace("{d}/session.toml", "{d}/fifo"), ("fifo", "FIFO"),
        {"fifo": fifo}),
    row("acquire-session-dev-zero", ACQUIRE.replace("{d}/session.toml", "/dev/zero"),
        ("/dev/zero", "device")),
    row("identify-input-fifo", "identify {d}/fifo --out {d}/m.csv", ("fifo", "FIFO"), {"fifo": fifo}),
    row("identify-input-dev-zero", "identify /dev/zero --out {d}/m.csv", ("/dev/zero", "device")),
    row("frf-run-fifo", "frf {d}/fifo", ("fifo", "FIFO"), {"fifo": fifo}),
    row("frf-run-dev-zero", "frf /dev/zero", ("/dev/zero", "device")),
    row("report-run-fifo", "report {d}/fifo --out {d}/r.html", ("fifo", "FIFO"), {"fifo": fifo}),
    row("report-diagnosis-fifo", "report --diagnosis {d}/fifo --out {d}/r.html", ("fifo", "FIFO"),
        {"fifo": fifo}),
    row("report-diagnosis-dev-zero", "report --diagnosis /dev/zero --out {d}/r.html",
        ("/dev/zero", "device")),
    row("report-rig-fifo", "report --measured {d}/modes.csv --rig {d}/fifo --out {d}/r.html",
        ("fifo", "FIFO"), {"fifo": fifo}),
    row("report-pred-dir", "report --pred {d} --out {d}/r.html", ("is a directory",)),
    row("diagnose-rig-fifo", DIAGNOSE.replace("{d}/rig.toml", "{d}/fifo"), ("fifo", "FIFO"), {"fifo": fifo}),
    row("diagnose-measured-dev-zero", DIAGNOSE.replace("{d}/modes.csv", "/dev/zero"),
        ("/dev/zero", "device")),
    row("sim-rig-fifo", "sim serve --protocol serial --rig {d}/fifo --duration 1", ("fifo", "FIFO"),
        {"fifo": fifo}),
    row("demo-rig-dev-zero", "demo --rig /dev/zero --out {d}/demo", ("/dev/zero", "device")),
    row("modes-huge", COMPARE, ("modes.csv", "larger than"), {"modes.csv": sparse(MODES, 300 << 20)}),
    # -- issue 24: parser depth and size extremes ----------------------------------------------------
    row("rig-deep-array", PREDICT, ("rig.toml", "nested"), rig(RIG + DEEP_TOML)),
    row("rig-deep-inline-table", PREDICT, ("rig.toml", "nested"), rig(RIG + DEEP_INLINE)),
    row("rig-5001-digits", PREDICT, ("rig.toml", "digits"), rig(RIG + LONG_INT)),
    row("session-deep-array", ACQUIRE, ("session.toml", "nested"), {"session.toml": SESSION + DEEP_TOML}),
    row("session-5001-digits", ACQUIRE, ("session.toml", "digits"), {"session.toml": SESSION + LONG_INT}),
    row("diagnosis-deep", "report --diagnosis {d}/d.json --out {d}/r.html", ("d.json", "nested"),
        {"d.json": "[" * 100_000 + "]" * 100_000}),
    row("diagnosis-deep-object", "report --diagnosis {d}/d.json --out {d}/r.html", ("d.json", "nested"),
        {"d.json": '{"a": ' * 100_000 + "1" + "}" * 100_000}),
    row("diagnosis-5001-digits", "report --diagnosis {d}/d.json --out {d}/r.html", ("d.json", "digits"),
        {"d.json": "9" * 5001}),
    row("run-pose-deep", IDENTIFY, ("run.h5", "pose")),
    row("run-pose-5001-digits", "frf {d}/run.h5", ("run.h5", "pose")),
    row("frf-provenance-deep", IDENTIFY, ("run.h5", "provenance", "nested")),
    row("modes-long-field", COMPARE, ("modes.csv",), {"modes.csv": MODES + "x" * 200_000 + ",1,2,e,0\n"}),
    # -- issue 24: foreign and damaged HDF5 ----------------------------------------------------------
    row("run-link-loop-identify", IDENTIFY, ("run.h5", "looping link")),
    row("run-link-loop-frf", "frf {d}/run.h5", ("run.h5", "looping link")),
    row("run-link-loop-report", REPORT, ("run.h5", "looping link")),
    row("run-external-link", IDENTIFY, ("run.h5", "external link", "not followed")),
    row("samples-external-link", "frf {d}/run.h5", ("run.h5", "'samples'", "external link")),
    row("samples-dangling-link", REPORT, ("run.h5", "'samples'", "dangling")),
    row("samples-damaged-identify", IDENTIFY, ("run.h5", "r1", "cannot read")),
    row("samples-damaged-frf", "frf {d}/run.h5 --workers 0", ("run.h5", "r1", "cannot read")),
    row("samples-damaged-report", "report {d}/run.h5 --out {d}/r.html --quiet", ("run.h5", "cannot read")),
    row("samples-filter-identify", IDENTIFY, ("run.h5", "filter 32004", "not installed")),
    row("samples-filter-frf", "frf {d}/run.h5", ("run.h5", "filter 32004", "not installed")),
    row("run-duplicate-channel", IDENTIFY, ("run.h5", "'F' appears twice")),
    row("run-duplicate-channel-frf", "frf {d}/run.h5", ("run.h5", "'F' appears twice")),
    row("run-pose-nan", IDENTIFY, ("run.h5", "theta_deg", "not a finite number")),
    row("run-pose-text", "frf {d}/run.h5", ("run.h5", "theta_deg", "not a finite number")),
    row("frf-group-dataset", IDENTIFY, ("run.h5", "frf group", "not a group")),
    row("frf-group-dataset-report", REPORT, ("run.h5", "frf group", "not a group")),
    row("frf-nfft-text", IDENTIFY, ("run.h5", "nfft", "'big'")),
    row("frf-H-1d", IDENTIFY, ("run.h5", "'H'", "shape (5,)")),
    row("frf-freq-nan", REPORT, ("run.h5", "freq_hz", "finite")),
    row("frf-coherence-shape", IDENTIFY, ("run.h5", "coherence")),
    row("frf-outputs-not-list", IDENTIFY, ("run.h5", "outputs")),
    row("frf-H-external", IDENTIFY, ("run.h5", "'H'", "external link")),
    row("frf-no-H", IDENTIFY, ("run.h5", "lacks", "'H'")),
    # -- issue 24: impossible values refused ---------------------------------------------------------
    row("identify-poles-nan", IDENTIFY + " --poles nan", ("--poles", "nan")),
    row("identify-poles-inf", IDENTIFY + " --poles 50,inf", ("--poles", "inf")),
    row("identify-poles-negative", IDENTIFY + " --poles=-5", ("--poles", "-5")),
    row("identify-fmax-above-nyquist", IDENTIFY + " --method peak --fmax 5000",
        ("above", "Nyquist", "clipped"), code=0),
    row("frf-scheduler-not-url", "frf {d}/run.h5 --scheduler not-a-url", ("--scheduler", "not-a-url")),
    row("modes-damping-percent", COMPARE, ("modes.csv", "damping_ratio = 1.5", "0.015"),
        {"modes.csv": "config,mode,freq_hz,damping_ratio\nA,1,10,1.5\n"}),
    row("modes-damping-text", COMPARE, ("modes.csv", "damping_ratio", "'low'"),
        {"modes.csv": "config,mode,freq_hz,damping_ratio\nA,1,10,low\n"}),
    row("modes-shape-inf-compare", COMPARE, ("modes.csv", "shape.a", "infinite"),
        {"modes.csv": "config,mode,freq_hz,shape.a,shape.b\nA,1,10,inf,1\n"}),
    row("modes-shape-inf-diagnose", DIAGNOSE, ("modes.csv", "shape.a1", "infinite"),
        {"modes.csv": "config,mode,freq_hz,pose.theta_deg,shape.a1,shape.a2\nt0,1,20,0,-inf,1\n"}),
    row("modes-pose-text", COMPARE, ("modes.csv", "pose.theta_deg", "'sixty'"),
        {"modes.csv": MODES.replace("experiment,0\n", "experiment,sixty\n", 1)}),
    row("modes-pose-inf-diagnose", DIAGNOSE, ("modes.csv", "pose.theta_deg", "inf"),
        {"modes.csv": MODES.replace("experiment,0\n", "experiment,inf\n", 1)}),
    row("poses-inf", PREDICT, ("poses.csv", "pose.theta_deg", "inf"),
        {"poses.csv": POSES.replace("60,60", "60,inf")}),
    row("poses-no-prefix", PREDICT, ("poses.csv", "pose.theta_deg"),
        {"poses.csv": POSES.replace("pose.theta_deg", "theta_deg")}),
    row("poses-semicolons", PREDICT, ("poses.csv", "semicolons", "decimal"),
        {"poses.csv": "config;pose.theta_deg\ntheta0;0,5\n"}),
    row("modes-semicolons", COMPARE, ("modes.csv", "semicolons", "decimal"),
        {"modes.csv": MODES.replace(",", ";")}),
    row("modes-tabs", COMPARE, ("modes.csv", "tabs"), {"modes.csv": MODES.replace(",", "\t")}),
    row("session-layout-huge", ACQUIRE, ("session.toml", "999999999999 values"),
        {"session.toml": MCU.replace('layout = "<12h"', 'layout = "<999999999999h"')}),
    row("session-window-tiny", ACQUIRE, ("session.toml", "window_s", "5e-324", "subnormal"),
        {"session.toml": MCU.replace("window_s = 1.0", "window_s = 5e-324")}),
    row("session-window-1e-300", ACQUIRE, ("session.toml", "window_s", "samples"),
        {"session.toml": MCU.replace("window_s = 1.0", "window_s = 1e-300")}),
    row("session-serial-bogus-url", ACQUIRE, ("session.toml", "bogus://"),
        {"session.toml": MCU.replace('port = "loop://" ', 'port = "bogus://x" ')}),
    row("session-dbc-signal-missing", ACQUIRE, ("session.toml", "'zz'", "canmod"),
        {"session.toml": CAN.replace('source = "a0"', 'source = "zz"'), "can-module.dbc": DBC}),
    row("session-duplicate-channel", ACQUIRE, ("session.toml", "'F'", "twice"),
        {"session.toml": SESSION.replace('name = "a1"', 'name = "F"')}),
    row("session-pose-inf", ACQUIRE, ("session.toml", "pose.theta_deg", "inf"),
        {"session.toml": SESSION.replace("theta_deg = 30.0", "theta_deg = inf")}),
    row("rig-1000-links-fe", PREDICT, ("rig.toml", "degrees of freedom", "GiB"), rig(big_rig(1000))),
    row("rig-1000-links-lumped", PREDICT.replace("fe", "lumped-mass"), ("rig.toml", "coordinates"),
        rig(big_rig(1000))),
    row("acquire-run-id-dot", ACQUIRE + " --run-id .", ("--run-id", "'.'")),
    row("acquire-run-id-slash", ACQUIRE + " --run-id a/b", ("--run-id", "'a/b'")),
    row("acquire-can-cannot-open", ACQUIRE.replace("{d}/session.toml", "{d}/can.toml"),
        ("can9", "cannot open"),
        {"can.toml": CAN.replace('channel = "can0"', 'channel = "can9"'), "can-module.dbc": DBC}),
    row("session-dbc-fifo", ACQUIRE, ("session.toml", "FIFO", "dbc file"),
        {"session.toml": CAN.replace('dbc = "can-module.dbc"', 'dbc = "fifo"'), "fifo": fifo}),
    row("demo-table-fifo", "demo --out {d}/demo", ("modes.csv", "FIFO"), {"demo/modes.csv": fifo}),
    row("demo-report-is-rig", "demo --rig {d}/demo/report.html --out {d}/demo", ("report.html", "input"),
        {"demo/report.html": RIG}),
    row("report-pdf-is-out", "report --measured {d}/modes.csv --out {d}/r.pdf --pdf", ("r.pdf", "output")),
    # -- session 3: the stabilisation diagram stored beside --out (MODES.diagram.npz) -----------------
    row("diagram-user-npz", IDENTIFY, (DIAGRAM, "not a stabilisation diagram"),
        {DIAGRAM: user_npz}),
    row("diagram-user-text", IDENTIFY + " --poles 30", (DIAGRAM, "not a stabilisation diagram"),
        {DIAGRAM: "my notes\n"}),
    row("diagram-fifo", FROM_DIAGRAM, (DIAGRAM, "FIFO"),
        {DIAGRAM: fifo}),
    row("diagram-link-to-run", IDENTIFY, (DIAGRAM, "input", "run.h5"),
        {DIAGRAM: link_to("run.h5")}),
    row("diagram-hdf5", IDENTIFY, (DIAGRAM, "HDF5"), {DIAGRAM: h5_file}),
    row("diagram-dev-zero", FROM_DIAGRAM, (DIAGRAM, "/dev/zero"),
        {DIAGRAM: lambda p: p.symlink_to("/dev/zero")}),
    row("diagram-directory", IDENTIFY, (DIAGRAM, "directory"),
        {"modes-out.diagram.npz/keep.txt": "x"}),
    row("diagram-missing", FROM_DIAGRAM, (DIAGRAM, "no stored")),
    row("diagram-without-poles", IDENTIFY + " --from-diagram", ("--poles",)),
    row("diagram-other-input", FROM_DIAGRAM, (DIAGRAM, "matches"),
        {DIAGRAM: stored_diagram()}),
    row("diagram-freq-nan", FROM_DIAGRAM, (DIAGRAM, "freq_hz", "nan"),
        {DIAGRAM: stored_diagram(lambda a: a["d0.freq_hz"].__setitem__(1, np.nan))}),
    row("diagram-damping-inf", FROM_DIAGRAM, (DIAGRAM, "damping"),
        {DIAGRAM: stored_diagram(lambda a: a["d0.damping_ratio"].__setitem__(0, np.inf))}),
    row("diagram-previous-out-of-range", FROM_DIAGRAM,
        (DIAGRAM, "previous"),
        {DIAGRAM: stored_diagram(lambda a: a["d0.previous"].__setitem__(2, 10**6))}),
    row("diagram-wrong-kind", FROM_DIAGRAM, (DIAGRAM, "order"),
        {DIAGRAM: stored_diagram(lambda a: a.__setitem__("d0.order", np.array(list("abc"))))}),
    row("diagram-declares-73-TiB", FROM_DIAGRAM, (DIAGRAM, "declares"),
        {DIAGRAM: diagram_declaring((10**13,))}),
    row("diagram-unpacks-huge", FROM_DIAGRAM, (DIAGRAM, "unpack"),
        {DIAGRAM: stored_diagram(lambda a: a.__setitem__("junk", np.zeros(40_000_000)))}),
    row("diagram-pickled", FROM_DIAGRAM, (DIAGRAM, "pickled"),
        {DIAGRAM: stored_diagram(lambda a: a.__setitem__("d0.config", np.array([{}], object)))}),
    # -- session 3: uncertainty columns of a modal table ----------------------------------------------
    row("modes-freq-std-text", COMPARE, ("modes.csv", "freq_std_hz", "'wide'"),
        {"modes.csv": "config,mode,freq_hz,freq_std_hz\nA,1,10,wide\n"}),
    row("modes-freq-std-negative", COMPARE, ("modes.csv", "freq_std_hz = -0.1", "negative"),
        {"modes.csv": "config,mode,freq_hz,freq_std_hz\nA,1,10,-0.1\n"}),
    row("modes-damping-std-inf-report", "report --measured {d}/modes.csv --out {d}/r.html",
        ("modes.csv", "damping_std", "inf"),
        {"modes.csv": "config,mode,freq_hz,damping_ratio,damping_std\nA,1,10,0.01,inf\n"}),
    row("modes-freq-std-negative-diagnose", DIAGNOSE, ("modes.csv", "freq_std_hz", "negative"),
        {"modes.csv": MODES_STD_NEGATIVE}),
    # -- session 3: report --geometry (a UFF test geometry) -------------------------------------------
    row("geometry-fifo", "report --measured {d}/modes.csv --geometry {d}/g.unv --out {d}/r.html",
        ("g.unv", "FIFO"), {"g.unv": fifo}),
    row("geometry-dev-zero", "report --measured {d}/modes.csv --geometry {d}/g.unv --out {d}/r.html",
        ("g.unv", "device"), {"g.unv": lambda p: p.symlink_to("/dev/zero")}),
    row("geometry-beyond-memory", "report --measured {d}/modes.csv --geometry {d}/g.unv --out {d}/r.html",
        ("g.unv", "too large"), {"g.unv": lambda p: sparse("    -1\n    15\n", _half_the_memory())(p)}),
    row("report-pdf-beside-is-input", "report --measured {d}/modes.csv --out {d}/r.html --pdf",
        ("r.pdf", "input"), {"r.pdf": link_to("modes.csv")}),
    row("report-out-is-geometry", "report --measured {d}/modes.csv --geometry {d}/g.unv --out {d}/g.unv",
        ("g.unv", "input"), {"g.unv": (REPO / "tests/data/uff/massif_geometry.uff").read_bytes()}),
    row("synthesis-user-file", IDENTIFY, ("modes-out.synthesis.csv", "not a FRF synthesis table"),
        {"modes-out.synthesis.csv": "my,own,table\n1,2,3\n"}),
    row("harmonics-user-file", "identify {d}/enc.h5 --track --out {d}/enc.csv",
        ("enc.harmonics.csv", "not a harmonics table"),
        {"enc.h5": encoder_run, "enc.harmonics.csv": "mine\n"}),
    # -- session 3: identify --track options -------------------------------------------------------
    row("track-window-one-sample", "identify {d}/enc.h5 --track --out {d}/map.csv --window 0.001 --hop 0.001",
        ("tracking window", "1 samples"), {"enc.h5": encoder_run}),
    row("track-bin-zero", "identify {d}/enc.h5 --track --out {d}/map.csv --bin 0", ("--bin", "'0'"),
        {"enc.h5": encoder_run}),
    row("track-orders-inf", "identify {d}/enc.h5 --track --out {d}/map.csv --orders 3,1e309",
        ("--orders", "finite"), {"enc.h5": encoder_run}),
    row("track-harmonics-is-input", "identify {d}/enc.h5 --track --out {d}/enc.csv",
        ("enc.harmonics.csv", "input"), {"enc.h5": encoder_run, "enc.harmonics.csv": link_to("enc.h5")}),
    # -- session 3: sweep runs (modal/sweep.py: one segment per sweep) --------------------------------
    row("sweep-constant-force", "frf {d}/run.h5 --workers 0", ("run.h5", "'F'", "constant")),
    row("sweep-nan-force", IDENTIFY, ("run.h5", "'F'", "nan")),
    # -- issue 24: numbers at the ends of the doubles (subnormal, 1e-300, 1e308, -0) ------------------
    row("track-bin-subnormal", "identify {d}/enc.h5 --track --out {d}/map.csv --bin 5e-324",
        ("--bin", "5e-324", "subnormal"), {"enc.h5": encoder_run}),
    row("track-bin-1e-300", "identify {d}/enc.h5 --track --out {d}/map.csv --bin 1e-300", (),
        {"enc.h5": encoder_run}, code=0),   # each window its own bin, named by its pose: a correct map
    row("track-hop-1e-300", "identify {d}/enc.h5 --track --out {d}/map.csv --hop 1e-300",
        ("--hop", "1e-300", "1/64"), {"enc.h5": encoder_run}),
    row("track-hop-one-sample", "identify {d}/enc.h5 --track --out {d}/map.csv --window 1 --hop 0.001",
        ("--hop", "0.001", "1/64"), {"enc.h5": encoder_run}),
    row("track-hop-1e308", "identify {d}/enc.h5 --track --out {d}/map.csv --hop 1e308",
        ("--hop", "1e308", "<= 1e+09"), {"enc.h5": encoder_run}),
    row("track-window-1e308", "identify {d}/enc.h5 --track --out {d}/map.csv --window 1e308",
        ("--window", "1e308"), {"enc.h5": encoder_run}),
    row("track-window-longer-than-record", "identify {d}/enc.h5 --track --out {d}/map.csv --window 1e6",
        ("tracking window", "1e+06 s", "longer than the record"), {"enc.h5": encoder_run}),
    row("track-max-spread-subnormal", "identify {d}/enc.h5 --track --out {d}/map.csv --max-spread 4e-320",
        ("--max-spread", "4e-320", "subnormal"), {"enc.h5": encoder_run}),
    row("acquire-duration-1e308", ACQUIRE.replace("1", "1e308"), ("--duration", "1e308")),
    row("acquire-duration-subnormal", ACQUIRE.replace("1", "5e-324"),
        ("--duration", "5e-324", "subnormal")),
    row("session-duration-1e300", ACQUIRE.replace(" --duration 1", ""), ("--duration", "1e+300", "samples"),
        {"session.toml": SESSION.replace('excitation = "impact"',
                                         'excitation = "impact"\nduration_s = 1e300')}),
    row("session-level-subnormal", ACQUIRE, ("session.toml", "level", "subnormal"),
        {"session.toml": SESSION.replace("level = 5.0", "level = 5e-324")}),
    row("session-rate-subnormal", ACQUIRE, ("session.toml", "sample_rate_hz", "subnormal"),
        {"session.toml": SESSION.replace("sample_rate_hz = 2048.0", "sample_rate_hz = 1e-320")}),
    row("rig-length-subnormal", PREDICT, ("rig.toml", "link[0].length_m", "subnormal"),
        rig(RIG.replace("length_m = 0.60", "length_m = 5e-324"))),
    row("rig-E-subnormal", PREDICT, ("rig.toml", "E_Pa", "subnormal"),
        rig(RIG.replace("E_Pa = 75e9", "E_Pa = 1e-310"))),
    row("sim-duration-1e308", "sim serve --protocol serial --duration 1e308", ("--duration", "1e308")),
    row("sim-drop-subnormal", "sim serve --protocol serial --drop 5e-324 --duration 1",
        ("--drop", "5e-324", "subnormal")),
    row("frf-overlap-subnormal", "frf {d}/run.h5 --overlap 5e-324", ("--overlap", "5e-324", "subnormal")),
    row("identify-fmin-subnormal", IDENTIFY + " --fmin 5e-324",
        ("--fmin", "5e-324", "subnormal")),
    row("identify-fmax-1e-300", IDENTIFY + " --fmax 1e-300", ("run.h5", "0 frequency lines", "1e-300")),
    row("identify-decay-subnormal", IDENTIFY + " --exp-window-decay 5e-324",
        ("--exp-window-decay", "5e-324")),
    row("identify-need-min-subnormal", IDENTIFY + " --need-min 5e-324", ("--need-min", "5e-324")),
    row("compare-min-mac-subnormal", COMPARE + " --min-mac 5e-324", ("--min-mac", "5e-324", "subnormal")),
    row("diagnose-scatter-1e-300", DIAGNOSE + " --scatter 1e-300",
        ("--scatter", "1e-300", ">= 1e-06")),
    row("diagnose-freq-std-1e-300", DIAGNOSE + " --effects joint_stiffness", (), {"modes.csv": "\n".join(
        [MODES.splitlines()[0] + ",freq_std_hz"] + [line + ",1e-300" for line in MODES.splitlines()[1:]])
        + "\n"}, code=0),   # a freq_std_hz this small is taken as 1 ppm (compare/gap.py MIN_SCATTER_REL);
    # one effect: 1 candidate fitted, not 91 (the floors it meets: tests/test_diagnosis_intervals.py)
    row("report-fmin-nan", "report {d}/run.h5 --out {d}/r.html --fmin nan", ("--fmin", "nan")),
    row("report-oma-fmax-subnormal", "report {d}/run.h5 --out {d}/r.html --oma-fmax 5e-324",
        ("--oma-fmax", "5e-324", "subnormal")),
    row("report-fmax-negative-zero", "report {d}/run.h5 --out {d}/r.html --fmax -0", ("--fmax", "'-0'")),
    # -- issue 24: numbers at the ends of the doubles in a modal table ---------------------------------
    row("modes-freq-1e308-compare", COMPARE, ("modes.csv", "freq_hz", "1e+308", "1e+09"),
        {"modes.csv": MODES.replace("theta0,1,25.5,", "theta0,1,1e308,", 1)}),
    row("modes-freq-1e308-report", "report --measured {d}/modes.csv --out {d}/r.html",
        ("modes.csv", "freq_hz", "1e+308"),
        {"modes.csv": MODES.replace("theta0,1,25.5,", "theta0,1,1e308,", 1)}),
    row("modes-freq-subnormal-diagnose", DIAGNOSE + " --quiet",   # read as 0 Hz
        ("modes.csv", "row 2: freq_hz = 0 is not above 0 Hz"),
        {"modes.csv": MODES.replace("theta0,1,25.5,", "theta0,1,5e-324,", 1)}),
    row("modes-pose-1e308-diagnose", DIAGNOSE, ("modes.csv", "pose.theta_deg", "1e+308"),
        {"modes.csv": MODES.replace("theta0,1,25.5,experiment,0", "theta0,1,25.5,experiment,1e308", 1)}),
    row("modes-mode-huge", COMPARE, ("modes.csv", "mode", "1e+30", "whole number"),
        {"modes.csv": MODES.replace("theta0,1,25.5,", "theta0,1000000000000000000000000000000,25.5,", 1)}),
    row("modes-mode-fraction", COMPARE, ("modes.csv", "mode = 1.5", "whole number"),
        {"modes.csv": MODES.replace("theta0,1,25.5,", "theta0,1.5,25.5,", 1)}),
    row("modes-damping-minus-5", COMPARE, ("modes.csv", "damping_ratio = -5", "-1"),
        {"modes.csv": "config,mode,freq_hz,damping_ratio\nA,1,10,-5\n"}),
    row("modes-shape-1e300", COMPARE, ("modes.csv", "shape.a1", "1e+300"),
        {"modes.csv": "config,mode,freq_hz,shape.a1\nA,1,10,1e300\n"}),
    row("run-samples-never-written-frf", "frf {d}/run.h5 --workers 0",
        ("run.h5", "declares shape", "never written")),
    row("run-samples-never-written-identify", IDENTIFY, ("run.h5", "declares shape", "never written")),
    # -- controls: the unmodified base files work ---------------------------------------------------
    row("control-predict", PREDICT, (), code=0),
    row("control-compare", COMPARE, (), code=0),
    row("control-compare-out-stdout", COMPARE + " --out -", (), code=0),
    row("control-identify-peak", IDENTIFY + " --method peak", (), code=0),
]
RUN_FILES = {
    "run-truncated-identify": truncated_run, "run-truncated-frf": truncated_run,
    "run-truncated-report": truncated_run, "run-truncated-acquire": truncated_run,
    "run-truncated-live": truncated_live_run, "run-foreign-hdf5": foreign_hdf5,
    "run-runs-dataset": runs_dataset,
    "run-no-rate-identify": mutate_run(del_attr("sample_rate_hz")),
    "run-no-rate-frf": mutate_run(del_attr("sample_rate_hz")),
    "run-no-rate-report": mutate_run(del_attr("sample_rate_hz")),
    "run-rate-text": mutate_run(set_attr("sample_rate_hz", "fast")),
    "run-rate-negative": mutate_run(set_attr("sample_rate_hz", -1.0)),
    "run-pose-not-json": mutate_run(set_attr("pose", "theta=3")),
    "run-excitation-unknown": mutate_run(set_attr("excitation", "hammer")),
    "run-no-start-time": mutate_run(del_attr("start_time")),
    "run-samples-text": mutate_run(replace_dataset("samples", np.array([[b"a", b"b"]] * 4))),
    "run-samples-1d": mutate_run(replace_dataset("samples", np.arange(100.0))),
    "run-channels-floats": mutate_run(replace_dataset("channels", np.ones((2, 3)))),
    "run-no-events": mutate_run(lambda g: g.__delitem__("events")),
    "report-mathtext-channel": lambda p: write_run(p, channel_names=("F", "a$\\frac{1$")),
    "run-channel-kind": mutate_run(lambda g: g["channels"].__setitem__(
        0, tuple(b"hammer" if n == "kind" else g["channels"][0][n] for n in g["channels"].dtype.names))),
    "run-pose-deep": mutate_run(set_attr("pose", "[" * 100_000 + "]" * 100_000)),
    "run-pose-5001-digits": mutate_run(set_attr("pose", '{"theta_deg": ' + "9" * 5001 + "}")),
    "frf-provenance-deep": with_frf(lambda g: g["frf"].attrs.__setitem__("provenance",
                                                                          "[" * 100_000 + "]" * 100_000)),
    "run-link-loop-identify": soft_link_loop, "run-link-loop-frf": soft_link_self_loop,
    "run-link-loop-report": soft_link_loop,
    "run-external-link": lambda p: (write_run(p), _edit(p, lambda f: external_link("r1")(f["runs"]))),
    "samples-external-link": mutate_run(external_link("samples")),
    "samples-dangling-link": mutate_run(dangling_soft("samples")),
    "samples-damaged-identify": damaged_chunk, "samples-damaged-frf": damaged_chunk,
    "samples-damaged-report": damaged_chunk,
    "samples-filter-identify": missing_filter, "samples-filter-frf": missing_filter,
    "run-duplicate-channel": mutate_run(duplicate_channel),
    "run-duplicate-channel-frf": mutate_run(duplicate_channel),
    "run-pose-nan": mutate_run(set_attr("pose", '{"theta_deg": NaN}')),
    "run-pose-text": mutate_run(set_attr("pose", '{"theta_deg": "sixty"}')),
    "frf-group-dataset": mutate_run(lambda g: g.__setitem__("frf", np.arange(3))),
    "frf-group-dataset-report": mutate_run(lambda g: g.__setitem__("frf", np.arange(3))),
    "frf-nfft-text": with_frf(lambda g: g["frf"].attrs.__setitem__("nfft", "big")),
    "frf-H-1d": with_frf(lambda g: replace_dataset("H", np.ones(5))(g["frf"])),
    "frf-freq-nan": with_frf(lambda g: g["frf/freq_hz"].__setitem__(3, np.nan)),
    "frf-coherence-shape": with_frf(lambda g: replace_dataset("coherence", np.ones((7, 3)))(g["frf"])),
    "frf-outputs-not-list": with_frf(lambda g: g["frf"].attrs.__setitem__("outputs", '{"a": 1}')),
    "frf-H-external": with_frf(lambda g: external_link("H")(g["frf"])),
    "frf-no-H": with_frf(lambda g: g["frf"].__delitem__("H")),
    "sweep-constant-force": mutate_run(lambda g: (g.attrs.__setitem__("excitation", "sweep"),
                                                  g["samples"].__setitem__((slice(None), 0), 1.0))),
    "run-samples-never-written-frf": never_written, "run-samples-never-written-identify": never_written,
    "sweep-nan-force": mutate_run(lambda g: (g.attrs.__setitem__("excitation", "sweep"),
                                             g["samples"].__setitem__((slice(None), 0), np.nan))),
}


def _edit(path: Path, change: Callable[[h5py.File], None]) -> None:
    with h5py.File(path, "r+") as f:
        change(f)
UFF_FILES = {"uff-lengths": uff_cut_short, "uff-flat": uff_flat}


def _prepare(r: Row, root: Path) -> Path:
    d = root / r.name
    d.mkdir()
    files = {**BASE, **r.files}
    if r.name in RUN_FILES:
        files["run.h5"] = RUN_FILES[r.name]
    if r.name in UFF_FILES:
        files["f.uff"] = UFF_FILES[r.name]
    for name, content in files.items():
        target = d / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if callable(content):
            content(target)
        elif isinstance(content, bytes):
            target.write_bytes(content)
        else:
            target.write_text(content, encoding="utf-8")
    return d


@dataclass(frozen=True)
class Outcome:
    code: int | None
    stderr: str
    seconds: float
    changed: tuple[str, ...] = ()   # files of the row's folder that are not as they were before


def _snapshot(folder: Path) -> dict[str, str]:
    """Every entry under ``folder``: a regular file by its SHA-256 (above 64 MiB by its size, mtime and
    inode), a link by its target, else its type."""
    out = {}
    for p in sorted(folder.rglob("*")):
        st = p.lstat()
        if stat.S_ISLNK(st.st_mode):
            out[str(p.relative_to(folder))] = "link:" + os.readlink(p)
        elif stat.S_ISREG(st.st_mode) and st.st_size > 64 << 20:   # a sparse giant: not read whole
            out[str(p.relative_to(folder))] = f"{st.st_size}:{st.st_mtime_ns}:{st.st_ino}"
        elif stat.S_ISREG(st.st_mode):
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[str(p.relative_to(folder))] = stat.filemode(st.st_mode)[0]
    return out


def _cold(exe: str, args: list[str], d: Path) -> tuple[int | None, str]:
    """Exit code (None: killed as hung) and stderr of the installed console script started afresh."""
    try:
        done = subprocess.run([exe, *args], capture_output=True, text=True, cwd=d, timeout=ROW_TIMEOUT_S,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired as exc:
        err = exc.stderr.decode(errors="replace") if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        return None, err
    return done.returncode, done.stderr


def _warm(clis: Queue, args: list[str], d: Path) -> tuple[int | None, str]:
    """The same, started warm (tests/warm_cli.py) by a free server of ``clis``."""
    cli = clis.get()
    try:
        return cli.run(args, d, timeout_s=ROW_TIMEOUT_S)
    finally:
        clis.put(cli)


def _run(r: Row, root: Path, start: Callable[[list[str], Path], tuple[int | None, str]]) -> Outcome:
    d = _prepare(r, root)
    before = _snapshot(d)
    args = [a.replace("{d}", str(d)) for a in r.args]
    t0 = time.monotonic()
    code, stderr = start(args, d)
    if code is None:
        return Outcome(None, stderr, time.monotonic() - t0)
    after = _snapshot(d)
    changed = tuple(sorted(k for k in before if after.get(k) != before[k]))
    if code == 2:   # a refused command leaves nothing of its own behind either
        changed += tuple(sorted(k for k in after if k not in before))
    return Outcome(code, stderr, time.monotonic() - t0, changed)


def _console_script() -> str:
    exe = Path(sys.executable).with_name("flexmodal")
    found = str(exe) if exe.exists() else shutil.which("flexmodal")
    assert found, "the flexmodal console script is not installed (pip install -e .)"
    return found


# started cold: the controls (the others: warm, tests/warm_cli.py)
COLD = {r.name for r in ROWS if r.name.startswith("control-")}


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory: pytest.TempPathFactory, warm_cli: WarmCli) -> dict[str, Outcome]:
    root = tmp_path_factory.mktemp("cli-table")
    exe = _console_script()
    own = [WarmCli(exe) for _ in range(THREADS - 1)]   # and the session's (tests/conftest.py warm_cli)
    clis: Queue = Queue()
    try:
        for cli in [warm_cli, *own]:
            clis.put(cli)
        with ThreadPoolExecutor(THREADS) as pool:
            futures = {r.name: pool.submit(_run, r, root, lambda args, d, cold=r.name in COLD:
                                           _cold(exe, args, d) if cold else _warm(clis, args, d))
                       for r in ROWS}
            return {name: f.result() for name, f in futures.items()}
    finally:
        for cli in own:
            cli.close()


def test_table_covers_every_command_and_class() -> None:
    commands = {r.args[0] for r in ROWS}
    assert commands >= {"demo", "acquire", "sim", "frf", "identify", "predict", "compare", "diagnose",
                        "report"}
    assert len(ROWS) >= 200 and len([r for r in ROWS if r.code == 2]) >= 190
    assert len({r.name for r in ROWS}) == len(ROWS)


@pytest.mark.parametrize("r", ROWS, ids=[r.name for r in ROWS])
def test_row(r: Row, outcomes: dict[str, Outcome]) -> None:
    out = outcomes[r.name]
    assert out.code is not None, f"hung: no exit within {ROW_TIMEOUT_S} s; stderr: {out.stderr[-500:]}"
    assert "Traceback" not in out.stderr, out.stderr[-2000:]
    assert out.code == r.code, f"exit {out.code}, expected {r.code}; stderr: {out.stderr[-1000:]}"
    if r.code == 2:
        lines = out.stderr.strip().splitlines()
        assert len(lines) == 1, f"expected one line on stderr, got {len(lines)}: {out.stderr[-1000:]}"
        for word in r.words:
            assert word in lines[0], f"{word!r} not in {lines[0]!r}"
        assert not out.changed, f"a refused command changed or left files: {out.changed}"
    else:   # a warning the row expects (suspicious values are accepted with one)
        for word in r.words:
            assert word in out.stderr, f"{word!r} not in {out.stderr[-1000:]!r}"


def test_row_times(outcomes: dict[str, Outcome]) -> None:
    """Row wall times (printed with -s: median, spread, slowest); every row under the time limit."""
    seconds = np.array([o.seconds for o in outcomes.values()])
    slowest = sorted(((round(o.seconds, 1), n) for n, o in outcomes.items()), reverse=True)[:5]
    print(json.dumps({"rows": len(outcomes), "median_s": round(float(np.median(seconds)), 2),
                      "p10_p90_s": [round(float(v), 2) for v in np.percentile(seconds, [10, 90])],
                      "slowest_s": slowest}))
    assert all(o.seconds < ROW_TIMEOUT_S for o in outcomes.values())
