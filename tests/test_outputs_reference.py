"""The outputs of the demo and of the README tour stay what they were (issue 22: a refactoring leaves the
modal tables, FRF groups, predictions and diagnosis.json identical), compared with the values recorded
in tests/data/outputs_reference.json: strings exactly, numbers to 1e-9 relative (the same numbers up to
the last bits a BLAS build may move); FRF groups by their shape, attributes and two checksums of each
array (the sum of magnitudes and a position-weighted sum).

Compared: the demo's ``fe.csv``, ``modes.csv``, the FRF groups of every run of ``runs.h5`` and the whole
``diagnosis.json``; the tour's ``predict`` table, ``compare`` text and the whole
``diagnosis.json`` of ``diagnose --holdout theta30,theta90,theta150`` on seed 003's Table 3 (README),
and seed 003's straight arm predicted by the other models (assumed modes, lumped mass, Blevins).
Slow (``-m slow``): ``frf`` again and ``identify`` of the demo's runs by lscf (with ``--uff``), peak and
output-only SSI.

The demo's ``theta30-impact`` run is acquired through the serial stack from a simulator on a pty; the
simulator starts its record when the acquisition has opened the port (fixtures.sim_common.PtyLink.
await_reader), so the run holds the same samples (``first_index`` 32) whatever the start-up took, and
it is compared like every other run.

After an intended change of outputs, record again (and say so in the commit message):
``python tests/test_outputs_reference.py record``.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
import sys
from pathlib import Path

import pytest

REFERENCE = Path(__file__).parent / "data" / "outputs_reference.json"
REPO = Path(__file__).resolve().parents[1]
MEASURED = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"
SEED_RIG = REPO / "examples" / "rigs" / "seed003_two_link.toml"
DEMO_RIG = REPO / "examples" / "rigs" / "demo_arm.toml"
RTOL = 1e-9


def _cli(folder: Path, *argv: str) -> str:
    """stdout of ``flexmodal ARGV`` run in-process (exit 0 asserted), the folder's path replaced."""
    from flexmodal.app import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.chdir(folder):
        assert main(["--quiet", *argv]) == 0, argv
    return out.getvalue().replace(str(folder), "OUT").replace(str(REPO), "REPO")


def _table(path: Path) -> dict:
    """A CSV as {column: values}."""
    import pandas as pd

    frame = pd.read_csv(path)
    return {c: frame[c].tolist() for c in frame.columns}


def _frf_groups(path: Path) -> dict:
    """Per run: each dataset of its FRF group as (shape, sum |x|, sum |x| * position) and the group's
    attributes (but provenance, which names files and versions)."""
    import h5py
    import numpy as np

    found = {}
    with h5py.File(path, "r") as f:
        for run_id in sorted(f["runs"]):
            group = f["runs"][run_id].get("frf")
            if group is None:
                continue
            entry = {"@attrs": {k: str(v) for k, v in sorted(group.attrs.items()) if k != "provenance"}}
            for name in sorted(group):
                x = np.abs(np.asarray(group[name][()])).ravel()
                weight = np.linspace(1.0, 2.0, x.size)
                entry[name] = [list(group[name].shape), float(x.sum()), float((x * weight).sum())]
            found[run_id] = entry
    return found


def demo_snapshot(demo: Path) -> dict:
    """The deterministic outputs of ``flexmodal demo --out DEMO`` (see the module docstring)."""
    return {"fe.csv": _table(demo / "fe.csv"), "modes.csv": _table(demo / "modes.csv"),
            "runs.h5 frf": _frf_groups(demo / "runs.h5"),
            "diagnosis.json": json.loads((demo / "diagnosis.json").read_text())}


def tour_snapshot(folder: Path) -> dict:
    """The README tour on seed 003 (predict, compare, diagnose), run in ``folder``."""
    shown = {"predict": _cli(folder, "predict", str(SEED_RIG), "--model", "fe", "--poses", str(MEASURED),
                             "--out", "fe.csv", "--modes", "2"),
             "compare": _cli(folder, "compare", str(MEASURED), "fe.csv", "--format", "md"),
             "diagnose": _cli(folder, "diagnose", "--rig", str(SEED_RIG), "--measured", str(MEASURED),
                              "--out", "diag", "--holdout", "theta30,theta90,theta150")}
    found = {"stdout": shown, "fe.csv": _table(folder / "fe.csv"),
             "diagnosis.json": json.loads((folder / "diag" / "diagnosis.json").read_text())}
    (folder / "straight.csv").write_text("config,pose.theta_deg\ntheta0,0\n")   # beam models: straight arm
    for model in ("assumed-modes", "lumped-mass", "blevins"):
        _cli(folder, "predict", str(SEED_RIG), "--model", model, "--poses", "straight.csv", "--out",
             f"{model}.csv", "--modes", "3")
        found[f"predict {model}"] = _table(folder / f"{model}.csv")
    return found


