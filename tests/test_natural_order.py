"""Configurations are listed with their numbers read as numbers (theta0, theta30, theta120, theta150),
not as text (theta0, theta120, theta150, theta30): in the CSV files ``predict`` writes, the tables
``compare`` prints, the runs of a file and the configurations a warning names."""

from __future__ import annotations

import csv
import io
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RIG = REPO / "examples" / "rigs" / "seed003_two_link.toml"
NATURAL = ["theta0", "theta30", "theta120", "theta150"]


def _flexmodal(folder: Path, *argv: str) -> str:
    done = subprocess.run([sys.executable, "-m", "flexmodal", "--quiet", *argv], cwd=folder,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout


def _configs(rows) -> list[str]:
    return list(dict.fromkeys(r["config"] for r in rows))


def test_predict_and_compare_list_configurations_in_natural_order(tmp_path):
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\n" + "".join(
        f"{c},{c[5:]}\n" for c in ("theta150", "theta30", "theta0", "theta120")))
    _flexmodal(tmp_path, "predict", str(RIG), "--model", "fe", "--poses", "poses.csv", "--out", "fe.csv",
               "--modes", "2")
    with open(tmp_path / "fe.csv", newline="") as fh:
        assert _configs(csv.DictReader(fh)) == NATURAL
    # no pose column: the table is ordered by the names alone
    (tmp_path / "bare.csv").write_text("config,mode,freq_hz\n" + "".join(f"{c},1,{10 + k}\n" for k, c in
                                       enumerate(("theta150", "theta30", "theta0", "theta120"))))
    shown = _flexmodal(tmp_path, "compare", "bare.csv", "bare.csv", "--format", "csv")
    assert _configs(csv.DictReader(io.StringIO(shown))) == NATURAL


def test_runs_and_warnings_name_configurations_in_natural_order(tmp_path):
    """A run file whose runs were stored as theta120, theta30, theta0: listed, identified and named in the
    warning summary as theta0, theta30, theta120 (HDF5 keeps its groups sorted as text)."""
    import flexmodal as fm
    from flexmodal.fixtures.examples import impact_run

    for theta in (120, 30, 0):
        runs = impact_run(tmp_path, theta)
    assert fm.list_runs(runs) == ["theta0", "theta30", "theta120"]
    ident = fm.identify(runs, fmax=400.0)
    assert list(ident.modes) == list(dict.fromkeys(ident.table.frame["config"])) == fm.list_runs(runs)
    summary = ident.warning_summary()
    assert any(line.startswith("3 configurations (theta0, theta30, theta120)") for line in summary), summary
