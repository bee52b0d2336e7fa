"""One percent format in what people read: three significant digits, a space, ``%`` (``43.1 %``), in
the diagnose summary, the verdict words, the demo and the self-check (checked_io.percent)."""

from __future__ import annotations

import re
from pathlib import Path

from flexmodal.checked_io.percent import percent

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data" / "diagnosis"
# a fraction written by Python's own percent format (``{x:.2%}`` -> ``43.08%``, no space)
PYTHON_PERCENT = re.compile(r":[+ ]?\d*(\.\d+)?%\}")


def test_percent_is_three_significant_digits_a_space_and_the_sign_when_asked():
    assert [percent(x) for x in (0.4308, 0.0328, 0.005, 1.0, 0.000005)] == \
        ["43.1 %", "3.28 %", "0.5 %", "100 %", "0.0005 %"]
    assert percent(0.054, signed=True) == "+5.4 %" and percent(-0.032, signed=True) == "-3.2 %"


def test_diagnose_summary_writes_percent_as_the_rest_of_its_output():
    import flexmodal as fm

    text = fm.format_diagnosis(fm.read_diagnosis(DATA / "demo.json"))
    assert text.splitlines()[0] == "verdict: joint_stiffness at elbow; held-out RMS 13.4 % -> 0.602 %"
    assert not re.search(r"\d%", text)


def test_no_module_people_read_formats_a_percent_without_the_space():
    offenders = []
    for path in sorted(REPO.glob("*/**/*.py")) + sorted(REPO.glob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        # benchmarks write their own docs tables
        if rel.split("/")[0] in {"tests", "benchmarks"}:
            continue
        offenders += [f"{rel}:{n}" for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
                      if PYTHON_PERCENT.search(line)]
    assert offenders == []
