"""Installing flexmodal gives exactly one top-level import name, `flexmodal`, in an editable and in a
regular install, and breaks nothing next to PyPI's `fixtures` and `modal` packages (installed first,
as when flexmodal used to overwrite fixtures/__init__.py): every file of theirs keeps the hash their
RECORD gives, and both `flexmodal` and `python -m flexmodal` work.

Each case builds a fresh venv (``--system-site-packages``, so numpy & co. come from the machine) and
installs with ``--no-deps``; pip fetches the build backend and the two PyPI wheels from the package
registry, which ``pip install .`` needs anyway.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO

# What the installed environment reports, run by the venv's own python: the importable top-level
# names the flexmodal distribution provides (regular files, .pth path entries, and the names mapped by
# setuptools' editable finder), and the files of fixtures/modal whose hash differs from their RECORD.
PROBE = r"""
import base64, hashlib, importlib, importlib.metadata as md, json, sys
from pathlib import Path

def top_level(dist):
    names = set()
    for f in dist.files:
        parts = f.parts
        if parts[0].endswith(".dist-info") or parts[0] in ("..", "__pycache__"):
            continue
        if parts[0].endswith(".pth"):
            for line in Path(f.locate()).read_text().splitlines():
                if line.startswith("import "):
                    module = line.split()[1].rstrip(";")
                    names |= set(getattr(importlib.import_module(module), "MAPPING", {}))
                elif line.strip():
                    names |= {p.stem for p in Path(line.strip()).iterdir()
                              if (p / "__init__.py").is_file() or p.suffix == ".py"}
        elif parts[0].startswith("__editable__"):
            continue
        else:
            names.add(parts[0].removesuffix(".py"))
    return sorted(names)

def changed(name):
    dist = md.distribution(name)
    bad = []
    for f in dist.files:
        if f.hash is None:
            continue
        digest = hashlib.new(f.hash.mode, Path(f.locate()).read_bytes()).digest()
        if base64.urlsafe_b64encode(digest).rstrip(b"=").decode() != f.hash.value:
            bad.append(str(f))
    return bad

import importlib.util as iu
print(json.dumps({
    "flexmodal": top_level(md.distribution("flexmodal")),
    "changed": {n: changed(n) for n in ("fixtures", "modal")},
    "origins": {n: iu.find_spec(n).origin for n in ("fixtures", "modal", "flexmodal.fixtures",
                                                    "flexmodal.modal")},
}))
"""


def _run(args: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run(args, capture_output=True, text=True, timeout=600, check=True, **kw)


@pytest.fixture(scope="module")
def pypi_wheels(tmp_path_factory) -> list[Path]:
    """PyPI's fixtures and modal wheels (no dependencies)."""
    d = tmp_path_factory.mktemp("wheels")
    _run([sys.executable, "-m", "pip", "download", "--no-deps", "--quiet", "-d", str(d), "fixtures", "modal"])
    wheels = sorted(d.glob("*.whl"))
    assert [w.name.split("-")[0] for w in wheels] == ["fixtures", "modal"]
    return wheels


@pytest.fixture(scope="module")
def source_copy(tmp_path_factory) -> Path:
    """The tracked files of the repository (a build writes build/ and *.egg-info next to them)."""
    files = _run(["git", "ls-files", "-z"], cwd=REPO).stdout.split("\0")
    dest = tmp_path_factory.mktemp("src") / "flexmodal"
    for rel in filter(None, files):
        if (REPO / rel).is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / rel, dest / rel)
    return dest


@pytest.mark.slow
@pytest.mark.parametrize("editable", [True, False], ids=["editable", "regular"])
def test_one_import_name_next_to_pypi_fixtures_and_modal(editable, pypi_wheels, source_copy, tmp_path):
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)])
    py, flexmodal = venv / "bin" / "python", venv / "bin" / "flexmodal"
    pip = [str(py), "-m", "pip", "install", "--quiet", "--no-deps", "--disable-pip-version-check"]
    _run(pip + [str(w) for w in pypi_wheels])
    _run(pip + (["-e"] if editable else []) + [str(source_copy)], cwd=tmp_path)
    report = json.loads(_run([str(py), "-c", PROBE], cwd=tmp_path).stdout)
    assert report["flexmodal"] == ["flexmodal"]
    assert report["changed"] == {"fixtures": [], "modal": []}
    site = Path(report["origins"]["fixtures"]).parents[1]
    assert report["origins"]["fixtures"] == str(site / "fixtures" / "__init__.py")
    assert report["origins"]["modal"] == str(site / "modal" / "__init__.py")
    ours = source_copy if editable else site / "flexmodal"
    assert report["origins"]["flexmodal.fixtures"] == str(ours / "fixtures" / "__init__.py")
    assert report["origins"]["flexmodal.modal"] == str(ours / "modal" / "__init__.py")
    # PyPI's fixtures still works, and so does flexmodal, as a command and as a module
    _run([str(py), "-c", "import fixtures; assert fixtures.Fixture and fixtures.TempDir"], cwd=tmp_path)
    rig = source_copy / "examples" / "rigs" / "demo_arm.toml"
    (tmp_path / "poses.csv").write_text("config,pose.theta_deg\na,0\n")
    out = _run([str(flexmodal), "predict", str(rig), "--model", "fe", "--poses", "poses.csv", "--out",
                "fe.csv", "--modes", "2"], cwd=tmp_path).stdout
    assert out.strip() == "fe.csv" and (tmp_path / "fe.csv").read_text().count("\n") == 3
    assert "acquire" in _run([str(py), "-m", "flexmodal", "--help"], cwd=tmp_path).stdout
    if not editable:   # the templates and rigs travel with a regular install
        assert (site / "flexmodal" / "reports" / "templates" / "report.html").is_file()
        assert (site / "flexmodal" / "fixtures" / "rigs" / "demo_arm.toml").is_file()
