"""Run the stabilisation once, pick many times (modal/diagrams.py): every pLSCF identification stores
its stabilisation diagram beside the modal table, and ``identify --poles`` picks from the stored diagram
of the same FRFs and options instead of running the stabilisation again."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import flexmodal as fm
import flexmodal.modal.identify as identify_module
from flexmodal.app import main
from flexmodal.fixtures.examples import impact_run
from flexmodal.modal.diagrams import KINDS, diagram_path, read_diagrams, write_diagrams
from flexmodal.modal.lscf import Stabilisation


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    """A simulated impact test of the demo arm identified automatically into m.csv."""
    folder = tmp_path_factory.mktemp("diagram")
    run = impact_run(folder)
    auto = fm.identify(run, fmax=400.0, out=folder / "m.csv")
    return run, folder, auto


@pytest.fixture
def no_stabilisation(monkeypatch):
    """Fail if the stabilisation diagram is computed."""
    def refuse(*_args, **_kwargs):
        raise AssertionError("the stabilisation ran again")

    monkeypatch.setattr(identify_module, "adaptive_stabilisation", refuse)


def test_the_diagram_is_stored_with_the_key_of_its_inputs_and_reads_back_whole(identified, tmp_path):
    assert set(KINDS) == {f.name for f in dataclasses.fields(Stabilisation)}   # every array stored
    _, folder, auto = identified
    stored = read_diagrams(diagram_path(folder / "m.csv"))
    modes = auto.modes["theta30"]
    assert list(stored) == [modes.diagram_key] and stored[modes.diagram_key].config == "theta30"
    diagram = stored[modes.diagram_key]
    for name in KINDS:
        np.testing.assert_array_equal(getattr(diagram.stabilisation, name),
                                      getattr(modes.stabilisation, name))
    assert diagram.order_note == modes.order_note
    again = write_diagrams(tmp_path / "copy.npz", stored.values())   # the writer's output reads back equal
    assert read_diagrams(again)[modes.diagram_key].stabilisation.pole.tobytes() == \
        diagram.stabilisation.pole.tobytes()


def _beside(identified, out):
    """The stored diagram of ``identified`` copied beside ``out`` (each test its own folder)."""
    _, folder, _ = identified
    diagram_path(out).write_bytes(diagram_path(folder / "m.csv").read_bytes())
    return out


def _wanted(auto) -> str:
    return ",".join(f"{f + 0.3:.4f}" for f in auto.table.frame["freq_hz"][:2])


def test_poles_from_the_diagram_skip_the_stabilisation_and_pick_what_a_new_one_picks(identified, tmp_path,
                                                                                    monkeypatch, capsys):
    run, _, auto = identified
    want = _wanted(auto)
    assert main(["--quiet", "identify", str(run), "--fmax", "400", "--poles", want,
                 "--out", str(tmp_path / "fresh.csv")]) == 0      # the stabilisation runs here
    fresh = fm.read_table(tmp_path / "fresh.csv").frame
    out = _beside(identified, tmp_path / "picked.csv")
    monkeypatch.setattr(identify_module, "adaptive_stabilisation",
                        lambda *a, **k: pytest.fail("the stabilisation ran again"))
    assert main(["identify", str(run), "--fmax", "400", "--poles", want, "--from-diagram",
                 "--out", str(out)]) == 0
    assert "poles picked from the stored diagram" in capsys.readouterr().err
    picked = fm.read_table(out).frame
    np.testing.assert_allclose(picked["freq_hz"], fresh["freq_hz"], rtol=1e-9)
    np.testing.assert_allclose(picked["damping_ratio"], fresh["damping_ratio"], rtol=1e-9)
    np.testing.assert_allclose(picked["freq_hz"], auto.table.frame["freq_hz"][:2], rtol=1e-4)
    assert (tmp_path / "picked.synthesis.csv").is_file()


def test_a_matching_stored_diagram_is_used_without_asking(identified, tmp_path, no_stabilisation):
    run, _, auto = identified
    out = _beside(identified, tmp_path / "m.csv")
    want = [float(f) + 0.3 for f in auto.table.frame["freq_hz"][:2]]
    picked = fm.identify(run, fmax=400.0, poles_hz=want, out=out)
    assert picked.modes["theta30"].order_note.endswith("poles picked from the stored diagram")


def test_a_diagram_of_other_options_is_not_used(identified, tmp_path, capsys):
    run, _, auto = identified
    out = _beside(identified, tmp_path / "m.csv")
    argv = ["identify", str(run), "--fmax", "390", "--poles", _wanted(auto), "--out", str(out)]
    assert main([*argv, "--from-diagram"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "m.diagram.npz: no stored stabilisation diagram matches" in err
    assert not out.exists()                           # nothing written
    assert main(["--quiet", *argv]) == 0              # without the flag: a new stabilisation (band 0-390 Hz)
    assert fm.read_table(out).frame["freq_hz"].size == 2
    assert "picked from the stored" not in capsys.readouterr().err


def test_a_damaged_diagram_file_is_named_when_asked_for_and_replaced_otherwise(identified, tmp_path, capsys):
    run, _, auto = identified
    out = tmp_path / "m.csv"
    diagram_path(out).write_bytes(b"PK\x03\x04 not a zip")
    argv = ["identify", str(run), "--fmax", "400", "--poles", _wanted(auto), "--out", str(out)]
    assert main([*argv, "--from-diagram"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "m.diagram.npz: not a stored stabilisation diagram" in err
    assert main(["--quiet", *argv]) == 0
    assert list(read_diagrams(diagram_path(out))) == [auto.modes["theta30"].diagram_key]


def test_from_diagram_needs_poles_and_an_output(identified, capsys):
    run, folder, _ = identified
    assert main(["identify", str(run), "--from-diagram", "--out", str(folder / "x.csv")]) == 2
    assert "--poles" in capsys.readouterr().err
    with pytest.raises(fm.ModalError, match="needs out"):
        fm.identify(run, poles_hz=[33.0], from_diagram=True)
