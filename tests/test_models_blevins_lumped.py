"""Blevins' table (seed 003 Table 7) and the flexibility-matrix lumped-mass model (seed 003 §3.1)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from flexmodal.models.assumed_modes import Beam, clamped_mass
from flexmodal.models.blevins import beam_frequencies_hz, cantilever_tip_mass_hz, lambdas
from flexmodal.models.errors import ModelError
from flexmodal.models.frame import frame_modes
from flexmodal.models.lumped_mass import lumped_mass_modes
from flexmodal.models.rig import load_rig, parse_rig

E, RHO = 75e9, 2700.0
I_M4 = (0.040**4 - 0.0378**4) / 12
A_M2 = 0.040**2 - 0.0378**2


def test_seed003_table7_within_0_1_percent(data_dir):
    table = pd.read_csv(data_dir / "seeds/seed003_table7_blevins_theta0.csv")
    f = beam_frequencies_hz("clamped-free", 1.36, E * I_M4, RHO * A_M2, 4)
    assert np.max(np.abs(f / table.freq_hz.to_numpy() - 1)) < 1e-3
    assert lambdas("clamped-free", 4) == pytest.approx(table["lambda"].to_numpy(), rel=1e-4)


def test_asymptotic_roots_continue_the_table():
    lam = lambdas("clamped-free", 6)
    assert lam[4] == pytest.approx(14.13716549, rel=2e-7)  # exact 5th root; the asymptote is 1e-7 off
    assert lambdas("pinned-pinned", 6) == pytest.approx(np.pi * np.arange(1, 7))
    with pytest.raises(ModelError, match="unknown boundary condition"):
        lambdas("glued-free")


def test_tip_mass_formula_within_one_percent_of_exact():
    beam = Beam(1.0, 100.0, 1.0)
    for ratio in (0.2, 1.0, 5.0):
        exact = clamped_mass(beam, ratio, 0.0, 1).freq_hz[0]
        assert cantilever_tip_mass_hz(1.0, 100.0, 1.0, ratio) == pytest.approx(exact, rel=1e-2)


# --- lumped-mass flexibility model ----------------------------------------------------------------------


@pytest.fixture
def seed003(rigs_dir):
    return load_rig(rigs_dir / "seed003_two_link.toml")


def cantilever_flexibility(x: np.ndarray, ei: float) -> np.ndarray:
    """Seed 003 eqs. 3-4: a_ij of a cantilever for points x (unit-load method)."""
    xi, xj = np.meshgrid(x, x, indexing="ij")
    lo, hi = np.minimum(xi, xj), np.maximum(xi, xj)
    return (3 * hi * lo**2 - lo**3) / (6 * ei)


def test_straight_flexibility_equals_the_cantilever_formula(seed003):
    modes = lumped_mass_modes(seed003, {"theta_deg": 0.0}, 4, 4, "transverse")
    x = np.r_[0.6 * np.arange(1, 5) / 4, 0.6 + 0.76 * np.arange(1, 5) / 4]
    assert modes.flexibility == pytest.approx(cantilever_flexibility(x, E * I_M4), rel=1e-9)


def test_right_angle_flexibility_equals_seed003_appendix(seed003):
    """theta = 90: eqs. 5, 8, 10, 11 (Table A1) for transverse coordinates."""
    ei = E * I_M4
    x = 0.6 * np.arange(1, 5) / 4
    b = 0.76 * np.arange(1, 5) / 4
    a = np.zeros((8, 8))
    a[:4, :4] = cantilever_flexibility(x, ei)
    alpha = x**2 / (2 * ei)                        # slope at the joint from a unit force on link 1 ... at x_j
    a[4:, :4] = np.outer(b, np.ones(4)) * alpha    # eq. 5 (the slope at x_j carries link 2 rigidly)
    # ... plus the deflection of link 1 between x_j and the joint, along link 2's normal: none at 90 deg
    a[:4, 4:] = a[4:, :4].T                        # eq. 8 by reciprocity: b_j x_i^2 / (2 EI)
    a[4:, 4:] = np.outer(b, b) * 0.6 / ei + cantilever_flexibility(b, ei)  # eqs. 10-11
    modes = lumped_mass_modes(seed003, {"theta_deg": 90.0}, 4, 4, "transverse")
    assert modes.flexibility == pytest.approx(a, rel=1e-9, abs=1e-15)


def test_joint_spring_adds_moment_squared_over_k(seed003):
    doc_rigid = lumped_mass_modes(seed003, {"theta_deg": 30.0}, 4, 4, "transverse").flexibility
    sprung = replace(seed003, joints=(replace(seed003.joints[0], kind="spring", k_Nm_per_rad=5000.0),))
    extra = lumped_mass_modes(sprung, {"theta_deg": 30.0}, 4, 4, "transverse").flexibility - doc_rigid
    b = np.r_[np.zeros(4), 0.76 * np.arange(1, 5) / 4]  # moment at the elbow of a unit normal force on link 2
    assert extra == pytest.approx(np.outer(b, b) / 5000.0, abs=1e-14)


def test_many_masses_converge_to_the_continuous_beam(seed003):
    f = lumped_mass_modes(seed003, {"theta_deg": 0.0}, 4, 40).freq_hz
    assert f == pytest.approx(beam_frequencies_hz("clamped-free", 1.36, E * I_M4, RHO * A_M2, 4), rel=1e-3)


def test_planar_coordinates_approach_fe_when_bent(seed003):
    """Bent arm: planar coordinates keep the carried link's inertia and converge towards the FE; the
    transverse-only choice of seed 003 overestimates f1 (38.5 Hz, the paper's Table 5 value) and f2."""
    fe = frame_modes(seed003, {"theta_deg": 90.0}, 2).freq_hz
    planar = lumped_mass_modes(seed003, {"theta_deg": 90.0}, 2, 40, "planar").freq_hz
    transverse = lumped_mass_modes(seed003, {"theta_deg": 90.0}, 2, 40, "transverse").freq_hz
    assert planar == pytest.approx(fe, rel=5e-3)
    assert transverse[0] == pytest.approx(38.50, rel=5e-3)
    assert transverse[1] > 1.8 * fe[1]


def test_sensor_shapes_follow_from_the_inertia_loads(seed003):
    """Static deflection under the modal inertia forces equals the shape where a sensor sits on a mass."""
    modes = lumped_mass_modes(seed003, {"theta_deg": 0.0}, 3, 4, "transverse")
    # sensor a3 is the tip, which is the 8th mass coordinate (trapezoid lumping, link-by-link order)
    assert modes.sensor_shapes[2] == pytest.approx(modes.phi[7], rel=1e-9)


def test_lumped_mass_refuses_a_pinned_chain():
    link = {"name": "a", "length_m": 1.0,
            "section": {"shape": "custom", "EA_N": 1e7, "EI_Nm2": 100.0, "mass_per_m_kg": 1.0}}
    with pytest.raises(ModelError, match="clamped or spring base"):
        lumped_mass_modes(parse_rig({"base": {"support": "pinned"}, "link": [link]}), {}, 2)
    assert math.isfinite(lumped_mass_modes(parse_rig({"link": [link]}), {}, 2).freq_hz[1])


def test_planar_lumped_mass_equals_fe_without_axial_strain_or_rotary_inertia(seed003):
    """Same physics on both sides (inextensible Euler-Bernoulli links): the bent arm agrees to 0.05 %."""
    stiff = {"rotary_inertia_per_m_kgm": 0.0, "EA_N": seed003.links[0].section.EA_N * 1e4}
    links = tuple(replace(lk, section=replace(lk.section, **stiff)) for lk in seed003.links)
    fe = frame_modes(replace(seed003, links=links), {"theta_deg": 90.0}, 4, elements_per_link=40).freq_hz
    lumped = lumped_mass_modes(seed003, {"theta_deg": 90.0}, 4, 80, "planar").freq_hz
    assert lumped == pytest.approx(fe, rel=5e-4)
