"""Odd inputs of a third adversarial pass (26 Nov, evening): unusual but valid forms of HDF5 runs, UFF
files cut or padded, numbers too large for a float in JSON, TOML and CSV, units out of any physical
range.  Each was a traceback, a hang or a silent answer; each class is now one line naming the file and
item, exit code 2.  In-process (the point is the message); small files, a few seconds in all."""

from __future__ import annotations

import functools
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import REPO
from conftest import one_line as _one_line
from hypothesis import given, settings
from hypothesis import strategies as st

from flexmodal.app import main
from flexmodal.checked_io.uff_blocks import check_blocks
from flexmodal.daq.store import Channel, RunWriter, list_runs
from flexmodal.modal.errors import ModalError

RIG = (REPO / "examples" / "rigs" / "seed003_two_link.toml").read_text(encoding="utf-8")
SESSION = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text(encoding="utf-8")
BIG = "9" * 400   # a whole number beyond the largest float (about 1.8e308)


def _run(path: Path) -> Path:
    chans = [Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2")]
    with RunWriter(path, "r1", sample_rate_hz=1024.0, channels=chans, excitation="random",
                   pose={"theta_deg": 0.0}) as w:
        w.append(np.random.default_rng(0).standard_normal((512, 2)))
    return path


def _events_declared_huge(g: h5py.Group, folder: Path) -> None:   # was a 216 GiB MemoryError traceback
    dt = g["events"].dtype
    del g["events"]
    g.create_dataset("events", shape=(10**9,), dtype=dt, chunks=(1024,), maxshape=(None,))


def _frf_declared_huge(g: h5py.Group, folder: Path) -> None:   # was a hang (16 GB of fill values)
    f = g.create_group("frf")
    f.create_dataset("H", shape=(1, 1, 10**9), dtype="c16", chunks=(1, 1, 4096))
    f.create_dataset("freq_hz", shape=(10**9,), dtype="f8", chunks=(4096,))
    f.create_dataset("coherence", shape=(1, 10**9), dtype="f8", chunks=(1, 4096))


def _samples_virtual(g: h5py.Group, folder: Path) -> None:   # was silently zeros (missing source file)
    shape = g["samples"].shape
    del g["samples"]
    layout = h5py.VirtualLayout(shape=shape, dtype="f8")
    layout[:] = h5py.VirtualSource("missing.h5", "x", shape=shape)
    g.create_virtual_dataset("samples", layout, fillvalue=0)


def _samples_external_short(g: h5py.Group, folder: Path) -> None:   # was silently zero-padded
    s = g["samples"][...]
    del g["samples"]
    s[:10].astype("<f8").tofile(folder / "raw.bin")
    g.create_dataset("samples", shape=s.shape, dtype="<f8",
                     external=[(str(folder / "raw.bin"), 0, h5py.h5f.UNLIMITED)])


def _pose_too_large(g: h5py.Group, folder: Path) -> None:   # was an OverflowError traceback
    g.attrs["pose"] = '{"theta_deg": ' + BIG + "}"


def _pose_key_twice(g: h5py.Group, folder: Path) -> None:   # was: the last value silently
    g.attrs["pose"] = '{"theta_deg": 1, "theta_deg": 2}'


@pytest.mark.parametrize(("change", "words"), [
    (_events_declared_huge, ("'events' declares shape (1000000000,)", "never written")),
    (_frf_declared_huge, ("frf group", "declares shape", "never written")),
    (_samples_virtual, ("'samples' is a virtual dataset", "not followed")),
    (_samples_external_short, ("'samples' needs 8192 bytes", "external files", "hold 160")),
    (_pose_too_large, ("attribute pose", "400 digits", "too large")),
    (_pose_key_twice, ("attribute pose", "'theta_deg' appears twice")),
])
def test_run_file_forms_that_read_wrong_or_never_end(tmp_path: Path, capsys, change, words) -> None:
    path = _run(tmp_path / "run.h5")
    with h5py.File(path, "r+") as f:
        change(f["runs/r1"], tmp_path)
    _one_line(capsys, main(["identify", str(path), "--out", str(tmp_path / "m.csv")]), "run.h5", *words)
    assert not (tmp_path / "m.csv").exists()


def test_a_run_reached_by_two_links_is_one_run(tmp_path: Path) -> None:
    """An HDF5 hard or soft link to a run group made the same run appear twice (identified twice)."""
    path = _run(tmp_path / "run.h5")
    with h5py.File(path, "r+") as f:
        f["runs/r2"] = f["runs/r1"]                       # hard link
        f["runs/r0"] = h5py.SoftLink("/runs/r1")          # soft link
    assert list_runs(path) == ["r0"]


@functools.cache
def _uff() -> bytes:
    """A small ASCII dataset-58 file of two FRFs, written by flexmodal itself."""
    from flexmodal.modal.frf import FrfResult
    from flexmodal.modal.uff import write_frfs

    f = np.linspace(0.0, 100.0, 64)
    H = (1.0 / (50.0**2 - f**2 + 2j * 0.02 * 50.0 * f))[None, None, :] * np.array([[[1.0]], [[2.0]]])
    res = FrfResult(f, H, np.ones((2, f.size)), "H1", "hann", 126, 1, 200.0, "accelerance", ("1+z", "2+z"),
                    ("9+z",))
    with tempfile.TemporaryDirectory() as folder:
        write_frfs(Path(folder) / "base.uff", res)
        return (Path(folder) / "base.uff").read_bytes()


@pytest.mark.parametrize(("mutate", "words"), [
    (lambda b: b[: len(b) * 3 // 4], ("no closing -1 delimiter", "cut short")),   # was: read half silently
    (lambda b: b + b"hello\n", ("text outside any dataset", "hello")),
    (lambda b: b.replace(b"\n", b"\n\f", 3), ("is not a dataset number",)),        # was: one FRF dropped
])
def test_uff_files_cut_or_damaged_are_named(tmp_path: Path, capsys, mutate, words) -> None:
    (tmp_path / "in.uff").write_bytes(mutate(_uff()))
    _one_line(capsys, main(["identify", str(tmp_path / "in.uff"), "--out", str(tmp_path / "m.csv")]),
              "in.uff", *words)


@settings(max_examples=80, deadline=None, derandomize=True)
@given(cut=st.integers(0, 10**6), junk=st.binary(max_size=12))
def test_uff_block_check_never_raises_anything_else(cut: int, junk: bytes) -> None:
    """Any cut of a valid file, with any bytes after it: the dataset numbers or one ModalError."""
    data = _uff()
    text = data[: cut % (len(data) + 1)] + junk
    try:
        numbers = check_blocks("x.uff", text, ModalError)
    except ModalError as exc:
        assert str(exc).startswith("x.uff: line ") and "\n" not in str(exc)
    else:
        assert all(n == 58 for n in numbers)


@pytest.mark.parametrize(("argv", "table", "words"), [
    (["compare", "{t}", "{t}"], f"config,mode,freq_hz\ntheta0,1,{BIG}\n",
     ("line 2", "'freq_hz'", "400 digits")),
    (["predict", "{rig}", "--model", "fe", "--poses", "{t}", "--out", "{o}"],
     f"config,pose.theta_deg\ntheta0,{BIG}\n", ("line 2", "'pose.theta_deg'", "400 digits")),
    (["compare", "{t}", "{t}"], "config,mode,freq_hz\ntheta0,True,25.5\n",
     ("'mode' is not a number (True)",)),
    (["compare", "{t}", "{t}"], "config,mode,freq_hz,shape.\ntheta0,1,25.5,1\n",
     ("'shape.' names no sensor",)),
])
def test_table_cells_no_float_can_hold(tmp_path: Path, capsys, argv, table, words) -> None:
    (tmp_path / "t.csv").write_text(table)
    (tmp_path / "rig.toml").write_text(RIG)
    args = [a.format(t=tmp_path / "t.csv", rig=tmp_path / "rig.toml", o=tmp_path / "o.csv") for a in argv]
    _one_line(capsys, main(args), "t.csv", *words)


def test_config_names_are_read_without_surrounding_blanks(tmp_path: Path, capsys) -> None:
    """"theta0 " was a config of its own, never paired with "theta0"."""
    (tmp_path / "m.csv").write_text("config,mode,freq_hz\ntheta0 ,1,25.5\n")
    (tmp_path / "p.csv").write_text("config,mode,freq_hz\ntheta0,1,25.0\n")
    assert main(["compare", str(tmp_path / "m.csv"), str(tmp_path / "p.csv"), "--format", "csv"]) == 0
    assert "pairs with no" not in capsys.readouterr().out


@pytest.mark.parametrize(("old", "new", "words"), [
    ("E_Pa = 75e9", f"E_Pa = {BIG}", ("rig.toml", "400 digits", "too large")),
    ('kind = "rigid"', 'kind = "spring"\nk_Nm_per_rad = 1e308', ("joint[0].k_Nm_per_rad", "out of range")),
    ('[[sensor]]\nname = "a1"', '[[mass]]\nat = "elbow"\nmass_kg = 1e308\n\n[[sensor]]\nname = "a1"',
     ("mass[0].mass_kg", "out of range")),   # was a RuntimeWarning and modes of an infinite mass
])
def test_rig_numbers_beyond_any_arm(tmp_path: Path, capsys, old, new, words) -> None:
    (tmp_path / "rig.toml").write_text(RIG.replace(old, new))
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\ntheta0,0\n")
    _one_line(capsys, main(["predict", str(tmp_path / "rig.toml"), "--model", "fe", "--poses",
                            str(tmp_path / "poses.csv"), "--out", str(tmp_path / "o.csv")]), *words)


@pytest.mark.parametrize(("old", "new", "words"), [
    ("scale = 0.30517578125\nsensitivity = 50.0", "scale = 0\nsensitivity = 50.0", ("scale = 0", "non-zero")),
    ("scale = 0.30517578125\nsensitivity = 50.0", "scale = 1e308\nsensitivity = 1e-6",
     ("per device unit", "out of range")),   # recorded inf samples
])
def test_session_channel_gains_that_record_zeros_or_infinities(tmp_path: Path, old, new, words) -> None:
    from flexmodal.daq.errors import DaqError
    from flexmodal.daq.session import load_session

    text = SESSION.replace('"../rigs/demo_arm.toml"', f'"{REPO}/examples/rigs/demo_arm.toml"')
    (tmp_path / "s.toml").write_text(text.replace(old, new, 1))
    with pytest.raises(DaqError) as exc:
        load_session(tmp_path / "s.toml")
    assert all(w in str(exc.value) for w in words) and "channel 'F'" in str(exc.value)


@pytest.mark.parametrize(("out", "words"), [
    ("-", ("path is '-'", "not standard output")),             # wrote a file named '-'
    ("x.csv/", ("x.csv/", "ends with '/'")),                    # wrote x.csv
    ("loop", ("loop", "Too many levels of symbolic links")),    # replaced the looping link by a file
])
def test_output_paths_that_name_no_file(tmp_path: Path, capsys, monkeypatch, out, words) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "rig.toml").write_text(RIG)
    (tmp_path / "p.csv").write_text("config,pose.theta_deg\ntheta0,0\n")
    (tmp_path / "loop").symlink_to("loop")
    code = main(["predict", "rig.toml", "--model", "fe", "--poses", "p.csv", "--out", out])
    _one_line(capsys, code, *words)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loop", "p.csv", "rig.toml"]


def test_an_unknown_matplotlib_backend_in_the_environment(tmp_path: Path) -> None:
    """MPLBACKEND=nonexistent made matplotlib's import raise ValueError: a traceback in every command
    that draws (a fresh process: matplotlib reads the variable once, on import)."""
    (tmp_path / "m.csv").write_text("config,mode,freq_hz\ntheta0,1,25.5\n")
    done = subprocess.run([sys.executable, "-m", "flexmodal", "report", "--measured", str(tmp_path / "m.csv"),
                           "--out", str(tmp_path / "r.html")], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "MPLBACKEND": "nonexistent_backend"})
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "MPLBACKEND='nonexistent_backend'" in done.stderr and "not a matplotlib backend" in done.stderr


def test_more_frf_workers_than_the_machine_runs(tmp_path: Path, capsys) -> None:
    """--workers 256 on 2 CPUs started 256 interpreters."""
    path = _run(tmp_path / "run.h5")
    _one_line(capsys, main(["frf", str(path), "--workers", "256"]), "--workers 256", "usable CPUs",
              "MiB per worker")
    with h5py.File(path) as f:
        assert "frf" not in f["runs/r1"]


def test_simulator_pty_link_in_a_missing_folder_names_the_link(tmp_path: Path) -> None:
    """The error named the pty (/dev/pts/N) instead of the --link path the user gave."""
    from flexmodal.fixtures.errors import FixtureError
    from flexmodal.fixtures.sim_common import PtyLink

    with pytest.raises(FixtureError, match="nodir/tty: cannot create the pty link there"):
        PtyLink(tmp_path / "nodir" / "tty")


def test_python_api_names_an_argument_of_the_wrong_kind(tmp_path: Path) -> None:
    """None or a list where a result or table belongs was an AttributeError deep inside."""
    import flexmodal as fm

    rig = REPO / "examples" / "rigs" / "seed003_two_link.toml"
    for call in (lambda: fm.plot_frf(None), lambda: fm.plot_stabilisation("run.h5"),
                 lambda: fm.plot_gap(None), lambda: fm.predict(rig, [("theta0", 0)], model="fe"),
                 lambda: fm.compute_frfs([], workers=True)):
        with pytest.raises(TypeError, match="expected|workers must be"):
            call()


def test_a_run_file_another_program_holds_open(tmp_path: Path, capsys) -> None:
    """A file another process has open for writing (HDF5's file lock) was called 'not a readable HDF5
    file': it is in use, not damaged."""
    path = _run(tmp_path / "run.h5")
    code = (f"import h5py, sys\nf = h5py.File({str(path)!r}, 'a')\nprint('open', flush=True)\n"
            "sys.stdin.read()\n")
    holder = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True)
    try:
        assert holder.stdout.readline().strip() == "open"
        _one_line(capsys, main(["identify", str(path), "--out", str(tmp_path / "m.csv")]), "run.h5",
                  "in use by another process")
        _one_line(capsys, main(["frf", str(path)]), "run.h5", "in use by another process")
    finally:
        holder.communicate("", timeout=600)


