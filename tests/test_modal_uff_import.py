"""UFF from other tools (issue 12 point 7): impact tests exported as dataset-58 time histories with
one record per hit and channel (hits as load cases or record numbers) identify like the same data in
HDF5; FRFs with any node/direction numbering; files shaped like every dataset-58 sample of pyuff are
identified or refused with one line (exit 2), none crashes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flexmodal.app import main
from flexmodal.contract.table import ModalTable
from flexmodal.daq.store import Channel, Event, RunWriter, read_run
from flexmodal.fixtures.modal_sim import modal_frf, modal_response
from flexmodal.modal.compute import compute_frf
from flexmodal.modal.identify import identify
from flexmodal.modal.sources import identify_input
from flexmodal.modal.uncertainty import with_uncertainty

pyuff = pytest.importorskip("pyuff")
DATA = Path(__file__).parent / "data" / "uff"
FS = 1024.0
FN, ZETA = np.array([31.0, 77.0, 140.0]), np.array([0.02, 0.012, 0.01])
PHI = np.array([[1.0, 0.7, 0.4]])
HIT = 2 * int(FS)


def _impact_record(n_hits: int = 5) -> tuple[np.ndarray, list[int]]:
    """Force and one acceleration, a hit every 2 s with varying force, 40 dB noise on the response."""
    force = np.zeros((n_hits * HIT, 1))
    trig = [k * HIT + 50 for k in range(n_hits)]
    for k, t in enumerate(trig):
        force[t:t + 8, 0] = (100 + 7 * k) * np.sin(np.pi * np.arange(8) / 7)
    y = modal_response(force, FS, FN, ZETA, PHI, PHI)
    y += 0.01 * y.std() * np.random.default_rng(4).standard_normal(y.shape)
    return np.column_stack([force, y]), trig


def _set58(data, node, direction, force: bool, **extra):
    return pyuff.prepare_58(func_type=1, rsp_node=node, rsp_dir=direction, ref_node=1, ref_dir=3,
                            ordinate_spec_data_type=13 if force else 12, orddenom_spec_data_type=0,
                            abscissa_spec_data_type=17, data=np.asarray(data, float),
                            x=np.arange(len(data)) / FS, abscissa_spacing=1, abscissa_min=0.0,
                            abscissa_inc=1 / FS, num_pts=len(data), id1="hit", **extra)


@pytest.mark.parametrize("field", ["load_case_id", "ver_num"])
def test_multi_record_time_histories_identify_like_the_same_hits_in_hdf5(tmp_path, field):
    samples, _ = _impact_record()
    h5 = tmp_path / "hits.h5"
    with RunWriter(h5, "hits", sample_rate_hz=FS, channels=[Channel("1+z", "force", "N"),
                   Channel("2+z", "acceleration", "m/s^2")], excitation="impact", pose={}) as w:
        w.append(samples)
        w.add_events([Event("note", 0, 0, "five hits")])
    run = read_run(h5, "hits")
    ref = compute_frf(run)
    starts = [h["trigger"] - int(round(0.02 * FS)) for h in ref.provenance["hits"]]
    assert len(starts) == 5 and all(h["accepted"] for h in ref.provenance["hits"])
    length = ref.nfft
    sets = []
    for k in (3, 0, 4, 1, 2):   # hits out of order: assembled by their load case / record number
        cut = run.samples[starts[k]:starts[k] + length]
        tag = {field: k + 1}
        sets += [_set58(cut[:, 0], 1, 3, True, **tag), _set58(cut[:, 1], 2, 3, False, **tag)]
    uff = tmp_path / "hits.uff"
    pyuff.UFF(str(uff)).write_sets(sets, mode="overwrite")
    table, found = identify_input(uff, fmin=10, fmax=300)
    modes = found["hits"][0]
    assert np.allclose(modes.freq_hz, FN, rtol=2e-3)
    same = identify(ref.freq_hz, ref.H, fmin=10, fmax=300, decay_rate_per_s=ref.decay_rate_per_s)
    same = with_uncertainty(same, ref.freq_hz, ref.H, ref.coherence, ref.n_averages, ref.quantity,
                            ref.decay_rate_per_s)   # the identification's refinement (modal/uncertainty.py)
    assert np.allclose(modes.freq_hz, same.freq_hz, rtol=1e-5)
    assert np.allclose(modes.damping_ratio, same.damping_ratio, rtol=1e-3)


def _cli(path: Path, tmp_path: Path, capsys, *options: str) -> tuple[int, list[str]]:
    code = main(["identify", str(path), "--out", str(tmp_path / "m.csv"), *options])
    return code, capsys.readouterr().err.strip().splitlines()


def _refused(path: Path, tmp_path: Path, capsys, message: str, *options: str) -> None:
    code, err = _cli(path, tmp_path, capsys, *options)
    assert code == 2 and len(err) == 1 and message in err[0], err


def _frf_set(f: np.ndarray, data: np.ndarray, rsp_node: int, rsp_dir: int, ref_node: int, ref_dir: int,
             func_type: int = 4, **names) -> dict:
    """A dataset-58 set of an accelerance FRF (complex double) on an evenly spaced frequency axis."""
    return pyuff.prepare_58(func_type=func_type, rsp_node=rsp_node, rsp_dir=rsp_dir, ref_node=ref_node,
                            ref_dir=ref_dir, ord_data_type=6, abscissa_spec_data_type=18,
                            ordinate_spec_data_type=12, orddenom_spec_data_type=13, data=data, x=f,
                            abscissa_spacing=1, abscissa_min=float(f[0]), abscissa_inc=float(f[1] - f[0]),
                            num_pts=f.size, id1="frf", **names)


def _identified(path: Path, sets: list[dict], tmp_path: Path, capsys) -> ModalTable:
    """Write ``sets`` to ``path``, identify it with the CLI's defaults (exit 0) and read the table."""
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    assert _cli(path, tmp_path, capsys)[0] == 0
    return ModalTable.read_csv(tmp_path / "m.csv")


