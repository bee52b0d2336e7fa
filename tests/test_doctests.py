"""The Examples of the docstrings run: every module of the package whose docstrings hold ``>>>`` lines
is run through doctest (numpydoc Examples sections are doctests) from the repository's root, so a
documented example that stops working fails the suite."""

from __future__ import annotations

import doctest
import importlib

import pytest
from conftest import REPO

PACKAGES = tuple(sorted(init.parent.name for init in REPO.glob("*/__init__.py")))  # every sub-package


def _modules_with_examples() -> list[str]:
    paths = [p for p in REPO.glob("*.py")] + [p for d in PACKAGES for p in (REPO / d).rglob("*.py")]
    names = []
    for path in sorted(paths):
        if ">>> " not in path.read_text(encoding="utf-8"):
            continue
        rel = path.relative_to(REPO).with_suffix("")
        parts = [part for part in rel.parts if part != "__init__"]
        names.append(".".join(["flexmodal", *parts]))
    return names


def test_the_walk_finds_the_documented_modules():
    assert {"checked_io", "contract", "cli", "daq", "modal", "models", "compare", "reports",
            "fixtures"} <= set(PACKAGES)
    assert {"flexmodal.checked_io.registry", "flexmodal.api"} <= set(_modules_with_examples())


@pytest.mark.parametrize("name", _modules_with_examples())
def test_docstring_examples_run(name, monkeypatch):
    monkeypatch.chdir(REPO)   # the Examples use the repository's examples/ as a user's clone has them
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                             verbose=False, report=True)
    assert result.attempted > 0 and result.failed == 0, result


# public functions without a run Examples section, each with where it is run end to end instead
NO_EXAMPLES: dict[str, str] = {}


def test_every_public_api_function_has_a_numpydoc_docstring():
    """Parameters (with units), Returns and Examples (run above) for every function of flexmodal.api."""
    import inspect

    from flexmodal import api

    missing = {}
    for name in api.__all__:
        func = getattr(api, name)
        if not inspect.isfunction(func):
            continue
        doc = inspect.getdoc(func) or ""
        wanted = ("Parameters", "Returns") + (() if name in NO_EXAMPLES else ("Examples",))
        lacks = [s for s in wanted if f"\n{s}\n{'-' * len(s)}\n" not in doc]
        if lacks:
            missing[name] = lacks
    assert missing == {}


def test_every_public_api_class_documents_each_field():
    """Every class flexmodal.api exports documents each of its fields (a dataclass's) or constructor
    arguments in a numpydoc Parameters or Attributes section (``name : type`` and a description):
    Faults, FrfResult, RunsFailed and Thresholds had none."""
    import dataclasses
    import inspect

    from flexmodal import api

    undocumented = {}
    for name in api.__all__:
        cls = getattr(api, name)
        if not inspect.isclass(cls):
            continue
        if dataclasses.is_dataclass(cls):
            names = [f.name for f in dataclasses.fields(cls)]
        else:
            params = inspect.signature(cls.__init__).parameters.values()
            names = [p.name for p in params if p.name != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD,
                                                                                p.KEYWORD_ONLY)]
        doc = inspect.getdoc(cls) or ""
        entries = {n.strip() for line in doc.splitlines() if " : " in line and not line.startswith(" ")
                   for n in line.split(" : ")[0].split(",")}
        sections = [s for s in ("Parameters", "Attributes") if f"\n{s}\n{'-' * len(s)}\n" in doc]
        lacking = [n for n in names if n not in entries or not sections]
        if lacking:
            undocumented[name] = lacking
    assert undocumented == {}


def test_every_public_api_example_is_one_the_doctest_run_collects():
    """The Examples of each function of flexmodal.api (those defined there, or in a module the walk
    runs) are doctests that ``doctest.testmod`` of their module finds, not text it skips."""
    import inspect

    from flexmodal import api

    walked = set(_modules_with_examples())
    uncollected = []
    for name in api.__all__:
        func = getattr(api, name)
        if not inspect.isfunction(func) or name in NO_EXAMPLES:
            continue
        module = importlib.import_module(func.__module__)
        found = {t.name.rsplit(".", 1)[-1]: len(t.examples) for t in doctest.DocTestFinder().find(module)}
        if func.__module__ not in walked or not found.get(func.__name__):
            uncollected.append(name)
    assert uncollected == []


def _section(doc: str, title: str) -> list[str]:
    """The lines of a numpydoc section (up to the next section's underlined title)."""
    lines = doc.splitlines()
    try:
        start = lines.index(title) + 2
    except ValueError:
        return []
    end = next((i for i in range(start, len(lines) - 1) if set(lines[i + 1]) == {"-"} and lines[i]),
               len(lines))
    return lines[start:end]


def test_every_public_api_docstring_documents_its_signature_in_numpydoc_form():
    """For each function and record class of flexmodal.api: its Parameters name every argument of
    the signature in order, each ``name : type`` (no bare name lists), and each Returns entry has a
    description line (numpydoc's PR01-PR04 and RT03 checks, without numpydoc)."""
    import inspect

    from flexmodal import api

    wrong = {}
    for name in api.__all__:
        obj = getattr(api, name)
        if not (inspect.isfunction(obj) or inspect.isclass(obj)) or obj.__module__ != "flexmodal.api":
            continue
        doc = inspect.getdoc(obj) or ""
        params = [p for p in _section(doc, "Parameters") if p and not p.startswith(" ")]
        documented = [n.strip() for p in params for n in p.split(" : ")[0].split(",")]
        signature = [("*" if p.kind is p.VAR_POSITIONAL else "**" if p.kind is p.VAR_KEYWORD else "") + p.name
                     for p in inspect.signature(obj).parameters.values() if p.name != "self"]
        untyped = [p for p in params if " : " not in p and not p.startswith("*")]
        returns = _section(doc, "Returns")
        bare = [r for i, r in enumerate(returns) if r and not r.startswith(" ")
                and not (i + 1 < len(returns) and returns[i + 1].startswith(" "))]
        if documented != signature or untyped or bare:
            wrong[name] = (documented, signature, untyped, bare)
    assert wrong == {}
