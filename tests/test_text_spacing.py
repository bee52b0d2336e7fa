"""What a person reads has one space between words: the diagnosis summary printed ``k_Nm_per_rad = 6616
 (95 % interval ...)`` with two.  The summaries of stored diagnoses are checked as printed, and every
message, table and summary string in the source (the class: any text formatter) by a scan of its string
literals; the live acquisition view aligns its columns with spaces on purpose and UFF blocks are a file
format, so those two are left out."""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data" / "diagnosis"
TWO_SPACES = re.compile(r"\S {2,}\S")
ALIGNED = {"daq/acquire.py",          # the live view's status lines and sparklines, aligned in columns
           "checked_io/uff_blocks.py",   # UFF: fixed-width records
           "fixtures/blind.py"}       # the blind benchmark's fixed-width case table


@pytest.mark.parametrize("name", sorted(p.name for p in DATA.glob("*.json")))
def test_a_diagnosis_summary_has_one_space_between_words(name, tmp_path):
    """Each stored diagnosis, given 95 % intervals of its parameters (those files predate them) as
    ``diagnose`` writes them, printed as ``diagnose`` prints it."""
    import json

    import flexmodal as fm

    doc = json.loads((DATA / name).read_text())
    params = doc["verdict"].get("params", {})   # none: no parameter
    doc["verdict"]["param_intervals"] = {k: [0.8 * v, 1.25 * v] for k, v in params.items()}
    (tmp_path / name).write_text(json.dumps(doc))
    text = fm.format_diagnosis(fm.read_diagnosis(tmp_path / name))
    assert [line for line in text.splitlines() if TWO_SPACES.search(line)] == []
    shown = re.findall(r"^  \w+ = \S+ \(95 % interval \S+ \.\. \S+\)$", text, re.M)   # indented
    assert len(shown) == len(params), text


def _strings(path: Path) -> list[tuple[int, str]]:
    """(line, text) of the string literals of a module that are not docstrings (f-string parts too)."""
    kinds = {tokenize.STRING, getattr(tokenize, "FSTRING_MIDDLE", tokenize.STRING)}
    found = []
    for tok in tokenize.generate_tokens(io.StringIO(path.read_text(encoding="utf-8")).readline):
        text = tok.string
        body = text.lstrip("rbfuRBFU")
        if tok.type in kinds and not body.startswith(('"""', "'''")):
            found.append((tok.start[0], body.strip("\"'")))   # without prefix, quotes: leading spaces indent
    return found


def test_no_message_or_table_string_holds_two_spaces_between_words():
    offenders = []
    for path in sorted(REPO.glob("*/**/*.py")) + sorted(REPO.glob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        if rel.split("/")[0] in {"tests", "benchmarks"} or rel in ALIGNED:
            continue
        offenders += [f"{rel}:{n}: {text[:60]}" for n, text in _strings(path) if TWO_SPACES.search(text)]
    assert offenders == []