def test_a_session_simulator_that_cannot_start_is_one_line(tmp_path: Path, capsys) -> None:
    """The simulator child printed its own error line above the session's: two lines."""
    text = SESSION.replace('"../rigs/demo_arm.toml"', f'"{REPO}/examples/rigs/demo_arm.toml"')
    effect = 'test = "impact"\neffects = ["nope@elbow:k=1"]'
    (tmp_path / "s.toml").write_text(text.replace('test = "impact"', effect))
    code = main(["acquire", "--config", str(tmp_path / "s.toml"), "--out", str(tmp_path / "r.h5"),
                 "--duration", "1"])
    _one_line(capsys, code, "s.toml", "did not start: unknown effect 'nope'")


def test_names_spelt_with_combining_accents_are_the_same_names(tmp_path: Path, capsys) -> None:
    """'théta0' written decomposed (NFD: e + U+0301) in one table and composed (NFC) in the other were
    two configs that never paired."""
    import unicodedata

    (tmp_path / "m.csv").write_text(f"config,mode,freq_hz\n{unicodedata.normalize('NFD', 'théta0')},1,25.5\n")
    (tmp_path / "p.csv").write_text(f"config,mode,freq_hz\n{unicodedata.normalize('NFC', 'théta0')},1,25.0\n")
    assert main(["compare", str(tmp_path / "m.csv"), str(tmp_path / "p.csv"), "--format", "csv"]) == 0
    out = capsys.readouterr().out
    assert "pairs with no" not in out and out.count("\n") == 2, out


def test_channel_names_are_read_composed_and_alike_names_are_one_name(tmp_path: Path, capsys) -> None:
    import unicodedata

    from flexmodal.daq.store import read_run

    path = _run(tmp_path / "run.h5")
    for names, ok in (((unicodedata.normalize("NFD", "é1"),), True),
                      ((unicodedata.normalize("NFD", "é1"), "é1"), False)):
        with h5py.File(path, "r+") as f:
            ch = f["runs/r1/channels"][...]
            for i, name in enumerate(names):
                ch["name"][-1 - i] = name.encode()
            del f["runs/r1/channels"]
            f["runs/r1/channels"] = ch
        if ok:
            assert read_run(path, "r1").channels[-1].name == "é1"
        else:
            _one_line(capsys, main(["frf", str(path)]), "channel name 'é1' appears twice")
