"""Channels of one quantity stored in different units (REVIEW41 L4).  Forces in N beside kN or lbf were
taken as stored: an FRF column of a force in kN was 1000 times too large, and a two-input random test
lost one of its close modes (32.7 and 33.6 Hz read as one at 33.4 Hz, 105.37 Hz read as 104.58 Hz).
The FRFs are now per N for every input.  Strain and velocity units with a known factor are converted
within their quantity, and channels of different quantities are named with their quantity."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import flexmodal as fm
from flexmodal.daq.store import RunWriter
from flexmodal.fixtures.demo import DEMO_RIG
from flexmodal.fixtures.rig_sim import simulate
from flexmodal.modal.sources import given_unit, si_factors
from flexmodal.models.rig import load_rig


def _two_inputs(path: Path, f2_unit: str, f2_per_newton: float) -> Path:
    """A 4 s random test of the demo arm (1024 Hz) with shakers at the tip (``F``, N) and the elbow
    (``F2``, stored in ``f2_unit``: ``f2_per_newton`` of it per N), the accelerations of both summed."""
    rig = load_rig(DEMO_RIG)
    tests = [simulate(rig, {"theta_deg": 30.0}, excitation="random", duration_s=4.0, sample_rate_hz=1024.0,
                      seed=seed, force_at=at) for seed, at in ((1, "tip"), (2, "elbow"))]
    a, b = tests
    channels = (a.channels[0], dataclasses.replace(b.channels[0], name="F2", unit=f2_unit), *a.channels[1:])
    samples = np.column_stack([a.samples[:, 0], b.samples[:, 0] * f2_per_newton,
                               a.samples[:, 1:] + b.samples[:, 1:]])
    with RunWriter(path, "two", sample_rate_hz=1024.0, channels=channels, excitation="random",
                   pose={"theta_deg": 30.0}) as writer:
        writer.append(samples)
    return path


@pytest.mark.parametrize(("unit", "per_newton"), [("kN", 1e-3), ("lbf", 1 / 4.4482216152605)])
def test_forces_in_n_and_kn_or_lbf_give_the_modes_of_the_same_test_in_n(tmp_path: Path, unit: str,
                                                                          per_newton: float) -> None:
    want = fm.identify(_two_inputs(tmp_path / "si.h5", "N", 1.0), fmax=400.0).table.frame
    got = fm.identify(_two_inputs(tmp_path / "mixed.h5", unit, per_newton), fmax=400.0).table.frame
    assert len(got) == len(want) >= 4
    for column in ("freq_hz", "damping_ratio", "shape.a1", "shape.a2", "shape.a5"):
        assert got[column].to_numpy() == pytest.approx(want[column].to_numpy(), rel=1e-4, abs=1e-6)


def test_a_force_in_a_unit_of_no_known_factor_is_named(tmp_path: Path) -> None:
    path = _two_inputs(tmp_path / "kip.h5", "kip", 1.0)
    with pytest.raises(fm.ModalError, match=r"kip.h5:two: the force channels are in different units "
                                            r"\(F \(N: force\), F2 \(kip: no known factor to "):
        fm.identify(path, fmax=400.0)


@pytest.mark.parametrize(("units", "given", "factors"), [
    (["µε", "microstrain", "ε"], "µε", [1.0, 1.0, 1e6]),
    (["m/s", "mm/s"], "m/s", [1.0, 1e-3]),
    (["N", "kN", "lbf", "mN"], "N", [1.0, 1e3, 4.4482216152605, 1e-3]),
    (["g", "m/s²", "mm/s^2"], "m/s^2", [9.80665, 1.0, 1e-3]),
    (["kN", "kN"], "kN", None),
    (["µε", "m/s^2"], None, [np.nan, np.nan])])
def test_units_of_one_quantity_are_brought_to_its_si_unit(units, given, factors) -> None:
    """Factors from the unit definitions (1 lbf = 4.4482216152605 N exactly, 1 g = 9.80665 m/s^2)."""
    assert given_unit(units) == given
    got = si_factors(units)
    assert (got is None) if factors is None else got == pytest.approx(factors, rel=1e-12, nan_ok=True)