def test_catman_time_history_without_a_force_is_refused_with_one_line(tmp_path, capsys):
    """No force: output-only by default, and 13 samples are too few for it; an FRF method needs a force."""
    path = DATA / "time-history-not-all-columns-filled.uff"
    _refused(path, tmp_path, capsys, "13 samples are too few")
    _refused(path, tmp_path, capsys, "no force channel among the time histories 0:0", "--method", "lscf")


@pytest.mark.parametrize("binary", [0, 1])
def test_pressure_time_history_like_pyuffs_sample_uff58_is_identified_or_refused(tmp_path, capsys, binary):
    """Sample_UFF58_ascii.uff / Sample_UFF58b_bin.uff: one microphone record, response entity 'Mic 01',
    node 0, no reference: the old reader crashed on it ('force' is not in list)."""
    x = np.arange(4096) * 1.52588e-05
    s = pyuff.prepare_58(binary=binary, func_type=1, rsp_ent_name="Mic 01", rsp_node=0, rsp_dir=1,
                         ref_ent_name="NONE", ref_node=0, ref_dir=0, ord_data_type=2,
                         abscissa_spec_data_type=17, ordinate_spec_data_type=0, orddenom_spec_data_type=0,
                         data=0.01 * np.sin(2 * np.pi * 300 * x), x=x, abscissa_spacing=1, abscissa_min=0.0,
                         abscissa_inc=1.52588e-05, num_pts=x.size, id1="Mic 01.0Scalar")
    path = tmp_path / "mic.uff"
    pyuff.UFF(str(path)).write_sets([s], mode="overwrite")
    if binary:   # pyuff reads none of the sets it wrote in binary form back: still one line, exit 2
        _refused(path, tmp_path, capsys, "mic.uff: ")
        return
    # no force: identified output-only by default (the 300 Hz tone), refused by an FRF method
    assert _cli(path, tmp_path, capsys)[0] == 0
    assert np.allclose(ModalTable.read_csv(tmp_path / "m.csv").freq_hz("mic"), [300.0], rtol=1e-3)
    _refused(path, tmp_path, capsys, "no force channel among the time histories 0+x", "--method", "lscf")


