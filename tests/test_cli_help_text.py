"""What ``flexmodal CMD --help`` shows a user, option by option, and what the README and docs/ say of
the same options: every option explains itself (a help text; a metavar that says what to give, not
argparse's upper-cased option name; an optional choice says its default), and every option the docs
use in a ``flexmodal CMD ...`` command is one that CMD's help lists, with values it accepts."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from cli_help import command_paths, help_text

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
OPTION = re.compile(r"^  (-[-\w]+(?:, -[-\w]+)?)(?: (\S+))?(?:\s{2,}(\S.*))?$")
NAME = re.compile(r"(?<![\w-])(--[a-z][-a-z0-9]*)")


def _entries(path: tuple[str, ...]) -> dict[str, tuple[str, str]]:
    """{option: (metavar, help)} of ``flexmodal PATH --help`` (help lines joined)."""
    found: dict[str, list[str]] = {}
    last = None
    for line in help_text(*path).splitlines():
        if m := OPTION.match(line):
            last = m.group(1).split(", ")[-1]
            found[last] = [m.group(2) or "", m.group(3) or ""]
        elif last is not None and line.startswith("      "):
            found[last][1] = f"{found[last][1]} {line.strip()}".strip()
        else:
            last = None
    return {k: (v[0], v[1]) for k, v in found.items()}


def _optional(path: tuple[str, ...]) -> set[str]:
    """The options the usage line shows in brackets (not required)."""
    usage = help_text(*path).split("\n\n")[0]
    return set(re.findall(r"\[(--[a-z][-a-z0-9]*)", usage))


PATHS = [(), *command_paths()]


@pytest.mark.parametrize("path", PATHS, ids=lambda p: " ".join(p) or "flexmodal")
def test_every_option_says_what_to_give_and_its_default(path: tuple[str, ...]) -> None:
    entries = _entries(path)
    assert entries, path
    optional = _optional(path)
    for option, (metavar, text) in entries.items():
        assert text, f"flexmodal {' '.join(path)} {option}: no help text"
        assert metavar != option.lstrip("-").upper().replace("-", "_"), \
            f"flexmodal {' '.join(path)} {option} {metavar}: argparse's default metavar says nothing"
        if metavar.startswith("{") and option in optional:
            assert "default" in text, f"flexmodal {' '.join(path)} {option}: which choice is the default?"


def _doc_commands(docs: list[Path]) -> list[tuple[str, str, str]]:
    """(file, command, the rest of its line) of every ``flexmodal CMD ...`` in ``docs``, continuation
    lines (``\\``) joined, up to the next command, shell separator or code span end."""
    commands = {" ".join(p) for p in command_paths()}
    found = []
    for doc in docs:
        text = doc.read_text(encoding="utf-8").replace("\\\n", " ")
        for m in re.finditer(r"flexmodal ((?:sim )?[a-z]+)(?=([^`\n]*))", text):
            if m.group(1) in commands:
                rest = re.split(r"flexmodal |&&|;|\|\||\)\s", m.group(2))[0]
                found.append((doc.name, m.group(1), rest))
    return found


def _doc_mistakes(found: list[tuple[str, str, str]]) -> list[str]:
    """The options of ``found`` that their command's help does not list, and the ``--opt a|b`` whose
    values are not all among the option's choices."""
    helps = {c: help_text(*c.split()) for c in {c for _, c, _ in found}}
    wrong = []
    for doc, command, rest in found:
        listed = set(NAME.findall(helps[command])) | {"--help"}
        wrong += [f"{doc}: flexmodal {command} {o}: not in its --help" for o in NAME.findall(rest)
                  if o not in listed]
        for option, values in re.findall(r"(--[a-z][-a-z0-9]*)[ =]([\w-]+(?:\\?\|[\w-]+)+)", rest):
            offered = re.search(re.escape(option) + r" \{([^}]*)\}", helps[command])
            if offered and not set(values.replace("\\", "").split("|")) <= set(offered.group(1).split(",")):
                wrong.append(f"{doc}: flexmodal {command} {option} {values}: offers {offered.group(1)}")
    return wrong


def test_the_docs_use_only_options_the_help_lists_with_values_it_accepts() -> None:
    found = _doc_commands(DOCS)
    assert len(found) > 40 and {c for _, c, _ in found} >= {"demo", "acquire", "frf", "identify", "predict",
                                                            "compare", "diagnose", "report", "sim serve"}
    assert _doc_mistakes(found) == []


def test_the_docs_check_catches_an_option_the_help_lacks_and_a_value_it_refuses(tmp_path: Path) -> None:
    doc = tmp_path / "x.md"
    doc.write_text("`flexmodal frf run.h5 --no-such 3 --averaging linear|cubic --workers 0`\n"
                   "flexmodal sim serve --protocol can \\\n  --test moving && flexmodal identify x --run a\n")
    found = _doc_commands([doc])
    assert [c for _, c, _ in found] == ["frf", "sim serve", "identify"]
    assert _doc_mistakes(found) == ["x.md: flexmodal frf --no-such: not in its --help",
                                    "x.md: flexmodal frf --averaging linear|cubic: offers linear,exponential"]
