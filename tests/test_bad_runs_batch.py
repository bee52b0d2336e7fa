"""A bad run does not stop the others (`frf` and `identify` over a file of many runs): the good runs
are written, each bad one is named with why in one summary, and the exit code is 2; `identify` over
many runs shows a progress bar on a terminal only."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest

from flexmodal.app import main
from flexmodal.checked_io.progress import progress_bar
from flexmodal.daq.store import Channel, RunWriter
from flexmodal.fixtures.modal_sim import modal_response
from flexmodal.modal.errors import ModalError
from flexmodal.modal.runs_io import read_frf
from flexmodal.modal.skipped import RunsFailed

FS = 256.0
FN, ZETA = np.array([12.0, 31.0, 55.0]), np.array([0.02, 0.01, 0.01])
PHI = np.array([[1.0, 0.8, 0.3], [0.5, -0.6, 0.9], [0.2, -0.9, -0.7]])
CHANNELS = [Channel("force", "force", "N")] + [Channel(f"a{k}", "acceleration", "m/s^2") for k in (1, 2, 3)]
SHORT = "record of 1024 samples is shorter than one segment (nfft 2048)"
CONSTANT = "channel 'a2' is constant (1.5 throughout)"


def _runs(path, bad=("r1", "r3"), n_runs=4):
    """r0..r3 of a random test of three modes; r1 too short for nfft 2048, r3 with a stuck channel."""
    for k, rid in enumerate(["r0", "r1", "r2", "r3"][:n_runs]):
        f = np.random.default_rng(k).standard_normal((1024 if rid == "r1" and rid in bad else 4096, 1))
        samples = np.column_stack([f, modal_response(f, FS, FN, ZETA, PHI, PHI[[0]])])
        if rid == "r3" and rid in bad:
            samples[:, 2] = 1.5
        with RunWriter(path, rid, sample_rate_hz=FS, channels=CHANNELS, excitation="random",
                       pose={"k": k}) as w:
            w.append(samples)
    return path


def _stderr_lines(capsys) -> tuple[list[str], list[str]]:
    out, err = capsys.readouterr()
    return out.splitlines(), err.splitlines()


def test_frf_writes_the_good_runs_and_names_each_bad_one_in_one_summary(tmp_path, capsys):
    path = _runs(tmp_path / "runs.h5")
    assert main(["frf", str(path), "--nfft", "2048", "--workers", "0"]) == 2
    out, err = _stderr_lines(capsys)
    assert out == [f"{path}:r0", f"{path}:r2"]
    assert err == [f"flexmodal: error: {path}:r1: {SHORT}", f"flexmodal: error: {path}:r3: {CONSTANT}",
                   "flexmodal: error: 2 of 4 runs skipped (each named above), the other 2 done"]
    assert [read_frf(path, r) is not None for r in ("r0", "r1", "r2", "r3")] == [True, False, True, False]
    assert read_frf(path, "r2").nfft == 2048


def test_frf_one_bad_run_is_one_line_and_a_bad_file_does_not_stop_the_good_one(tmp_path, capsys):
    path = _runs(tmp_path / "runs.h5", bad=("r3",))
    missing = tmp_path / "missing.h5"
    assert main(["frf", str(path), "--nfft", "256"]) == 2
    out, err = _stderr_lines(capsys)
    assert len(out) == 3
    assert err == [f"flexmodal: error: {path}:r3: {CONSTANT} (skipped; the other 3 runs done)"]
    assert main(["frf", str(missing), f"{path}::r0", "--nfft", "256"]) == 2
    out, err = _stderr_lines(capsys)
    assert out == [f"{path}:r0"] and len(err) == 1 and str(missing) in err[0] and "skipped" in err[0]
    assert main(["frf", str(missing)]) == 2                     # nothing else: the error as it was
    out, err = _stderr_lines(capsys)
    assert out == [] and len(err) == 1 and "skipped" not in err[0] and str(missing) in err[0]


def test_api_compute_frfs_raises_runs_failed_after_writing_the_good_runs(tmp_path):
    import flexmodal as fm

    path = _runs(tmp_path / "runs.h5")
    with pytest.raises(RunsFailed) as info:
        fm.compute_frfs([path], nfft=2048)
    assert [(str(p), r) for p, r in info.value.written] == [(str(path), "r0"), (str(path), "r2")]
    assert [name for name, _ in info.value.failed] == [f"{path}:r1", f"{path}:r3"]
    assert isinstance(info.value, ModalError)


def test_identify_writes_the_good_runs_modes_and_names_the_bad_run(tmp_path, capsys):
    path, out = _runs(tmp_path / "runs.h5", bad=("r3",)), tmp_path / "modes.csv"
    assert main(["identify", str(path), "--out", str(out)]) == 2
    stdout, err = _stderr_lines(capsys)
    assert stdout == [str(out)]
    assert err[-1] == f"flexmodal: error: {path}:r3: {CONSTANT} (skipped; the other 3 runs done)"
    table = pd.read_csv(out)
    assert sorted(set(table["config"])) == ["r0", "r1", "r2"]
    for config in ("r0", "r1", "r2"):    # the three modes of each good run
        assert np.allclose(table.loc[table["config"] == config, "freq_hz"], FN, rtol=0.02)


def test_identify_progress_bar_shows_on_a_terminal_only(tmp_path, capsys, monkeypatch):
    """The bar is drawn on a terminal (a stream that says it is one), never into a pipe or log."""
    import flexmodal as fm

    path = _runs(tmp_path / "runs.h5", bad=(), n_runs=2)
    assert main(["identify", str(path), "--out", str(tmp_path / "m.csv"), "--fmax", "100"]) == 0
    assert "identify" not in capsys.readouterr().err         # stderr is not a terminal here: no bar

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    term = Terminal()
    monkeypatch.setattr("sys.stderr", term)
    with progress_bar(4, "identify") as advance:
        for _ in range(4):
            advance()
    assert "identify" in term.getvalue() and "100%" in term.getvalue()
    term.seek(0)
    term.truncate()
    fm.identify(path, quiet=False, fmax=100.0)
    assert "identify" in term.getvalue() and "100%" in term.getvalue()
    term.seek(0)
    term.truncate()
    assert main(["--quiet", "identify", str(path), "--out", str(tmp_path / "m.csv"), "--fmax", "100"]) == 0
    assert term.getvalue() == ""
