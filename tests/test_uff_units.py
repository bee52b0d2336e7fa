"""UFF dataset-58 inputs follow the unit rules of HDF5 runs within a quantity (docs/formats.md): records
of one quantity whose unit labels differ are brought to its SI unit (a response in g beside ones in
m/s^2, a force in kN or lbf beside ones in N), records sharing a unit stay in it; records of different
quantities (m/s beside m/s^2) or of a unit without a known factor are kept as given (a run refuses
them; a real UFF export mixes laser velocities and reference accelerations).

Before: the labels were not read; an FRF exported in g/N beside ones in (m/s^2)/N gave a mode shape
entry 9.81 times too small at that sensor, exit 0.  Files written with pyuff, read by modal.uff.read_uff
and the command line; the truth is the FRF matrix (or the time histories) in SI before it was written.
About 1 s.
"""

from __future__ import annotations

import numpy as np
import pytest
import pyuff

from flexmodal.daq.session import G_M_PER_S2
from flexmodal.modal.uff import read_uff

F_HZ = np.linspace(1.0, 100.0, 200)
LBF_N = 4.4482216152605


def _truth() -> np.ndarray:
    """H [3 outputs, 1 input, f] of one 40 Hz mode, accelerance in (m/s^2)/N."""
    s, w0 = 2j * np.pi * F_HZ, 2 * np.pi * 40.0
    return np.array([1.0, 2.0, -1.5])[:, None, None] * (s**2 / (s**2 + 2 * 0.02 * w0 * s + w0**2))[None, None]


def _write(path, units: list[tuple[str, str]], scale: list[float], ordinate_types=(12, 12, 12),
           time: bool = False):
    """Dataset-58 FRFs of :func:`_truth`, record k labelled ``units[k]`` (numerator, denominator; "" for
    no label) and its data multiplied by ``scale[k]`` (SI to that unit)."""
    H = _truth()
    for k, ((num, den), factor) in enumerate(zip(units, scale, strict=True)):
        data = H[k, 0] * factor
        rec = pyuff.prepare_58(func_type=4, rsp_node=k + 1, rsp_dir=3, ref_node=10, ref_dir=3, data=data,
                               x=F_HZ.copy(), ordinate_spec_data_type=ordinate_types[k],
                               orddenom_spec_data_type=13, abscissa_spec_data_type=18,
                               abscissa_spacing=1, abscissa_min=F_HZ[0], abscissa_inc=F_HZ[1] - F_HZ[0],
                               num_pts=F_HZ.size, ordinate_axis_units_lab=num or "NONE",
                               orddenom_axis_units_lab=den or "NONE")
        pyuff.UFF(str(path)).write_sets(rec, "add")
    return path


@pytest.mark.parametrize(("units", "scale"), [
    ([("m/s^2", "N"), ("g", "N"), ("", "")], [1.0, 1 / G_M_PER_S2, 1.0]),
    ([("m/s^2", "N"), ("m/s^2", "kN"), ("(m/s^2)/N", "")], [1.0, 1e3, 1.0]),
    ([("g/lbf", ""), ("m/s^2", "N"), ("m/s^2", "N")], [LBF_N / G_M_PER_S2, 1.0, 1.0]),
], ids=["g beside m/s^2", "kN beside N", "g/lbf ratio label"])
def test_mixed_units_are_brought_to_si(tmp_path, units, scale) -> None:
    frfs = read_uff(_write(tmp_path / "mixed.uff", units, scale))
    np.testing.assert_allclose(frfs.H, _truth(), rtol=1e-4)   # the file holds 6 significant digits


def test_one_shared_unit_is_kept(tmp_path) -> None:
    frfs = read_uff(_write(tmp_path / "g.uff", [("g", "N")] * 3, [1 / G_M_PER_S2] * 3))
    np.testing.assert_allclose(frfs.H, _truth() / G_M_PER_S2, rtol=1e-4)


def test_records_of_a_unit_without_known_factor_are_kept_as_given(tmp_path) -> None:
    """As before (a run refuses them).  Time histories of laser velocities beside reference
    accelerations, the pyOMA steel frame of the real-data board, are kept as given too; FRFs of two
    quantities are refused (accelerance and mobility)."""
    units = [("m/s^2", "N"), ("furlong", "N"), ("m/s^2", "N")]
    frfs = read_uff(_write(tmp_path / "odd.uff", units, [1.0] * 3))
    np.testing.assert_allclose(frfs.H, _truth(), rtol=1e-4)


def test_time_histories_in_mixed_units_are_brought_to_si(tmp_path) -> None:
    """Type 1 records: a force in kN beside one in N, a response in g beside one in m/s^2."""
    rng = np.random.default_rng(1)
    truth = rng.standard_normal((256, 4))   # F1 [N], F2 [N], a1 [m/s^2], a2 [m/s^2]
    path = tmp_path / "time.uff"
    for k, (code, unit, factor) in enumerate([(13, "N", 1.0), (13, "kN", 1e-3), (12, "m/s^2", 1.0),
                                              (12, "g", 1 / G_M_PER_S2)]):
        rec = pyuff.prepare_58(func_type=1, rsp_node=k + 1, rsp_dir=3, ref_node=0, ref_dir=0,
                               data=truth[:, k] * factor, x=np.arange(256) / 512.0,
                               ordinate_spec_data_type=code, orddenom_spec_data_type=0,
                               abscissa_spec_data_type=17,
                               abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=1 / 512.0, num_pts=256,
                               ordinate_axis_units_lab=unit)
        pyuff.UFF(str(path)).write_sets(rec, "add")
    record = read_uff(path)
    assert record.names == ("1+z", "2+z", "3+z", "4+z")
    assert record.kinds == ("force", "force", "acceleration", "acceleration")
    np.testing.assert_allclose(record.samples, truth, rtol=1e-4, atol=1e-9)
