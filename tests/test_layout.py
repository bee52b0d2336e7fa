"""The layout of docs/architecture.md, checked on the source (ast), as a rule over folders (no file
exempted by its name): each folder of the package imports only the folders listed for it in ALLOWED,
at run time (imports under ``if TYPE_CHECKING`` are types only).  ``modal`` and ``models`` are siblings:
neither imports the other, both write the modal-table contract (``contract``).  The root modules stand
with a folder: ``api.py`` and the root ``__init__.py`` (which re-exports the API and wires the built-in
simulator launcher) are the API; ``app.py`` and ``__main__.py`` are the shell with ``cli/``, which imports
only ``flexmodal.api`` and the kit's argparse types, error family and registry shape (SHELL_KIT).  Also:
reports renders and computes nothing; docs stand alone (no reference to a contract file that is not in
the repository, every docs path named in --help exists)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from cli_help import command_paths, help_text
from conftest import REPO

FOLDERS = ("checked_io", "contract", "daq", "modal", "models", "compare", "reports", "fixtures", "cli")
_BELOW_COMPARE = {"checked_io", "contract", "daq", "modal", "models"}
ALLOWED = {
    "checked_io": set(),
    "contract": {"checked_io"},
    "daq": {"checked_io"},
    "modal": {"checked_io", "contract", "daq"},
    "models": {"checked_io", "contract", "daq"},
    "compare": _BELOW_COMPARE,
    "reports": _BELOW_COMPARE | {"compare"},
    "fixtures": _BELOW_COMPARE | {"compare", "reports"},
    "api": _BELOW_COMPARE | {"compare", "reports", "fixtures"},
    "cli": {"api", "app"},   # the one shell: parse argv, call flexmodal.api, print
}
ALLOWED["app"] = ALLOWED["cli"] | {"cli"}
# what the shell may take from the kit beside the API: argparse types, the error family it turns into one
# line, and the registry shape of its command registry (no I/O: every output is written by the API)
SHELL_KIT = {"flexmodal.checked_io.options", "flexmodal.checked_io.errors", "flexmodal.checked_io.registry"}
ROOT = {"api.py": "api", "__init__.py": "api", "app.py": "app", "__main__.py": "app"}
# what reports/ may import from below it: data types and small display helpers, no solver
REPORT_IMPORTS = {"flexmodal.compare.tables", "flexmodal.contract.table", "flexmodal.contract.mac",
                  "flexmodal.modal.peaks", "flexmodal.checked_io.text", "flexmodal.checked_io.output",
                  "flexmodal.checked_io.uff_blocks",   # a geometry file read as whole UFF datasets
                  "flexmodal.compare.result", "flexmodal.compare.errors",
                  "flexmodal.compare.verdict_text",  # the verdict in words: text from a record, no solving
                  "flexmodal.modal.stability",  # the stability criteria a caption quotes: constants only
                  "flexmodal.modal.order_note",  # the order note's words a caption reads back: constants only
                  "flexmodal.checked_io.errors", "flexmodal.checked_io.registry"}   # the diagnosis records


def _sources() -> list[Path]:
    """Every module of the installed package (tests, benchmarks and any build/ output are not part
    of it)."""
    return sorted(p for p in REPO.rglob("*.py") if p.relative_to(REPO).parts[0] in FOLDERS
                  or str(p.relative_to(REPO)) in ROOT)


def _layer(rel: Path) -> str:
    """The folder a module stands in (a root module: the one it stands with, ROOT)."""
    return ROOT[rel.name] if len(rel.parts) == 1 else rel.parts[0]


def _target(module: str) -> str:
    """The folder of an imported flexmodal module (``flexmodal.api`` and root names: api)."""
    part = module.split(".")[1]
    return part if part in FOLDERS or part == "app" else "api"


def _runtime_imports(path: Path) -> list[str]:
    """flexmodal modules imported by ``path`` at run time (imports under ``if TYPE_CHECKING`` left out)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    typing_only = {id(n) for node in ast.walk(tree)
                   if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING"
                   for n in ast.walk(node)}
    found = []
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            folder = REPO.joinpath(*node.module.split(".")[1:])   # ``from package import module``: the module
            subs = [f"{node.module}.{a.name}" for a in node.names
                    if node.module == "flexmodal" or (folder / f"{a.name}.py").is_file()]
            found += subs or [node.module]
    return [m for m in found if m.startswith("flexmodal.")]


def _upward(path: Path, rel: Path | None = None) -> list[str]:
    """Imports of ``path`` (standing at ``rel`` in the repository) that its folder may not make."""
    rel = rel or path.relative_to(REPO)
    mine = _layer(rel)
    kit = SHELL_KIT if mine in ("cli", "app") else set()
    return [m for m in _runtime_imports(path)
            if _target(m) != mine and _target(m) not in ALLOWED[mine] and m not in kit]


@pytest.mark.parametrize("rel", [str(p.relative_to(REPO)) for p in _sources()])
def test_no_module_imports_up_the_data_flow(rel):
    assert _upward(REPO / rel) == []


