"""Stored files are read with every whole number checked for range, and a diagnosis.json too large to
read in reasonable time is refused unread: each in one line naming the file and the field or the size,
exit 2, nothing written (a 47 MB diagnosis.json kept ``report`` busy for over a minute; an FRF group's
``nfft`` of 2^62 or a diagnosis's rank of 2^62 were taken as they were)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py

from flexmodal.app import main

DEMO = Path(__file__).resolve().parent / "data" / "diagnosis" / "demo.json"


def _report(capsys, diagnosis: Path) -> str:
    out = diagnosis.with_name("report.html")
    assert main(["--quiet", "report", "--diagnosis", str(diagnosis), "--out", str(out)]) == 2
    assert not out.exists()
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    return err


def test_a_diagnosis_larger_than_the_limit_is_refused_unread(tmp_path, capsys):
    from flexmodal.reports.html import MAX_DIAGNOSIS_BYTES

    doc = json.loads(DEMO.read_text())
    doc["ranking"] = doc["ranking"] * (MAX_DIAGNOSIS_BYTES // len(json.dumps(doc["ranking"])) + 1)
    big = tmp_path / "diagnosis.json"
    big.write_text(json.dumps(doc))
    assert big.stat().st_size > MAX_DIAGNOSIS_BYTES
    said = f"flexmodal: error: {big}: larger than 8 MiB, too large for a diagnosis JSON file"
    assert _report(capsys, big) == said


def test_a_whole_number_of_a_diagnosis_out_of_range_is_named(tmp_path, capsys):
    doc = json.loads(DEMO.read_text())
    doc["holdout"]["n_folds"] = 2**62
    bad = tmp_path / "diagnosis.json"
    bad.write_text(json.dumps(doc))
    assert _report(capsys, bad).endswith(f"{bad}: holdout.n_folds: expected an integer from 0 to 1000000 "
                                         "(got int 4611686018427387904)")


def test_a_stored_frf_segment_length_out_of_range_is_named(tmp_path, capsys):
    import flexmodal as fm
    from flexmodal.fixtures.examples import impact_run

    runs = impact_run(tmp_path)
    fm.compute_frfs([runs])
    with h5py.File(runs, "r+") as f:
        f["runs/theta30/frf"].attrs["nfft"] = 2**62
    before = runs.read_bytes()
    out = tmp_path / "modes.csv"
    assert main(["--quiet", "identify", str(runs), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.endswith(
        "frf group: attribute nfft = 4611686018427387904 is not a whole number from 1 to "
        "281474976710656"), err
    assert runs.read_bytes() == before and not out.exists()


def test_an_event_count_out_of_range_is_named(tmp_path, capsys):
    """A gap of 2^62 samples: its end (first + count) overflowed int64 and the gap was not skipped."""
    from flexmodal.fixtures.examples import impact_run

    runs = impact_run(tmp_path)
    with h5py.File(runs, "r+") as f:
        f["runs/theta30/events"][0] = ("gap", 10, 2**62, "")
    before = runs.read_bytes()
    assert main(["--quiet", "frf", str(runs)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.endswith(
        "'events' row 0 (gap): count = 4611686018427387904 is not from 0 to 281474976710656 samples"), err
    assert runs.read_bytes() == before
