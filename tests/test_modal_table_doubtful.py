"""Modal tables that were accepted but doubtful (adv27, REVIEW41): a 0 Hz mode was shown by ``compare``
with a blank error column (``diagnose`` refused it on its own), a negative damping ratio as -1.00 %, and
modes numbered against rising frequency (docs/formats.md, /work/shared/CONTRACT.md: "ascending
frequency") were paired as given.  The one checker (contract.table.ModalTable.from_frame) refuses them,
naming file, row, field and value, for every command that reads a modal table (exit 2, one line)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexmodal.app import main
from flexmodal.contract.errors import ContractError
from flexmodal.contract.table import ModalTable

GOOD = "config,mode,freq_hz,damping_ratio\nc1,1,10,0.01\nc1,2,20,0.02\nc2,1,12,0.01\n"
DOUBTFUL = {   # CSV text -> the message after the file name
    "zero": ("config,mode,freq_hz,damping_ratio\nc1,1,10,0.01\nc1,2,0,0.02\n",
             "row 3: freq_hz = 0 is not above 0 Hz"),
    "damping of -1": ("config,mode,freq_hz,damping_ratio\nc1,1,10,-1\nc1,2,20,0.02\n",
                      "row 2: damping_ratio = -1 is not above -1"),
    "falling": ("config,mode,freq_hz\nc1,2,10\nc2,1,5\nc1,1,20\n",
                "row 2: freq_hz = 10 of mode 2 is below the 20 Hz of mode 1 (row 4) in config 'c1'"),
}


@pytest.mark.parametrize("case", DOUBTFUL)
@pytest.mark.parametrize("where", ["compare measured", "compare predicted", "diagnose", "report"])
def test_every_command_refuses_a_doubtful_table_in_one_line(tmp_path: Path, capsys, case: str,
                                                            where: str) -> None:
    from flexmodal.fixtures.demo import DEMO_RIG

    bad, good = tmp_path / "bad.csv", tmp_path / "good.csv"
    bad.write_text(DOUBTFUL[case][0])
    good.write_text(GOOD)
    argv = {"compare measured": ["compare", str(bad), str(good)],
            "compare predicted": ["compare", str(good), str(bad)],
            "diagnose": ["diagnose", "--rig", str(DEMO_RIG), "--measured", str(bad),
                         "--out", str(tmp_path / "d")],
            "report": ["report", "--measured", str(bad), "--out", str(tmp_path / "r")]}[where]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"flexmodal: error: {bad}: {DOUBTFUL[case][1]}")


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["a", "b"]), st.sampled_from([0.0, 5.0, 10.0, 20.0]),
                          st.sampled_from([-1.0, -0.01, 0.0, 0.02])), min_size=1, max_size=6))
def test_a_table_is_read_exactly_when_its_modes_rise_above_0_hz_with_damping_above_minus_1(rows) -> None:
    """Independent rule: number each configuration's rows 1, 2, ... in the order given; the table is
    sound when every frequency is above 0, every damping ratio above -1 (between -1 and 0: a growing
    mode, kept as given, docs/formats.md), and each configuration's frequencies never fall from one mode
    to the next."""
    frame = pd.DataFrame(rows, columns=["config", "freq_hz", "damping_ratio"])
    frame.insert(1, "mode", frame.groupby("config").cumcount() + 1)
    sound = ((frame["freq_hz"] > 0).all() and (frame["damping_ratio"] > -1).all()
             and all(g["freq_hz"].is_monotonic_increasing for _, g in frame.groupby("config")))
    try:
        table = ModalTable.from_frame(frame, "t.csv")
    except ContractError as exc:
        assert not sound, exc
        assert str(exc).startswith("t.csv: row ")
    else:
        assert sound and len(table.frame) == len(frame)
