"""The outputs of the demo and of the README tour stay what they were (issue 22: a refactoring leaves the
modal tables, FRF groups, predictions and diagnosis.json identical), compared with the values recorded
in tests/data/outputs_reference.json: words exactly, numbers to what the pipeline can promise across
machines (the BLAS kernel OpenBLAS picks by CPU, and its thread count, move the last bits of every
matrix product; ``RTOL`` by kind, about ten times the largest difference measured between machines and
between core types: FE predictions 1e-8, identified frequencies 1e-6, FRF checksums 1e-5, the other
identified quantities and the diagnosis's errors and scores 1e-3, its fitted parameters 1e-2 (1e-3
absolute for pose-law log-slopes and curvatures): its fits converge, but in flat directions the optimum
moves by 1e-5 to 1e-3 relative when the model's rounding does by 1e-8 to 1e-7).  A number inside a
string (printed text, diagnosis summaries) is compared parsed, to the same tolerance plus one unit of
its last printed digit (rounding may move it), the words between numbers exactly.  FRF groups by their
shape, attributes and two checksums of each array (the sum of magnitudes and a position-weighted sum).

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
import re
import shutil
import sys
from pathlib import Path

import pytest

REFERENCE = Path(__file__).parent / "data" / "outputs_reference.json"
REPO = Path(__file__).resolve().parents[1]
MEASURED = REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"
SEED_RIG = REPO / "examples" / "rigs" / "seed003_two_link.toml"
DEMO_RIG = REPO / "examples" / "rigs" / "demo_arm.toml"
RTOL = {"diagnosis": 1e-3, "diagnosis params": 1e-2, "frf": 1e-5, "identified freq_hz": 1e-6,
        "identified": 1e-3, "prediction": 1e-8}
"""Relative tolerance by kind: diagnosis.json and printed text, the fitted parameters of every candidate
in diagnosis.json (a ranked candidate's flat direction moves them by up to 1e-3 between kernels), FRF
checksums, identified frequencies, the other identified quantities (damping, shapes, their stds,
MPC/MPD), FE and beam-model predictions."""
ATOL = {"/params/log_": 1e-3, "": 1e-12}
"""Absolute tolerance: pose-law log-slopes and curvatures (1/rad, 1/rad^2) are regularised towards 0,
where a relative tolerance means nothing (they moved by 2e-4 between kernels); everything else."""
IDENTIFIED = ("/modes.csv", "/lscf", "/peak", "/oma")
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


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


def _rtol(where: str) -> float:
    """The relative tolerance of the numbers at path ``where`` (``RTOL``)."""
    if where.startswith("/diagnosis.json") and ("/params/" in where or "/param_intervals/" in where):
        return RTOL["diagnosis params"]
    if where.startswith(("/diagnosis.json", "/stdout")):
        return RTOL["diagnosis"]
    if where.startswith("/runs.h5 frf"):
        return RTOL["frf"]
    if where.startswith(IDENTIFIED):
        column = where.split("/")[2].split("[")[0]
        return RTOL["identified freq_hz" if column == "freq_hz" else "identified"]
    return RTOL["prediction"]


def _last_digit(text: str) -> float:
    """One unit of the last printed digit of a number printed with a decimal point or an exponent, 0
    for an integer (a count or a name's index is compared by ``RTOL`` alone)."""
    mantissa, _, exponent = text.lower().partition("e")
    if "." not in mantissa and not exponent:
        return 0.0
    return 10.0 ** (int(exponent or 0) - len(mantissa.partition(".")[2]))


def _text_differences(got: str, want: str, rtol: float) -> bool:
    """Whether two strings differ in their words or in a number beyond ``rtol`` and rounding."""
    words_got, words_want = NUMBER.split(got), NUMBER.split(want)
    numbers_got, numbers_want = NUMBER.findall(got), NUMBER.findall(want)
    return words_got != words_want or any(
        abs(float(g) - float(w)) > rtol * abs(float(w)) + max(_last_digit(g), _last_digit(w))
        for g, w in zip(numbers_got, numbers_want, strict=True))


def _differences(got, want, where: str = "") -> list[str]:
    """Where ``got`` differs from ``want``: structure and words exactly, numbers to ``_rtol``."""
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
        atol = next(tol for key, tol in ATOL.items() if key in where)
        same = (math.isnan(want) and math.isnan(got)) or math.isclose(got, want, rel_tol=_rtol(where),
                                                                      abs_tol=atol)
        return [] if same else [f"{where}: {got!r}, recorded {want!r}"]
    if isinstance(want, str) and isinstance(got, str):
        return [f"{where}: {got!r}, recorded {want!r}"] if _text_differences(got, want, _rtol(where)) else []
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


KERNELS = (("Haswell", "1"), ("Prescott", "2"))
"""Two OpenBLAS kernels and thread counts (``OPENBLAS_CORETYPE``, ``OPENBLAS_NUM_THREADS``): AVX2 on one
thread and SSE3 on two, as two machines would pick; any x86-64 CPU runs both."""


def _tour_diagnosis_under(kernel: str, threads: str, folder: Path) -> tuple[str, dict]:
    """The BLAS kernel OpenBLAS reports and the tour's diagnose (stdout, diagnosis.json) in a process
    with OpenBLAS forced to ``kernel`` on ``threads`` threads."""
    import os
    import subprocess

    env = {**os.environ, "OPENBLAS_CORETYPE": kernel, "OPENBLAS_NUM_THREADS": threads}
    probe = ("import numpy; from threadpoolctl import threadpool_info; "
             "print(*[i.get('architecture') for i in threadpool_info() if i['internal_api'] == 'openblas'])")
    arch = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True,
                          check=True, timeout=60).stdout.strip()
    folder.mkdir()
    argv = ["diagnose", "--rig", str(SEED_RIG), "--measured", str(MEASURED), "--out", "diag",
            "--holdout", "theta30,theta90,theta150"]
    out = subprocess.run([sys.executable, "-m", "flexmodal", "--quiet", *argv], env=env, cwd=folder,
                         capture_output=True, text=True, check=True, timeout=600).stdout
    return arch, {"stdout": out.replace(str(folder), "OUT"),
                  "diagnosis.json": json.loads((folder / "diag" / "diagnosis.json").read_text())}


@pytest.mark.slow
def test_the_tour_diagnosis_is_the_same_under_two_blas_kernels(tmp_path):
    """The README tour's diagnosis under two BLAS kernels agrees to ``RTOL``: before its fits converged
    (stopping at a relative cost decrease of 1e-4), the spring stiffness was 1053.21 N/m under one and
    1053.13 under the other, and the stiffness interval printed 488 or 487.9 (about 12 s of CPU)."""
    (arch_a, a), (arch_b, b) = (_tour_diagnosis_under(kernel, threads, tmp_path / kernel)
                                for kernel, threads in KERNELS)
    assert arch_a and arch_b and arch_a != arch_b
    assert _differences(a, b) == []


def test_the_comparison_catches_a_change_and_passes_what_is_equal():
    recorded = {"a": [1.0, float("nan"), "x"], "b": {"c": 2}}
    assert _differences({"a": [1.0 + 1e-9, float("nan"), "x"], "b": {"c": 2}}, recorded) == []
    assert _differences({"a": [1.0 + 1e-6, float("nan"), "y"], "b": {}}, recorded) == [
        "/a[0]: 1.000001, recorded 1.0", "/a[2]: 'y', recorded 'x'", "/b/c: only one side"]


def test_numbers_are_compared_to_the_tolerance_of_their_kind_also_inside_text():
    recorded = {"diagnosis.json": {"k": 1053.21, "s": "k 488 N/m at theta30 (0.30 %)"},
                "modes.csv": {"freq_hz": [10.0]}, "fe.csv": {"freq_hz": [10.0]}}
    moved = {"diagnosis.json": {"k": 1053.13, "s": "k 487.9 N/m at theta30 (0.31 %)"},
             "modes.csv": {"freq_hz": [10.000001]}, "fe.csv": {"freq_hz": [10.000001]}}
    assert _differences(moved, recorded) == ["/fe.csv/freq_hz[0]: 10.000001, recorded 10.0"]
    fitted = {"diagnosis.json": {"params": {"k_N_per_m": 1443.1, "log_slope_per_rad": 0.0091}, "score": 0.1}}
    assert _differences({"diagnosis.json": {"params": {"k_N_per_m": 1444.6, "log_slope_per_rad": 0.0089},
                                            "score": 0.1001}}, fitted) == []
    assert len(_differences({"diagnosis.json": {"params": {"k_N_per_m": 1460.0, "log_slope_per_rad": 0.0079},
                                                "score": 0.1002}}, fitted)) == 3
    for changed in ("k 488 N/m at theta31 (0.30 %)", "k 488 N/mm at theta30 (0.30 %)",
                    "k 490 N/m at theta30 (0.30 %)", "k 488 N/m at theta30 (0.32 %)", "k 488 N/m"):
        assert _differences(changed, recorded["diagnosis.json"]["s"], "/stdout") == [
            f"/stdout: {changed!r}, recorded {recorded['diagnosis.json']['s']!r}"]


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