def test_the_walk_sees_every_folder_and_catches_a_forbidden_import(tmp_path):
    assert {_layer(p.relative_to(REPO)) for p in _sources()} == set(ALLOWED)
    probe = tmp_path / "probe.py"   # a modal module importing a model is caught, a typing-only import not
    probe.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import flexmodal.compare\n"
                     "def f():\n    from flexmodal.models.rig import Rig\n    from flexmodal import api\n")
    assert _upward(probe, Path("modal/probe.py")) == ["flexmodal.models.rig", "flexmodal.api"]
    assert _upward(probe, Path("models/probe.py")) == ["flexmodal.api"]
    probe.write_text("from flexmodal.modal.identify import identify\n")
    assert _upward(probe, Path("models/probe.py")) == ["flexmodal.modal.identify"]   # siblings
    assert _upward(probe, Path("compare/probe.py")) == []
    probe.write_text("def f():\n    from flexmodal.checked_io.output import output_file\n"
                     "    from flexmodal.checked_io import options\n    from flexmodal.api import identify\n")
    assert _upward(probe, Path("cli/probe.py")) == ["flexmodal.checked_io.output"]   # the shell: API only


def test_reports_renders_and_solves_nothing():
    for path in sorted((REPO / "reports").glob("*.py")):
        below = [m for m in _runtime_imports(path) if not m.startswith("flexmodal.reports")]
        assert set(below) <= REPORT_IMPORTS, (path.name, sorted(set(below) - REPORT_IMPORTS))


def _help_texts() -> str:
    """--help of flexmodal and of every sub-command, nested ones included."""
    return "\n".join(help_text(*path) for path in [(), *command_paths()])


def test_docs_stand_alone():
    tracked = [p for p in REPO.rglob("*") if p.suffix in (".py", ".md") and "tests" not in p.parts
               and ".egg-info" not in str(p)]
    assert [str(p.relative_to(REPO)) for p in tracked if "CONTRACT" in p.read_text(encoding="utf-8")] == []
    helps = _help_texts()
    named = set(re.findall(r"docs/[\w-]+\.md", helps))
    assert {"docs/formats.md", "docs/hdf5-format.md"} <= named
    for doc in named:
        assert (REPO / doc).is_file(), doc
    prose = "\n".join(p.read_text(encoding="utf-8") for p in (REPO / "docs").glob("*.md"))
    for link in set(re.findall(r"\]\(([\w-]+\.md)(?:#[\w-]+)?\)", prose)):
        assert (REPO / "docs" / link).is_file(), link
    formats = (REPO / "docs" / "formats.md").read_text(encoding="utf-8")
    for heading in ("## Command conventions", "## Modal table CSV", "## Rig TOML", "## Diagnosis JSON"):
        assert heading in formats


def test_examples_hold_no_symlinks_and_the_demo_rig_copy_is_the_fixture():
    """examples/ works from a plain copy of the tree (zip, Windows): no links; the demo arm users read
    there is byte for byte the one the demo simulates (copy fixtures/rigs/demo_arm.toml when it changes)."""
    assert [str(p) for p in (REPO / "examples").rglob("*") if p.is_symlink()] == []
    assert ((REPO / "examples" / "rigs" / "demo_arm.toml").read_bytes()
            == (REPO / "fixtures" / "rigs" / "demo_arm.toml").read_bytes())


def test_every_package_error_is_one_of_the_family():
    """One error family: each package's error type subclasses FlexmodalError, which the CLI catches."""
    import importlib

    from flexmodal.checked_io.errors import FlexmodalError

    found = {}
    for path in sorted(REPO.glob("*/errors.py")):
        module = importlib.import_module(f"flexmodal.{path.parent.name}.errors")
        found |= {name: obj for name, obj in vars(module).items() if isinstance(obj, type)
                  and issubclass(obj, Exception) and obj.__module__ == module.__name__}
    assert set(found) - {"FlexmodalError"} == {"DaqError", "ModalError", "ModelError", "CompareError",
                                               "ReportError", "FixtureError", "ContractError"}
    assert all(issubclass(cls, FlexmodalError) for cls in found.values())


def _module_name(path: Path) -> str:
    rel = path.relative_to(REPO).with_suffix("")
    return ".".join(("flexmodal", *rel.parts)).removesuffix(".__init__")


def _module_level_imports(path: Path) -> set[str]:
    """flexmodal modules imported at module level, typing-only ones included (an ``if`` at top level)."""
    found = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        for n in ast.walk(node) if isinstance(node, ast.If | ast.Import | ast.ImportFrom) else ():
            if isinstance(n, ast.Import):
                found |= {a.name for a in n.names}
            elif isinstance(n, ast.ImportFrom) and n.module and n.level == 0:
                found.add(n.module)
    return {m for m in found if m.startswith("flexmodal.")}


def test_no_import_cycle_even_for_types():
    """No module reaches itself through module-level imports (typing-only ones count: such a cycle is
    a record living in the wrong module, as daq.session.Device did for daq.devices)."""
    graph = {_module_name(p): _module_level_imports(p) for p in _sources()}
    cycles, state = [], {}

    def visit(module: str, path: list[str]) -> None:
        state[module] = "open"
        for nxt in sorted(graph.get(module, ())):
            if state.get(nxt) == "open":
                cycles.append(path[path.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, [*path, nxt])
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    assert cycles == []
