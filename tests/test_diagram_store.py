"""Run the stabilisation once, pick many times (modal/diagrams.py): every pLSCF identification stores
its stabilisation diagram beside the modal table, and ``identify --poles`` picks from the stored diagram
of the same FRFs and options instead of running the stabilisation again."""

from __future__ import annotations

import dataclasses
import io
import re
import zipfile

import numpy as np
import pytest

import flexmodal as fm
import flexmodal.modal.identify as identify_module
from flexmodal.app import main
from flexmodal.fixtures.examples import impact_run
from flexmodal.modal.diagrams import KINDS, MAX_BYTES, diagram_path, read_diagrams, write_diagrams
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
    run, folder, auto = identified
    out = tmp_path / "m.csv"
    stored = bytearray(diagram_path(folder / "m.csv").read_bytes())
    stored[len(stored) // 2:len(stored) // 2 + 64] = bytes(64)   # a member's bytes lost: its CRC fails
    diagram_path(out).write_bytes(bytes(stored))
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


@pytest.mark.parametrize("foreign", [b"my notes\n", b"PK\x03\x04 not a zip", "npz"])
def test_a_file_of_the_users_own_where_the_diagram_goes_is_never_replaced(identified, tmp_path, capsys,
                                                                           foreign):
    run, _, _ = identified
    out = tmp_path / "m.csv"
    if foreign == "npz":
        np.savez(diagram_path(out), my_data=np.arange(5.0))
    else:
        diagram_path(out).write_bytes(foreign)
    before = diagram_path(out).read_bytes()
    assert main(["identify", str(run), "--fmax", "400", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "m.diagram.npz: exists and is not a stabilisation diagram" in err
    assert diagram_path(out).read_bytes() == before and not out.exists()


@pytest.mark.parametrize(("name", "value", "words"), [
    ("freq_hz", np.nan, "freq_hz[0] = nan"), ("damping_ratio", np.inf, "damping_ratio[0] = inf"),
    ("previous", 10**6, "previous[0] = 1000000"), ("order", -3, "order[0] = -3"),
    ("order", 2**62, "order[0] = 4611686018427387904")])
def test_impossible_stored_values_are_named(identified, tmp_path, name, value, words):
    _, folder, _ = identified
    with np.load(diagram_path(folder / "m.csv")) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays[f"d0.{name}"][0] = value
    np.savez(tmp_path / "d.npz", **arrays)
    with pytest.raises(fm.ModalError, match=re.escape(f"diagram 1: {words} is impossible")):
        read_diagrams(tmp_path / "d.npz")


def test_identify_names_a_stored_order_out_of_range_and_keeps_the_file(identified, tmp_path, capsys):
    """A stored diagram whose model order is 2^62 was read as a diagram; ``identify --poles
    --from-diagram`` now refuses it in one line naming the file, the diagram and the value, exit 2,
    and neither the stored diagram nor anything else is written."""
    run, folder, auto = identified
    with np.load(diagram_path(folder / "m.csv")) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["d0.order"][-1] = 2**62
    out = tmp_path / "m.csv"
    np.savez(diagram_path(out), **arrays)
    before = diagram_path(out).read_bytes()
    poles = ",".join(f"{f:.2f}" for f in auto.table.freq_hz(auto.table.configs[0]))
    assert main(["identify", str(run), "--fmax", "400", "--out", str(out), "--poles", poles,
                 "--from-diagram"]) == 2
    err = capsys.readouterr().err.strip()
    n = arrays["d0.order"].size - 1
    said = f"m.diagram.npz: diagram 1: order[{n}] = 4611686018427387904 is impossible"
    assert err.count("\n") == 0 and err.endswith(said), err
    assert diagram_path(out).read_bytes() == before and not out.exists()


def test_sizes_are_checked_before_reading(identified, tmp_path):
    _, folder, _ = identified
    with np.load(diagram_path(folder / "m.csv")) as npz:
        arrays = {k: npz[k] for k in npz.files}
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**13,)})
    with zipfile.ZipFile(tmp_path / "huge.npz", "w") as zf:   # declares 73 TiB, holds 64 bytes
        for k, a in arrays.items():
            member = io.BytesIO()
            np.save(member, a)
            zf.writestr(k + ".npy", header.getvalue() + bytes(64) if k == "d0.freq_hz" else member.getvalue())
    with pytest.raises(fm.ModalError, match="declares shape"):
        read_diagrams(tmp_path / "huge.npz")
    np.savez_compressed(tmp_path / "bomb.npz", **arrays, junk=np.zeros(MAX_BYTES // 8 + 1))   # 1 MB on disk
    with pytest.raises(fm.ModalError, match="unpack to"):
        read_diagrams(tmp_path / "bomb.npz")
