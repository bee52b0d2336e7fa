"""``diagnose`` said one line and then nothing for the whole ranking (12 s on seed 003): it now says each
stage on stderr (the fits of single effects, of pairs, the cross-validation, the verdict), with a
transient bar of the fits on a terminal, as ``identify`` does; ``--quiet`` silences it, stdout keeps
only the result."""

from __future__ import annotations

import io
import re
from pathlib import Path

from flexmodal.app import main

REPO = Path(__file__).resolve().parents[1]
ARGV = ["diagnose", "--rig", str(REPO / "examples" / "rigs" / "seed003_two_link.toml"),
        "--measured", str(REPO / "examples" / "measured" / "seed003_table3_f1f2.csv"),
        "--holdout", "theta30,theta90,theta150", "--effects", "joint_stiffness,tip_mass"]


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_diagnose_tells_each_stage_and_shows_a_bar_on_a_terminal(tmp_path, capsys, monkeypatch):
    term = Terminal()
    monkeypatch.setattr("sys.stderr", term)
    assert main([*ARGV, "--out", str(tmp_path / "d")]) == 0
    said = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", term.getvalue())    # without the terminal's codes
    stages = re.findall(r"diagnose: (fitting \d+ single effects|fitting \d+ pairs? .*|cross-validating "
                        r"the candidates that fit best|fitting triples of effects .*|choosing the verdict)$",
                        said, re.M)
    kinds = [next(k for k in ("single", "pair", "cross", "triples", "verdict") if k in s) for s in stages]
    assert kinds[0] == "single" and kinds[-1] == "verdict" and "cross" in kinds, said   # in this order
    assert kinds.index("pair") < kinds.index("cross"), said
    assert "fitting single effects" in said and "100%" in said          # the bar, on a terminal
    out = capsys.readouterr().out
    assert out.startswith("verdict: ") and "diagnose:" not in out      # stdout: the result alone
    term.seek(0)
    term.truncate()                   # --quiet: one effect (no pairs) still has stages to silence
    assert main(["--quiet", *ARGV[:-1], "joint_stiffness", "--out", str(tmp_path / "q")]) == 0
    assert capsys.readouterr().out.startswith("verdict: ")               # it ran, to the result
    assert term.getvalue() == ""
