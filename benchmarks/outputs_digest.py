"""Record the outputs of the demo and of the README tour, to compare two versions of the code (a
refactoring must leave them identical).

    python benchmarks/outputs_digest.py record DIR      # run everything into DIR (about 1-5 min)
    python benchmarks/outputs_digest.py compare A B      # list the files whose content differs

``record`` runs, through the ``flexmodal`` command of the running interpreter: ``demo``; the README's
seed 003 tour (``predict``, ``compare``, ``diagnose --holdout``); ``frf``, ``identify`` (lscf with
``--uff``, peak, output-only) on a copy of the demo's runs; ``predict`` with every model on the demo
arm.  It keeps every CSV, JSON, UFF file and stdout, and a digest of every FRF group (``frf.json``).
To record another version, put its tree first on ``PYTHONPATH`` (e.g. ``git archive REV`` unpacked
into ``T/flexmodal``, then ``PYTHONPATH=T python benchmarks/outputs_digest.py record DIR``).

The demo's ``theta30-impact`` run goes through the serial stack with a simulator on a pty: where the
acquisition starts in the simulator's stream depends on timing (``first_index`` and the trigger rows
differ from run to run), and everything computed from it (that configuration's modes, the diagnosis)
differs with it.  ``compare`` says so when the two recordings' serial runs differ; the comparison of
two versions is meaningful for those outputs only when they do not.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

SUFFIXES = (".csv", ".json", ".stdout", ".uff")


def _run(out: Path, name: str, args: list[str], log: dict) -> None:
    fm = str(Path(sys.executable).parent / "flexmodal")
    done = subprocess.run([fm, *args], capture_output=True, text=True, timeout=1800, cwd=out)
    repo = str(Path(_package_dir()))
    (out / f"{name}.stdout").write_text(done.stdout.replace(str(out), "OUT").replace(repo, "REPO"))
    log[name] = done.returncode


def _package_dir() -> str:
    import flexmodal

    return os.path.dirname(flexmodal.__file__)


def _frf_digest(path: Path) -> dict:
    import h5py
    import numpy as np

    found: dict = {}
    with h5py.File(path, "r") as f:
        def visit(name, obj):
            if "/frf" not in "/" + name:
                return
            if isinstance(obj, h5py.Dataset):
                found[name] = hashlib.sha256(np.ascontiguousarray(obj[()]).tobytes()).hexdigest()
            found[name + "@attrs"] = {k: str(v) for k, v in obj.attrs.items() if k != "provenance"}
        f.visititems(visit)
    return found


def record(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    repo, log = Path(_package_dir()), {}
    measured = str(repo / "examples/measured/seed003_table3_f1f2.csv")
    seed_rig = str(repo / "examples/rigs/seed003_two_link.toml")
    demo_rig = str(repo / "fixtures/rigs/demo_arm.toml")
    _run(out, "demo", ["demo", "--out", "demo", "--quiet"], log)
    _run(out, "tour_predict", ["predict", seed_rig, "--model", "fe", "--poses", measured, "--out", "fe.csv",
                               "--modes", "2"], log)
    _run(out, "tour_compare", ["compare", measured, "fe.csv", "--format", "md"], log)
    _run(out, "tour_diagnose", ["diagnose", "--rig", seed_rig, "--measured", measured, "--out", "diag",
                                "--holdout", "theta30,theta90,theta150", "--quiet"], log)
    shutil.copy(out / "demo" / "runs.h5", out / "runs_cli.h5")
    _run(out, "cli_frf", ["frf", "runs_cli.h5", "--workers", "0", "--quiet"], log)
    _run(out, "cli_identify", ["identify", "runs_cli.h5", "--out", "ident.csv", "--uff", "ident.uff",
                               "--fmax", "450", "--quiet"], log)
    _run(out, "cli_identify_peak", ["identify", "demo/runs.h5", "--out", "peak.csv", "--method", "peak",
                                    "--fmax", "450", "--quiet"], log)
    _run(out, "cli_identify_oma", ["identify", "demo/operational.h5", "--out", "oma.csv", "--fmin", "20",
                                   "--fmax", "450", "--quiet"], log)
    _run(out, "cli_compare_csv", ["compare", "demo/modes.csv", "demo/fe.csv", "--format", "csv"], log)
    for model in ("fe", "assumed-modes", "lumped-mass", "blevins"):
        argv = ["predict", demo_rig, "--model", model, "--poses", "demo/modes.csv", "--out",
                f"demo_{model}.csv", "--modes", "3"]
        _run(out, f"demo_predict_{model}", argv, log)
    (out / "rc.json").write_text(json.dumps(log, indent=1))
    digest = {p: _frf_digest(out / p) for p in ("demo/runs.h5", "demo/operational.h5", "runs_cli.h5")}
    (out / "frf.json").write_text(json.dumps(digest, indent=1, sort_keys=True))


def _serial_run(folder: Path) -> str:
    import h5py

    with h5py.File(folder / "demo" / "runs.h5", "r") as f:
        g = f["runs/theta30-impact"]
        return f"{g.attrs.get('first_index')} {[int(e['sample_index']) for e in g['events'][()]]}"


def compare(a: Path, b: Path) -> int:
    differ = 0
    for path in sorted(p for p in a.rglob("*") if p.suffix in SUFFIXES):
        rel = path.relative_to(a)
        if not (b / rel).is_file() or (b / rel).read_bytes() != path.read_bytes():
            print(f"differs: {rel}")
            differ += 1
    if _serial_run(a) != _serial_run(b):
        print("note: the serially acquired demo run started elsewhere in the simulator's stream "
              f"({_serial_run(a)} vs {_serial_run(b)}): its modes and the diagnosis differ with it")
    print(f"{differ} files differ")
    return 1 if differ else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "record":
        record(Path(sys.argv[2]).resolve())
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(Path(sys.argv[2]), Path(sys.argv[3])))
    else:
        sys.exit(__doc__)
