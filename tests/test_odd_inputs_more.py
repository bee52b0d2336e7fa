"""Odd inputs beyond the classes of tests/test_cli_table.py (an adversarial pass of 26 Nov): each a
failure once seen (a traceback, exit 1, or a silent answer), now one line naming the file, field or
value and exit code 2.  In-process calls of the CLI entry point (the point is the message), a few
milliseconds each but the one run file."""

from __future__ import annotations

import errno
import io
import os
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import REPO
from conftest import one_line as _one_line

from flexmodal.app import main
from flexmodal.compare.candidates import parse_effects

RIG = (REPO / "examples" / "rigs" / "seed003_two_link.toml").read_text(encoding="utf-8")
MODES = (REPO / "examples" / "measured" / "seed003_table3_f1f2.csv").read_text(encoding="utf-8")
PRED = "config,mode,freq_hz,source\ntheta0,1,25.3,fe\ntheta30,1,26.1,fe\n"


class _FullDisk(io.StringIO):
    """A stream on a full disk, as /dev/full is (every write fails)."""

    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_run_whose_sample_rate_is_finite_but_absurd_is_refused(tmp_path: Path, capsys) -> None:
    """sample_rate_hz = 1e300 passed the finite > 0 check and overflowed in the FRF fit (exit 1)."""
    from flexmodal.daq.store import Channel, RunWriter

    path = tmp_path / "run.h5"
    chans = [Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2")]
    with RunWriter(path, "r1", sample_rate_hz=1024.0, channels=chans, excitation="random",
                   pose={"theta_deg": 0.0}) as w:
        w.append(np.random.default_rng(0).standard_normal((256, 2)))
    for rate in (1e300, 5e-324):
        with h5py.File(path, "r+") as f:
            f["runs/r1"].attrs["sample_rate_hz"] = rate
        _one_line(capsys, main(["frf", str(path)]), "run.h5", "sample_rate_hz", "<= 1e+09 Hz")
    with pytest.raises(Exception, match="sample_rate_hz must be > 0 and <= 1e"):
        RunWriter(tmp_path / "new.h5", "r1", sample_rate_hz=1e12, channels=chans, excitation="random",
                  pose={})


@pytest.mark.parametrize(("table", "words"), [
    ("config,mode,freq_hz\n", ("modes.csv", "header but no rows")),   # was a zip() traceback
    ("config,mode,freq_hz,pose.theta_deg\ntheta0,1,25.5,0\ntheta0,2,92.2,60\n",   # was: first row wins
     ("modes.csv", "'theta0'", "pose.theta_deg", "0 and 60")),
])
def test_modal_table_without_rows_or_with_two_poses_in_one_config(tmp_path: Path, capsys, table: str,
                                                                   words: tuple[str, ...]) -> None:
    (tmp_path / "modes.csv").write_text(table, encoding="utf-8")
    (tmp_path / "pred.csv").write_text(PRED, encoding="utf-8")
    _one_line(capsys, main(["compare", str(tmp_path / "modes.csv"), str(tmp_path / "pred.csv")]), *words)


def test_modal_map_keeps_its_per_mode_mean_poses(tmp_path: Path, capsys) -> None:
    """A modal map (identify --track) names a pose bin per config; each of its rows carries the mean
    pose of that mode's windows, so one bin holds several pose values and is read as it is."""
    rows = ("config,mode,freq_hz,n_windows,pose.theta_deg\n"
            "theta_deg=30,1,25.5,4,29.1\ntheta_deg=30,2,92.2,3,31.2\n")
    (tmp_path / "map.csv").write_text(rows, encoding="utf-8")
    (tmp_path / "pred.csv").write_text(PRED, encoding="utf-8")
    assert main(["compare", str(tmp_path / "map.csv"), str(tmp_path / "pred.csv")]) == 0
    assert "theta_deg=30" in capsys.readouterr().out


def test_poses_listing_a_config_twice(tmp_path: Path, capsys) -> None:
    """Two poses for one config: the last one silently won; the same pose twice (a modal table given
    as POSES.csv, as the README does) stays fine."""
    (tmp_path / "rig.toml").write_text(RIG, encoding="utf-8")
    args = ["predict", str(tmp_path / "rig.toml"), "--model", "fe", "--poses", str(tmp_path / "poses.csv"),
            "--out", str(tmp_path / "pred.csv"), "--modes", "1"]
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\ntheta0,0\ntheta0,60\n", encoding="utf-8")
    _one_line(capsys, main(args), "poses.csv", "'theta0'", "0 and 60")
    assert not (tmp_path / "pred.csv").exists()
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\ntheta0,0\ntheta0,0\n", encoding="utf-8")
    assert main(args) == 0 and (tmp_path / "pred.csv").read_text(encoding="utf-8").count("theta0") == 1


@pytest.mark.parametrize(("old", "new", "words"), [
    ('kind = "rigid"', 'kind = "rigid"\nstiffnes = 3', ("joint[0].stiffnes", "unknown key")),
    ("[[sensor]]", "[[sensors]]", ("sensors", "unknown key", "sensor")),
    ('name = "a1"', 'name = "a1"\nmass_g = 2', ("sensor[0].mass_g", "unknown key", "mass_kg")),
    ("rho_kg_m3 = 2700", "rho_kg_m3 = 2700\nE_GPa = 75", ("material.aluminium.E_GPa", "unknown key")),
    ('{ shape = "square_tube", outer_m = 0.040, wall_m = 0.0011 }',
     '{ shape = "solid_rect", width_m = 0.04, height_m = 0.04, wall_m = 0.001 }',
     ("link[0].section.wall_m", "solid_rect")),
])
def test_rig_key_misspelt_is_named_not_dropped(tmp_path: Path, capsys, old: str, new: str,
                                               words: tuple[str, ...]) -> None:
    """A misspelt optional key (a sensor's mass, a mass's inertia) was ignored: the model was built
    without it and exit 0."""
    (tmp_path / "rig.toml").write_text(RIG.replace(old, new, 1), encoding="utf-8")
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\nt,0\n", encoding="utf-8")
    code = main(["predict", str(tmp_path / "rig.toml"), "--model", "fe", "--poses",
                 str(tmp_path / "poses.csv"), "--out", str(tmp_path / "pred.csv")])
    _one_line(capsys, code, "rig.toml", *words)


def test_effect_named_twice_counts_once() -> None:
    """`diagnose --effects joint_stiffness,joint_stiffness` ended in a numpy traceback (exit 1)."""
    assert parse_effects("joint_stiffness, joint_stiffness,tip_mass") == ("joint_stiffness", "tip_mass")


def test_stdout_closed_full_or_current_folder_gone(tmp_path: Path, capsys, monkeypatch) -> None:
    """`flexmodal compare ... >&-` was an AttributeError traceback; `> /dev/full` and a deleted
    current folder gave a line naming nothing ("No space left on device")."""
    (tmp_path / "modes.csv").write_text(MODES, encoding="utf-8")
    (tmp_path / "pred.csv").write_text(PRED, encoding="utf-8")
    args = ["compare", str(tmp_path / "modes.csv"), str(tmp_path / "pred.csv")]
    with monkeypatch.context() as m:
        m.setattr("sys.stdout", None)
        _one_line(capsys, main(args), "standard output is closed")
    with monkeypatch.context() as m:
        m.setattr("sys.stdout", _FullDisk())
        _one_line(capsys, main(args), "standard output: No space left on device")
    gone = tmp_path / "gone"
    gone.mkdir()
    monkeypatch.chdir(gone)
    gone.rmdir()
    _one_line(capsys, main([*args, "--out", "t.md"]), "current folder no longer exists")


@pytest.mark.parametrize(("pose", "words"), [
    ("thta_deg=60", ("'thta_deg'", "theta_deg")),   # the rig stayed at its default 30 deg, exit 0
    ("theta_deg=10,theta_deg=20", ("theta_deg is given twice",)),   # the last one won
])
def test_simulator_pose_names_the_rig_does_not_have(capsys, pose: str, words: tuple[str, ...]) -> None:
    code = main(["sim", "serve", "--protocol", "serial", "--pose", pose, "--duration", "0.5", "--quiet"])
    _one_line(capsys, code, "pose", *words)


def test_simulator_rate_beyond_memory_is_refused_before_allocating(capsys, monkeypatch) -> None:
    """`sim serve --rate 1e7` computed 8 s of the rig at 10 MHz in memory (some 30 GB): the machine
    swapped.  Here the machine is made to have 2 GB so that 1 MHz (about 3 GB) is refused."""
    monkeypatch.setattr("flexmodal.checked_io.text.available_memory_bytes", lambda: 2_000_000_000)
    code = main(["sim", "serve", "--protocol", "serial", "--rate", "1e6", "--duration", "0.5", "--quiet"])
    _one_line(capsys, code, "sample rate 1e+06 Hz", "GB", "lower rate")


def test_python_api_names_wrong_arguments(tmp_path: Path) -> None:
    """The Python API's wrong arguments end in the error family or a TypeError saying what was
    expected, not in an AttributeError, KeyError, ValueError or numpy ufunc error from deep inside."""
    import flexmodal as fm

    (tmp_path / "modes.csv").write_text(MODES, encoding="utf-8")
    rig, modes = REPO / "examples" / "rigs" / "seed003_two_link.toml", tmp_path / "modes.csv"
    with pytest.raises(fm.ModelError, match="config 't': pose theta_deg = 'x' is not a finite number"):
        fm.predict(rig, {"t": {"theta_deg": "x"}}, "fe")            # was ValueError from float()
    with pytest.raises(TypeError, match="expected a modal table or the path of its CSV file, got list"):
        fm.compare_modes(modes, [modes])                            # was AttributeError: .source
    with pytest.raises(fm.ReportError, match="no configuration 'nope'"):
        fm.plot_mode_shapes(rig, modes, "nope")                     # was KeyError
    with pytest.raises(fm.ModalError, match="--fmin '10': not a frequency"):
        fm.identify(modes, fmin="10")                               # was a numpy ufunc error
    with pytest.raises(TypeError, match="source must be an HDF5 or UFF path or an FrfResult, got bytes"):
        fm.identify(b"run.h5")                                      # was AttributeError: .H
    with pytest.raises(fm.FixtureError, match="n_cases = 0"):
        fm.selftest(0)                                              # was a summary of nan %


@pytest.mark.parametrize(("units", "normalised"), [(("N", "m/s^2"), True), (("N", "m/s²"), True),
                                                   (("N", "g"), False), (("kN", "m/s^2"), False)])
def test_mass_normalisation_only_in_si_units(tmp_path: Path, units: tuple[str, str],
                                             normalised: bool) -> None:
    """A run stored in g (or kN) had its shapes mass-normalised as if in m/s^2 per N: off by sqrt(9.81)
    with exit 0.  The driving point is now used only in SI units; otherwise shapes are unit-maximum."""
    from flexmodal.daq.store import Channel, RunWriter, read_run
    from flexmodal.modal.compute import compute_frf
    from flexmodal.modal.sources import _driving_point

    chans = [Channel("F", "force", units[0], location="tip", direction="y"),
             Channel("a1", "acceleration", units[1], location="tip", direction="y")]
    with RunWriter(tmp_path / "run.h5", "r1", sample_rate_hz=1024.0, channels=chans, excitation="random",
                   pose={}) as w:
        w.append(np.random.default_rng(0).standard_normal((1024, 2)))
    run = read_run(tmp_path / "run.h5", "r1")
    assert (_driving_point(run, compute_frf(run, nfft=256)) == 0) is normalised


def test_frf_out_into_another_files_run_of_the_same_id(tmp_path: Path, capsys) -> None:
    """`frf a.h5 --out b.h5` where b.h5 holds its own run r1: a's FRFs replaced b's and sat beside
    samples they were not computed from, exit 0.  A file holding only FRFs (an earlier --out) stays a
    valid target."""
    from flexmodal.daq.store import Channel, RunWriter

    chans = [Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2")]
    for name, rate in (("a.h5", 1024.0), ("b.h5", 512.0)):
        with RunWriter(tmp_path / name, "r1", sample_rate_hz=rate, channels=chans, excitation="random",
                       pose={}) as w:
            w.append(np.random.default_rng(0).standard_normal((1024, 2)))
    before = (tmp_path / "b.h5").read_bytes()
    _one_line(capsys, main(["frf", str(tmp_path / "a.h5"), "--out", str(tmp_path / "b.h5"), "--quiet"]),
              "b.h5", "'r1'", "another run with its own samples")
    assert (tmp_path / "b.h5").read_bytes() == before
    for _ in range(2):
        assert main(["frf", str(tmp_path / "a.h5"), "--out", str(tmp_path / "f.h5"), "--quiet"]) == 0


def test_compare_names_a_config_predicted_at_another_pose(tmp_path: Path, capsys) -> None:
    """Measured theta0 at 0 deg, predicted theta0 at 60 deg: the modes of two poses were paired under
    one name and their gap reported as the model's error, exit 0."""
    (tmp_path / "modes.csv").write_text(MODES, encoding="utf-8")
    pred = "config,mode,freq_hz,pose.theta_deg\ntheta0,1,25.3,60\n"
    (tmp_path / "pred.csv").write_text(pred, encoding="utf-8")
    _one_line(capsys, main(["compare", str(tmp_path / "modes.csv"), str(tmp_path / "pred.csv")]),
              "'theta0'", "pose.theta_deg = 0", "predicted at 60")


def test_config_names_with_markup_characters_stay_in_their_cell(tmp_path: Path, capsys) -> None:
    """A `$` or `{` in a configuration name broke the LaTeX table, a `|` the Markdown one (and LaTeX's:
    OT1 prints it as a dash); `_` before a brace may open emphasis in Markdown."""
    for name, f in (("m.csv", 30), ("p.csv", 31)):   # two configurations: the config column is shown
        text = f'config,mode,freq_hz\n"r$1_{{a}}|b",1,{f}\nt2,1,{f}\n'
        (tmp_path / name).write_text(text, encoding="utf-8")
    args = ["compare", str(tmp_path / "m.csv"), str(tmp_path / "p.csv"), "--format"]
    assert main([*args, "tex"]) == 0
    assert r"r\$1\_\{a\}\textbar{}b &" in capsys.readouterr().out
    assert main([*args, "md"]) == 0
    assert r"| r$1\_{a}\|b |" in capsys.readouterr().out


def test_a_terminal_that_cannot_show_greek_letters(tmp_path: Path) -> None:
    """stdout in ASCII (a C or Latin-1 locale, PYTHONIOENCODING=ascii): the comparison's `Δf` header
    ended in a UnicodeEncodeError traceback, exit 1, after the work was done.  A process of its own:
    the point is the stream the process is started with."""
    import subprocess
    import sys

    (tmp_path / "modes.csv").write_text(MODES, encoding="utf-8")
    (tmp_path / "pred.csv").write_text(PRED, encoding="utf-8")
    env = {**os.environ, "PYTHONIOENCODING": "ascii"}
    env.pop("PYTHONUTF8", None)
    command = [sys.executable, "-m", "flexmodal", "compare", "modes.csv", "pred.csv"]
    done = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, timeout=300)
    assert done.returncode == 0 and b"Traceback" not in done.stderr, done.stderr.decode()
    assert b"\\u0394f" in done.stdout


def test_run_of_integer_counts_identifies(tmp_path: Path) -> None:
    """Samples stored as int32 (coarse counts of -3..3): the uncertainty's Gauss-Newton refinement
    diverged (poles to 1e25) and ended in a ValueError traceback, exit 1.  A step that raises the
    residual is not taken now; the modes and their standard deviations come out finite."""
    from flexmodal.contract.table import ModalTable
    from flexmodal.daq.store import Channel, RunWriter

    rng = np.random.default_rng(1)
    force = rng.standard_normal(8192)
    response = np.convolve(force, np.exp(-np.arange(200) / 40.0) * np.sin(np.arange(200) / 3.0))[:8192]
    chans = [Channel("F", "force", "N", location="tip", direction="y"),
             Channel("a1", "acceleration", "m/s^2", location="tip", direction="y")]
    with RunWriter(tmp_path / "run.h5", "r1", sample_rate_hz=1024.0, channels=chans, excitation="random",
                   pose={}) as w:
        w.append(np.column_stack([force, response]))
    with h5py.File(tmp_path / "run.h5", "r+") as f:
        g = f["runs/r1"]
        counts = g["samples"][...].astype(np.int32)
        del g["samples"]
        g.create_dataset("samples", data=counts, chunks=(1024, 2), maxshape=(None, 2))
    assert main(["identify", str(tmp_path / "run.h5"), "--out", str(tmp_path / "m.csv"), "--quiet"]) == 0
    table = ModalTable.read_csv(tmp_path / "m.csv").frame
    assert len(table) and np.isfinite(table[["freq_hz", "freq_std_hz", "damping_std"]].to_numpy()).all()


def test_session_whose_simulator_rig_is_wrong_is_one_line(tmp_path: Path, capsys) -> None:
    """A session's simulator with a rig the simulator refuses printed the child's error line and then
    the session's own "simulator ... did not start" (two lines, the second without the reason)."""
    (tmp_path / "rig.toml").write_text(RIG.replace('kind = "rigid"', 'kind = "rigid"\nstifness = 1'),
                                       encoding="utf-8")
    session = (REPO / "examples" / "sessions" / "serial-sim.toml").read_text(encoding="utf-8")
    session = session.replace('"../rigs/demo_arm.toml"', '"rig.toml"')
    (tmp_path / "s.toml").write_text(session, encoding="utf-8")
    code = main(["acquire", "--config", str(tmp_path / "s.toml"), "--out", str(tmp_path / "r.h5"),
                 "--duration", "1", "--quiet"])
    _one_line(capsys, code, "s.toml: simulator", "joint[0].stifness", "unknown key")
    assert not (tmp_path / "r.h5").exists()


def test_demo_into_a_folder_of_ones_own_results(tmp_path: Path, capsys) -> None:
    """`flexmodal demo --out .` in a folder holding one's own runs.h5 and modes.csv replaced both with
    simulated ones, exit 0 (an interrupted demo would have removed them).  Refused now, untouched; a
    folder the demo wrote before is its own to rewrite."""
    (tmp_path / "modes.csv").write_text(MODES, encoding="utf-8")
    _one_line(capsys, main(["demo", "--out", str(tmp_path), "--quiet"]), "modes.csv",
              "not written by flexmodal demo")
    assert (tmp_path / "modes.csv").read_text(encoding="utf-8") == MODES
    assert not (tmp_path / "report.html").exists()
    from flexmodal.fixtures.demo import DEMO_MARK, claim_folder

    (tmp_path / DEMO_MARK).write_text("", encoding="utf-8")
    claim_folder(tmp_path)   # marked: the demo may replace its outputs there


def test_shapes_at_sensors_named_apart_are_said_not_silently_skipped(tmp_path: Path, capsys) -> None:
    """Both tables with shapes, sensors `a1, a2` against `A1, A2`: paired by frequency order without a
    word, as if no shapes had been given."""
    (tmp_path / "m.csv").write_text("config,mode,freq_hz,shape.a1,shape.a2\nt,1,10,1,0.5\nt,2,30,0.5,-1\n",
                                    encoding="utf-8")
    (tmp_path / "p.csv").write_text("config,mode,freq_hz,shape.A1,shape.A2\nt,1,11,1,0.5\nt,2,29,0.5,-1\n",
                                    encoding="utf-8")
    assert main(["compare", str(tmp_path / "m.csv"), str(tmp_path / "p.csv")]) == 0
    assert "paired by frequency order, not by MAC" in capsys.readouterr().out


def test_references_that_the_method_does_not_use(tmp_path: Path, capsys) -> None:
    """`identify RUN.h5 --references a1` on a run with a force: pLSCF from FRFs ran and the option was
    ignored, exit 0."""
    from flexmodal.daq.store import Channel, RunWriter

    chans = [Channel("F", "force", "N"), Channel("a1", "acceleration", "m/s^2")]
    with RunWriter(tmp_path / "run.h5", "r1", sample_rate_hz=1024.0, channels=chans, excitation="random",
                   pose={}) as w:
        w.append(np.random.default_rng(0).standard_normal((1024, 2)))
    code = main(["identify", str(tmp_path / "run.h5"), "--out", str(tmp_path / "m.csv"), "--method", "lscf",
                 "--references", "a1"])
    _one_line(capsys, code, "run.h5", "--references", "ssi/fdd", "lscf")
    assert not (tmp_path / "m.csv").exists()


@pytest.mark.parametrize("command", [
    ["predict", "{d}/rig.toml", "--model", "fe", "--poses", "{d}/modes.csv"],
    ["diagnose", "--rig", "{d}/rig.toml", "--measured", "{d}/modes.csv"],   # wrote into the current folder
    ["demo"],                                                                 # so did the demo
])
def test_an_empty_out_path_is_refused(tmp_path: Path, capsys, monkeypatch, command: list[str]) -> None:
    """`--out "$DIR"` with DIR unset: an empty path is not the current folder."""
    (tmp_path / "rig.toml").write_text(RIG, encoding="utf-8")
    (tmp_path / "modes.csv").write_text(MODES, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    code = main([a.format(d=tmp_path) for a in command] + ["--out", "", "--quiet"])
    _one_line(capsys, code, "--out", "path is empty")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["modes.csv", "rig.toml"]


class _ReaderGone(io.StringIO):
    """A pipe whose reader has ended (`flexmodal compare ... | head -1`)."""

    def write(self, text: str) -> int:
        raise BrokenPipeError(errno.EPIPE, os.strerror(errno.EPIPE))


def test_a_pipe_whose_reader_ended_is_no_error(tmp_path: Path, capsys, monkeypatch) -> None:
    """`flexmodal diagnose ... | head -1`: "flexmodal: error: Broken pipe", exit 2, once head had
    read its line.  The reader took what it wanted: exit 0, nothing on stderr."""
    (tmp_path / "modes.csv").write_text(MODES, encoding="utf-8")
    (tmp_path / "pred.csv").write_text(PRED, encoding="utf-8")
    monkeypatch.setattr("sys.stdout", _ReaderGone())
    assert main(["compare", str(tmp_path / "modes.csv"), str(tmp_path / "pred.csv")]) == 0
    assert capsys.readouterr().err == ""