def test_psd_with_uneven_abscissa_like_pyuffs_sample_is_refused(tmp_path, capsys):
    f = np.arange(0.0, 200.0)
    s = pyuff.prepare_58(func_type=9, rsp_ent_name="Pilot 1", rsp_node=0, rsp_dir=0, ref_node=0, ref_dir=0,
                         ord_data_type=5, abscissa_spacing=0, abscissa_spec_data_type=18,
                         ordinate_spec_data_type=0, orddenom_spec_data_type=0,
                         data=1e-4 * np.ones(f.size, complex), x=f, num_pts=f.size,
                         id1="Power Spectral Density (PSD)")
    path = tmp_path / "psd.uff"
    pyuff.UFF(str(path)).write_sets([s], mode="overwrite")
    _refused(path, tmp_path, capsys, "function types [9] are not supported: none is an FRF (4)")


def test_frfs_of_a_test_case_entity_like_pyuffs_measurement_sample_are_identified(tmp_path, capsys):
    """measurement.uff: complex double FRFs, entity 'TestCase', 0-1000 Hz at 1 Hz, the reference at
    node 1 direction +x (code 1), responses at nodes 1, 2, 3; here with a coherence set (type 6) too."""
    f = np.arange(0.0, 1001.0)
    fn, zeta = np.array([215.0, 470.0, 760.0]), np.array([0.01, 0.008, 0.006])
    phi = np.array([[1.0, 0.8, -0.5], [0.6, -0.9, 0.7], [0.3, -0.4, -1.0]])
    H = modal_frf(f, fn, zeta, phi, phi[[0]])
    H[..., 0] = 0
    sets = [_frf_set(f, H[k, 0] if ft == 4 else np.ones(f.size), k + 1, 1, 1, 1, func_type=ft,
                     rsp_ent_name="TestCase", ref_ent_name="TestCase") for k in range(3) for ft in (4, 6)]
    table = _identified(tmp_path / "measurement.uff", sets, tmp_path, capsys)
    assert np.allclose(table.freq_hz("measurement"), fn, rtol=1e-4)
    assert table.sensors == ["1+x", "2+x", "3+x"]


def test_a_file_without_dataset_58_like_pyuffs_testlab_geometry_is_refused(tmp_path, capsys):
    s = pyuff.prepare_15(node_nums=[1, 2], def_cs=[0, 0], disp_cs=[0, 0], color=[8, 8],
                         x=[-2.4, -2.6], y=[-0.95, 2.05], z=[0.0, 0.0])
    path = tmp_path / "geometry.uff"
    pyuff.UFF(str(path)).write_sets([s], mode="overwrite")
    _refused(path, tmp_path, capsys, "no dataset 58 (found dataset types [15]")


def test_two_frfs_for_one_pair_and_garbage_are_refused(tmp_path, capsys):
    f = np.arange(1.0, 100.0)
    s = pyuff.prepare_58(func_type=4, rsp_node=2, rsp_dir=-2, ref_node=1, ref_dir=3, ord_data_type=6,
                         abscissa_spec_data_type=18, ordinate_spec_data_type=12, orddenom_spec_data_type=13,
                         data=np.ones(f.size, complex), x=f, abscissa_spacing=1, abscissa_min=1.0,
                         abscissa_inc=1.0, num_pts=f.size)
    path = tmp_path / "twice.uff"
    pyuff.UFF(str(path)).write_sets([s, s], mode="overwrite")
    _refused(path, tmp_path, capsys, "two FRFs for response 2-y and reference 1+z")
    junk = tmp_path / "junk.uff"
    junk.write_text("    -1\n    58\nthis is not a dataset\n    -1\n")
    code, err = _cli(junk, tmp_path, capsys)
    assert code == 2 and len(err) == 1, err


