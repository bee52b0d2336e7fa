"""Odd inputs of a ninth adversarial pass (stop 40, 27 Nov).  A config or run id holding a run of more
than 4300 digits stopped every modal-table read and every run listing with a traceback, exit 1 (the
natural order converted each digit run to an int, and Python refuses to convert more than 4300 digits);
so did a sensor of 5000 digits before '+z' in report --geometry and in a UFF export (read as a node).
An FRF group with ``nfft`` above frf --nfft's 2^24 (an impact record or a sweep segment is one FFT as
long as the hit or the sweep) was written by ``frf`` and then refused by ``identify``; the refusal quoted
the number as text ('16777218').  Now the natural order compares digit runs without converting them,
one bound (the longest record) is checked when the group is written and when it is read, and stored
numbers are shown as numbers.  Small files, in-process CLI, about 4 s in all."""

from __future__ import annotations

import dataclasses
import re
from decimal import Decimal
from pathlib import Path

import h5py
import pytest
from conftest import REPO, one_line
from hypothesis import given
from hypothesis import strategies as st
from test_odd_inputs_stop39 import _run

from flexmodal.app import main
from flexmodal.checked_io.text import natural_key
from flexmodal.contract.table import ModalTable
from flexmodal.daq.errors import DaqError
from flexmodal.daq.run_schema import MAX_EVENT_SAMPLES, check_run_file
from flexmodal.daq.store import list_runs
from flexmodal.modal.errors import ModalError
from flexmodal.modal.runs_io import read_frf, write_frf

ONES, NINES = "1" * 5000, "9" * 4999   # 5000 ones are worth more than 4999 nines


# -- natural order: digit runs of any length, ordered by value -------------------------------------------
def _split_numbers(text: str) -> list[str]:
    """The rule of docs (natural order) read by a scanner written here, not the code's pattern: a run of
    decimal digits with an optional ``.digits`` part is a number, signed when the ``-`` right before it
    opens the name or follows a character that is neither a letter nor a digit; text at even places,
    numbers at odd places."""
    parts, start, i = [], 0, 0
    while i < len(text):
        if not text[i].isdecimal():
            i += 1
            continue
        end = i
        while end < len(text) and text[end].isdecimal():
            end += 1
        if end + 1 < len(text) and text[end] == "." and text[end + 1].isdecimal():
            end += 1
            while end < len(text) and text[end].isdecimal():
                end += 1
        sign = i >= 1 and text[i - 1] == "-" and (i == 1 or not text[i - 2].isalnum())
        parts += [text[start:i - sign], text[i - sign:end]]
        start = i = end
    return [*parts, text[start:]]


def _value_key(text: str) -> list:
    """The reference: the numbers (``_split_numbers``) converted to Decimal (fine at these lengths), then
    the text itself."""
    return [[Decimal(t) if k % 2 else t for k, t in enumerate(_split_numbers(text))], text]


@given(st.lists(st.text(st.sampled_from("0123456789ab-.\u0663\u0660\u06f5"), max_size=10), min_size=2,
                max_size=8))
def test_the_natural_order_is_the_order_of_the_numbers_values(names: list[str]) -> None:
    """Arabic-Indic digits (U+0663 is 3) are decimal digits too: their values are compared (signed
    decimals since stop 41, tests/test_natural_key.py)."""
    assert sorted(names, key=natural_key) == sorted(names, key=_value_key)


def test_a_config_of_5000_digits_is_read_and_compared(tmp_path: Path, capsys) -> None:
    path = tmp_path / "m.csv"
    rows = [f"c{ONES},1,30", f"c{NINES},1,31", "c7,1,32", "c07,1,33"]
    path.write_text("config,mode,freq_hz\n" + "\n".join(rows) + "\n", encoding="utf-8")
    assert ModalTable.read_csv(path).configs == ["c07", "c7", f"c{NINES}", f"c{ONES}"]
    assert main(["compare", str(path), str(path)]) == 0
    out, err = capsys.readouterr()
    assert f"| c{ONES} | 1 | 30.00 |" in out and err == ""


def test_a_run_id_of_5000_digits_is_listed_and_then_named(tmp_path: Path, capsys) -> None:
    """Listing orders it (it was the traceback); the run itself is refused by the run-id rule (at most
    255 characters), in one line, and the other runs' FRFs are computed."""
    path = _run(tmp_path / "runs.h5")
    with h5py.File(path, "r+") as f:
        for name in (f"t{ONES}", f"t{NINES}", "t7"):
            f.copy("runs/r1", f"runs/{name}")
    assert list_runs(path) == ["r1", "t7", f"t{NINES}", f"t{ONES}"]
    with h5py.File(path, "r+") as f:
        del f[f"runs/t{NINES}"]
    assert main(["--quiet", "frf", str(path)]) == 2
    one_line(capsys, 2, f"run 't{ONES[:40]}", "cannot name a run", "at most 255 characters", "skipped")
    assert read_frf(path, "r1") is not None and read_frf(path, "t7") is not None