def identify_snapshot(demo: Path, folder: Path) -> dict:
    """``identify`` of the demo's runs (lscf with --uff on a copy whose FRFs ``frf`` computes again, peak,
    output-only), run in ``folder``."""
    shutil.copy(demo / "runs.h5", folder / "runs.h5")
    _cli(folder, "frf", "runs.h5", "--workers", "0")
    found = {"runs.h5 frf again": _frf_groups(folder / "runs.h5")}
    for name, argv in (("lscf", ["--uff", "lscf.uff"]), ("peak", ["--method", "peak"])):
        _cli(folder, "identify", "runs.h5", "--out", f"{name}.csv", "--fmax", "450", *argv)
        found[name] = _table(folder / f"{name}.csv")
    _cli(folder, "identify", str(demo / "operational.h5"), "--out", "oma.csv", "--fmin", "20",
         "--fmax", "450")
    found["oma"] = _table(folder / "oma.csv")
    return found


def _differences(got, want, where: str = "") -> list[str]:
    """Where ``got`` differs from ``want``: structure and strings exactly, numbers to RTOL."""
    if isinstance(want, dict) and isinstance(got, dict):
        keys = sorted(set(want) | set(got))
        return [d for k in keys for d in (_differences(got.get(k), want.get(k), f"{where}/{k}")
                                          if k in want and k in got else [f"{where}/{k}: only one side"])]
    if isinstance(want, list) and isinstance(got, list):
        if len(want) != len(got):
            return [f"{where}: {len(got)} entries, recorded {len(want)}"]
        return [d for k, (g, w) in enumerate(zip(got, want, strict=True))
                for d in _differences(g, w, f"{where}[{k}]")]
    numbers = (int, float)
    if isinstance(want, numbers) and isinstance(got, numbers) and not isinstance(want, bool):
        same = (math.isnan(want) and math.isnan(got)) or math.isclose(got, want, rel_tol=RTOL, abs_tol=1e-300)
        return [] if same else [f"{where}: {got!r}, recorded {want!r}"]
    return [] if got == want else [f"{where}: {got!r}, recorded {want!r}"]


def _recorded(part: str) -> dict:
    return json.loads(REFERENCE.read_text())[part]


def test_the_demo_outputs_are_the_recorded_ones(demo_run):
    folder, *_ = demo_run
    assert _differences(demo_snapshot(folder), _recorded("demo")) == []


def test_the_readme_tour_outputs_are_the_recorded_ones(tmp_path):
    assert _differences(tour_snapshot(tmp_path), _recorded("tour")) == []


@pytest.mark.slow
def test_frf_and_identify_on_the_demo_runs_give_the_recorded_tables(demo_run, tmp_path):
    folder, *_ = demo_run
    assert _differences(identify_snapshot(folder, tmp_path), _recorded("identify")) == []


def test_the_comparison_catches_a_change_and_passes_what_is_equal():
    recorded = {"a": [1.0, float("nan"), "x"], "b": {"c": 2}}
    assert _differences({"a": [1.0 + 1e-12, float("nan"), "x"], "b": {"c": 2}}, recorded) == []
    assert _differences({"a": [1.0 + 1e-6, float("nan"), "y"], "b": {}}, recorded) == [
        "/a[0]: 1.000001, recorded 1.0", "/a[2]: 'y', recorded 'x'", "/b/c: only one side"]


def record() -> None:
    """Run the demo, the tour and the identifications in a temporary folder and write REFERENCE."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        _cli(root, "demo", "--out", "demo")
        (root / "tour").mkdir()
        (root / "ident").mkdir()
        found = {"demo": demo_snapshot(root / "demo"), "tour": tour_snapshot(root / "tour"),
                 "identify": identify_snapshot(root / "demo", root / "ident")}
    REFERENCE.write_text(json.dumps(found, indent=1, sort_keys=True) + "\n")
    print(REFERENCE)


if __name__ == "__main__":
    if sys.argv[1:] != ["record"]:
        sys.exit(__doc__)
    record()