def _three_modes() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies [Hz] (0-400 Hz, 0.25 Hz lines), natural frequencies [Hz] and the FRFs (modal_frf)
    [3 responses, 1 reference (the third point), n_freq] of three modes, the 0 Hz line zeroed."""
    f = np.arange(0.0, 400.0, 0.25)
    fn, zeta = np.array([60.0, 150.0, 310.0]), np.array([0.01, 0.01, 0.02])
    phi = np.array([[1.0, 0.5, -0.4], [0.3, -0.9, 0.8], [-0.7, 0.6, 0.5]])
    H = modal_frf(f, fn, zeta, phi, phi[[2]])
    H[..., 0] = 0
    return f, fn, H


def test_frfs_with_any_node_and_direction_numbering_are_identified(tmp_path, capsys):
    """Scalar (0), rotational (5) and negative directions, large node numbers, a -z reference."""
    f, fn, H = _three_modes()
    nodes = [(1001, 0), (1002, 5), (7, -3)]
    sets = [_frf_set(f, H[k, 0], n, d, 7, -3) for k, (n, d) in enumerate(nodes)]
    table = _identified(tmp_path / "numbering.uff", sets, tmp_path, capsys)
    assert np.allclose(table.freq_hz("numbering"), fn, rtol=1e-5)
    assert table.sensors == ["1001:0", "1002:5", "7-z"]


def _analyser_frf_text(f: np.ndarray, data: np.ndarray) -> str:
    """One FRF as an analyser writes it (UFFFiles.jl's test/datasets/dataset58_FRF.unv, 2018): node
    names as entity names with node and direction 0, complex single precision six values a line, and
    the last line filled up with zeros."""
    values = np.column_stack([data.real, data.imag]).ravel()
    values = np.concatenate([values, np.zeros(-values.size % 6)])
    lines = ["".join(f"{v:13.5E}" for v in row) for row in values.reshape(-1, 6)]
    head = ["    -1", "    58", "Frequency Response Function", "NONE", "05-Dec-18 14:22:22", "NONE", "NONE",
            "    4         0    0         0 .1.Z-              0   0 .56.Z              0   0",
            f"         5{f.size:10d}         1{f[0]:13.5E}{f[1] - f[0]:13.5E}{0:13.5E}",
            "        18    0    0    0 NONE                 NONE",
            "         0    0    0    0 Receptance           (m/s)/N",
            "         0    0    0    0 NONE                 NONE",
            "         2    0    0    0 NONE                 NONE"]
    return "\n".join([*head, *lines, "    -1", ""])


def test_an_analyser_frf_whose_last_data_line_is_filled_with_zeros_is_identified(tmp_path, capsys):
    """1600 complex points fill 533 lines and 2 values; the analyser pads that line with 4 zeros, which
    pyuff reads as 2 more points: they are dropped, not refused as a data block of the wrong length."""
    f = np.arange(1600) * 0.5
    fn, zeta = np.array([81.5, 175.0, 376.5]), np.array([0.01, 0.008, 0.006])
    phi = np.array([[1.0, -0.6, 0.8]])
    H = modal_frf(f, fn, zeta, phi, phi)[0, 0]
    path = tmp_path / "padded.unv"
    path.write_text(_analyser_frf_text(f, H))
    assert _cli(path, tmp_path, capsys)[0] == 0
    assert np.allclose(ModalTable.read_csv(tmp_path / "m.csv").freq_hz("padded"), fn, rtol=1e-4)
    # a surplus that is not zero is data the header does not announce: refused with one line
    path.write_text(_analyser_frf_text(f, H).replace(f"5{f.size:10d}", f"5{f.size - 2:10d}"))
    _refused(path, tmp_path, capsys, "1602 data values and 1602 abscissa values, the header announces "
             "num_pts = 1598 (values after the data block)")


def _th(data, node, direction, force=False, **extra):
    return pyuff.prepare_58(func_type=1, rsp_node=node, rsp_dir=direction, ref_node=0, ref_dir=0,
                            ordinate_spec_data_type=13 if force else 12, orddenom_spec_data_type=0,
                            abscissa_spec_data_type=17, data=np.asarray(data, float),
                            x=np.arange(len(data)) / FS, abscissa_spacing=1, abscissa_min=0.0,
                            abscissa_inc=1 / FS, num_pts=len(data), **{"id1": "laser", **extra})


def test_skewed_sensors_sharing_a_node_and_direction_code_0_are_separate_channels(tmp_path):
    """Three laser beams at node 5 (direction code 0) and one at node 6 in one load case were refused
    ("channels hold different numbers of records"); by order within the load case they are sensors
    5:0#1..3, and with different ID lines the ID line tells them apart, whatever their order."""
    from flexmodal.modal.uff import read_uff

    rng = np.random.default_rng(5)
    y = rng.standard_normal((256, 4))
    path = tmp_path / "lasers.uff"
    pyuff.UFF(str(path)).write_sets([_th(y[:, k], 5 if k < 3 else 6, 0, load_case_id=1) for k in range(4)],
                                    mode="overwrite")
    rec = read_uff(path)
    assert rec.names == ("5:0#1", "5:0#2", "5:0#3", "6:0") and np.allclose(rec.samples, y, rtol=1e-6)
    z = rng.standard_normal((256, 3))   # a second load case, beams written in another order
    sets = [_th(y[:, k], 5, 0, id1=f"beam {'CAB'[k]}", load_case_id=1) for k in range(3)]
    sets += [_th(z[:, k], 5, 0, id1=f"beam {'ABC'[k]}", load_case_id=2) for k in range(3)]
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    rec = read_uff(path)
    assert rec.names == ("5:0#1", "5:0#2", "5:0#3") and rec.hit_len == 256
    assert np.allclose(rec.samples, np.concatenate([y[:, :3], z[:, [2, 0, 1]]]), rtol=1e-6)


def test_tri_axial_sensors_with_direction_code_0_in_a_multi_hit_impact_export(tmp_path):
    """Each hit a load case holding the force and three records of node 2 direction 0: three channels
    of three hits each (the force is never split: one hammer per point)."""
    from flexmodal.modal.uff import read_uff

    rng = np.random.default_rng(6)
    hits = [rng.standard_normal((512, 3)) for _ in range(3)]
    sets = []
    for h, resp in enumerate(hits):
        force = np.zeros(512)
        force[20:26] = 50 * np.sin(np.pi * np.arange(6) / 5)
        sets += [_th(force, 1, 3, True, load_case_id=h + 1)]
        sets += [_th(resp[:, k], 2, 0, load_case_id=h + 1) for k in range(3)]
    path = tmp_path / "triax.uff"
    pyuff.UFF(str(path)).write_sets(sets, mode="overwrite")
    rec = read_uff(path)
    assert rec.names == ("1+z", "2:0#1", "2:0#2", "2:0#3") and rec.hit_len == 512
    assert np.allclose(rec.samples[:, 1:], np.concatenate(hits), rtol=1e-6)


def test_frfs_of_tri_axial_sensors_with_direction_code_0_are_identified(tmp_path, capsys):
    f, fn, H = _three_modes()
    sets = [_frf_set(f, H[k, 0], 4, 0, 7, -3) for k in range(3)]
    table = _identified(tmp_path / "triax.uff", sets, tmp_path, capsys)
    assert np.allclose(table.freq_hz("triax"), fn, rtol=1e-5)
    assert table.sensors == ["4:0#1", "4:0#2", "4:0#3"]