# -- a stored FRF group's whole numbers: one bound on write and on read ----------------------------------
def test_an_frf_longer_than_the_nfft_option_is_written_and_read_back(tmp_path: Path) -> None:
    """A sweep of 2^24 + 2 samples is one segment of that length (modal.compute): beyond --nfft's 2^24."""
    path = _run(tmp_path / "r.h5", frf=True)
    result = read_frf(path, "r1")
    write_frf(path, "r1", dataclasses.replace(result, nfft=2**24 + 2))
    assert read_frf(path, "r1").nfft == 2**24 + 2


@pytest.mark.parametrize("key, value, bound", [("nfft", MAX_EVENT_SAMPLES + 1, MAX_EVENT_SAMPLES),
                                               ("nfft", 0, MAX_EVENT_SAMPLES),
                                               ("n_averages", 2**40 + 1, 2**40)])
def test_a_whole_number_beyond_the_bound_is_refused_on_write_and_on_read(tmp_path: Path, key: str,
                                                                          value: int, bound: int) -> None:
    path = _run(tmp_path / "r.h5", frf=True)
    before = path.read_bytes()
    said = f"r.h5: run 'r1': frf group: attribute {key} = {value} is not a whole number from 1 to {bound}"
    with pytest.raises(ModalError, match=re.escape(said) + "; nothing written$"):
        write_frf(path, "r1", dataclasses.replace(read_frf(path, "r1"), **{key: value}))
    assert path.read_bytes() == before
    with h5py.File(path, "r+") as f:
        f["runs/r1/frf"].attrs[key] = value
    with pytest.raises(ModalError, match=re.escape(said) + "$"):
        read_frf(path, "r1")


@pytest.mark.parametrize("stored, shown", [(0.0, "0.0"), (-5, "-5"), ("1024", "'1024'")])
def test_a_stored_number_is_shown_as_a_number_and_text_as_text(tmp_path: Path, stored, shown: str) -> None:
    path = _run(tmp_path / "r.h5", frf=True)
    said = re.escape(shown) + r"( \(stored as [^)]+\))? is not"
    with h5py.File(path, "r+") as f:
        f["runs/r1/frf"].attrs["nfft"] = stored
    with pytest.raises(ModalError, match="attribute nfft = " + said):
        read_frf(path, "r1")
    with h5py.File(path, "r+") as f:
        f["runs/r1"].attrs["sample_rate_hz"] = stored
    with pytest.raises(DaqError, match="attribute sample_rate_hz = " + said):
        check_run_file(path, "r1")


# -- the same class where a sensor name is read as a UFF node number --------------------------------------
def test_a_sensor_of_5000_digits_names_no_node_of_the_geometry(tmp_path: Path, capsys) -> None:
    path = tmp_path / "m.csv"
    path.write_text(f"config,mode,freq_hz,shape.{ONES}+z\nt0,1,30,0.5\n", encoding="utf-8")
    geometry = REPO / "tests" / "data" / "uff" / "massif_geometry.uff"
    code = main(["--quiet", "report", "--measured", str(path), "--geometry", str(geometry),
                 "--out", str(tmp_path / "r.html")])
    one_line(capsys, code, "massif_geometry.uff: sensor '1111", "no node 111111111111... (5000 digits)")
    assert not (tmp_path / "r.html").exists()


def test_a_channel_that_names_no_uff_node_gets_its_default_node(tmp_path: Path) -> None:
    """'3+z' is node 3, +z; a superscript two or 5000 digits are no node number (int() refused both with
    a traceback): the channel takes its place's node, as any other name does."""
    import numpy as np

    from flexmodal.modal.frf import FrfResult
    from flexmodal.modal.uff import read_uff, write_frfs

    freq_hz = np.linspace(0.0, 512.0, 65)
    outputs = ("\u00b2+z", f"{ONES}+z", "0003-x")
    write_frfs(tmp_path / "f.uff", FrfResult(freq_hz, np.ones((3, 1, 65), complex), np.ones((3, 65)), "H1",
                                             "hann", 128, 16, 1024.0, "accelerance", outputs, ("F",)))
    assert read_uff(tmp_path / "f.uff").outputs == ("1+z", "2+z", "3-x")
