"""Assumed-modes beams (models/assumed_modes.py): published roots, FE agreement, seeds 002 and 004."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from flexmodal.models.assumed_modes import (
    BOUNDARY_CONDITIONS,
    CLAMPED,
    FREE,
    PINNED,
    Beam,
    FlexibleForearmArm,
    beam_modes,
    clamped_mass,
    forearm_frequencies,
    forearm_inertia_matrix,
    forearm_modes,
    hub_beam,
    krylov,
    named_modes,
    seed002_characteristic,
)
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import parse_rig

EI, MU, L = 3240.0, 0.4621, 1.36
BEAM = Beam(L, EI, MU)
# published roots beta*L (Blevins 1979 table 8-1), flexible modes
PUBLISHED = {
    "clamped-free": [1.87510407, 4.69409113, 7.85475744, 10.99554073],
    "free-free": [4.73004074, 7.85320462, 10.99560784, 14.13716549],
    "clamped-clamped": [4.73004074, 7.85320462, 10.99560784, 14.13716549],
    "clamped-pinned": [3.92660231, 7.06858275, 10.21017612, 13.35176878],
    "pinned-free": [3.92660231, 7.06858275, 10.21017612, 13.35176878],
    "pinned-pinned": [math.pi * k for k in range(1, 5)],
    "clamped-sliding": [2.36502037, 5.49780392, 8.63937983, 11.78097245],
}


def elastic(values: np.ndarray, n: int = 4) -> np.ndarray:
    return values[values > 1e-3][:n]


@pytest.mark.parametrize("condition", sorted(BOUNDARY_CONDITIONS))
def test_roots_match_published_values(condition):
    modes = named_modes(Beam(1.0, 1.0, 1.0), condition, 6)
    assert elastic(modes.lam) == pytest.approx(PUBLISHED[condition], rel=2e-8)
    assert modes.freq_hz[modes.lam > 0][0] == pytest.approx(PUBLISHED[condition][0] ** 2 / (2 * math.pi))


def test_krylov_series_joins_the_closed_form():
    below, above = krylov(np.array([1.0 - 1e-12])), krylov(np.array([1.0 + 1e-12]))
    assert below == pytest.approx(above, rel=1e-10)


def test_shapes_are_normalised_with_end_masses():
    modes = hub_beam(BEAM, hub_inertia_kgm2=0.01, payload_kg=0.2, payload_inertia_kgm2=1e-3, n_modes=4)
    x = np.linspace(0.0, L, 4001)
    phi = modes.shape(x)
    dphi0, phiL, dphiL = modes.slope0, modes.tip, modes.shape(L, 1)[0]
    energy = MU * np.trapezoid(phi**2, x, axis=0) + 0.01 * dphi0**2 + 0.2 * phiL**2 + 1e-3 * dphiL**2
    assert energy == pytest.approx(np.ones(4), rel=1e-6)
    assert modes.v == pytest.approx(MU * np.trapezoid(phi, x, axis=0), rel=1e-6, abs=1e-9)


# --- assumed modes against the frame FE on single uniform beams, every boundary condition ------------------

# Euler-Bernoulli section (no rotary inertia), axially stiff so no axial mode falls among the first four
SECTION = {"shape": "custom", "EA_N": 1e11, "EI_Nm2": EI, "mass_per_m_kg": MU,
           "rotary_inertia_per_m_kgm": 0.0}
RIGID = {"shape": "custom", "EA_N": 1e13, "EI_Nm2": 1e13, "mass_per_m_kg": 1e-9,
         "rotary_inertia_per_m_kgm": 0.0}


def beam_rig(support: str = "clamped", **extra):
    doc = {"name": "beam", "base": {"support": support},
           "link": [{"name": "l1", "length_m": L, "section": SECTION, "elements": 16}]}
    doc.update(extra)
    return parse_rig(doc)


PIN_TIP = {"spring": [{"at": "tip", "k_N_per_m": 1e14}]}
CLAMP_TIP = {"member": [{"name": "wall", "from": "tip", "to": f"ground@{L + 0.05},0", "section": RIGID,
                         "ends": "clamped-clamped", "elements": 1}]}
FE_RIGS = {"clamped-free": ("clamped", {}), "free-free": ("free", {}), "pinned-free": ("pinned", {}),
           "pinned-pinned": ("pinned", PIN_TIP), "clamped-pinned": ("clamped", PIN_TIP),
           "clamped-clamped": ("clamped", CLAMP_TIP)}


@pytest.mark.parametrize("condition", sorted(FE_RIGS))
def test_assumed_modes_match_fe_within_0_2_percent(condition):
    support, extra = FE_RIGS[condition]
    fe = elastic(frame_modes(beam_rig(support, **extra), {}, 7).freq_hz)
    am = elastic(named_modes(BEAM, condition, 7).freq_hz)
    assert np.max(np.abs(fe / am - 1)) < 2e-3


def test_tip_mass_and_hub_spring_match_fe():
    mass = [{"at": "tip", "mass_kg": 0.3, "inertia_kgm2": 2e-3}, {"at": "l1@0", "mass_kg": 0.0,
                                                                 "inertia_kgm2": 0.02}]
    fe = frame_modes(beam_rig(mass=mass), {}, 4).freq_hz
    assert fe == pytest.approx(clamped_mass(BEAM, 0.3, 2e-3).freq_hz, rel=2e-3)
    spring = beam_rig("spring", mass=mass, base={"support": "spring", "k_Nm_per_rad": 800.0})
    fe = frame_modes(spring, {}, 4).freq_hz
    assert fe == pytest.approx(hub_beam(BEAM, 0.02, 800.0, 0.3, 2e-3).freq_hz, rel=2e-3)


# --- seed 004: a joint spring on a hub ---------------------------------------------------------------------

SEED004 = Beam(1.0, 7e10 * 0.33e-10, 0.277)  # 5 cm x 0.2 cm aluminium strip, 1 m


@pytest.mark.parametrize("hub", [0.0, 0.05])
def test_seed004_joint_spring_limits(hub):
    flexible = hub_beam(SEED004, hub, joint_k_Nm_per_rad=2.31, n_modes=4)  # K_t L / EI = 1
    assert flexible.freq_hz[0] > 0.1  # no rigid-body mode for a finite joint stiffness
    stiff = hub_beam(SEED004, hub, joint_k_Nm_per_rad=1e9, n_modes=4).freq_hz
    assert stiff == pytest.approx(beam_modes(SEED004, CLAMPED, FREE, 4).freq_hz, rel=1e-3)
    soft = hub_beam(SEED004, hub, joint_k_Nm_per_rad=1e-9, n_modes=5).freq_hz
    pinned = hub_beam(SEED004, hub, 0.0, n_modes=5).freq_hz  # pinned on the hub: rigid mode first
    assert pinned[0] == 0.0 and soft[0] < 1e-3 * soft[1]
    assert soft[1:] == pytest.approx(pinned[1:], rel=1e-3)
    assert np.all(np.diff(flexible.freq_hz) > 0)


def test_seed004_frequencies_rise_with_joint_stiffness():
    f = [hub_beam(SEED004, 0.05, k, n_modes=2).freq_hz for k in (0.1, 1.0, 10.0, 100.0)]
    assert np.all(np.diff(np.array(f), axis=0) > 0)


# --- seed 002: flexible forearm -----------------------------------------------------------------------------

RHO, L2, J02 = 1.8 / 0.7, 0.7, 6.35e-4


def seed002_arm() -> FlexibleForearmArm:
    lam1 = hub_beam(Beam(L2, 1.0, RHO), J02, n_modes=2).lam[1]
    ei = RHO * (4.716 * 2 * math.pi) ** 2 * L2**4 / lam1**4  # EI fitted to omega_1 = 4.716 Hz
    return FlexibleForearmArm(0.3, Beam(L2, ei, RHO), J02, 0.447, 0.303, 0.195)


def test_seed002_eq3_roots_equal_the_general_determinant():
    general = hub_beam(Beam(L2, 1.0, RHO), J02, n_modes=3).lam
    assert general[0] == 0.0
    for lam in general[1:]:
        assert root_of_eq3(lam - 0.3, lam + 0.3, J02) == pytest.approx(lam, rel=1e-10)
    # J02 = 0 gives the pinned-free roots, J02 -> inf the clamped-free ones
    assert root_of_eq3(3.5, 4.2, 0.0) == pytest.approx(3.92660231)
    assert root_of_eq3(1.5, 2.2, 1e6) == pytest.approx(1.8751, 1e-4)


def root_of_eq3(lo: float, hi: float, j02: float) -> float:
    """beta*L root of seed 002 eq. 3 between lo and hi."""
    return brentq(seed002_characteristic, lo / L2, hi / L2, args=(L2, RHO, j02), xtol=1e-14) * L2


def test_seed002_fitted_forearm_frequencies():
    arm = seed002_arm()
    modes = forearm_modes(arm, 2)
    assert modes.lam == pytest.approx([3.905898, 6.932748], rel=1e-6)
    assert modes.freq_hz[0] == pytest.approx(4.716, rel=1e-12)
    assert arm.forearm.EI_Nm2 == pytest.approx(2.3291, rel=1e-4)
    # omega_2 follows from the roots alone: 14.857 Hz against the paper's 14.395 Hz (+3.2 %)
    assert modes.freq_hz[1] == pytest.approx(4.716 * (6.932748 / 3.905898) ** 2, rel=1e-6)
    assert modes.freq_hz[1] / 14.395 - 1 == pytest.approx(0.0321, abs=5e-4)
    clamped = named_modes(arm.forearm, "clamped-free", 1).freq_hz[0]
    assert clamped == pytest.approx(1.0869, rel=1e-3)  # the paper: "about 1 Hz"
    # modal integrals of eq. 12, up to the sign convention: |phi'_i0| = 5.79, 11.40 (paper 5.74, 11.64)
    assert np.abs(modes.slope0) == pytest.approx([5.790, 11.402], rel=1e-3)
    assert np.abs(modes.v * L2) == pytest.approx([0.3396, 0.1585], rel=1e-3)  # h_i (paper 0.336, 0.126)


def test_seed002_linearised_two_link_model():
    arm = seed002_arm()
    omega = forearm_modes(arm, 2).freq_hz
    # joint 1 held: the slewing-beam modes are orthogonal to the forearm's rotation -> exactly omega_i
    assert forearm_frequencies(arm, 0.3, locked=(1,))[1:] == pytest.approx(omega, rel=1e-9)
    # at theta2 = 90 deg the forearm's modes decouple from joint 1 as well
    assert forearm_frequencies(arm, math.pi / 2)[2:] == pytest.approx(omega, rel=1e-9)
    straight = forearm_frequencies(arm, 0.0)
    assert straight[:2] == pytest.approx([0.0, 0.0], abs=1e-6) and np.all(straight[2:] > omega)
    B = forearm_inertia_matrix(arm, 0.4)
    assert np.all(np.linalg.eigvalsh(B) > 0) and B == pytest.approx(B.T)


def test_pinned_pinned_uses_both_pins():
    modes = beam_modes(BEAM, PINNED, PINNED, 2)
    x = np.linspace(0, L, 7)
    expected = np.sin(np.pi * x / L)[:, None] * math.sqrt(2 / (MU * L))
    assert modes.shape(x)[:, :1] == pytest.approx(expected, abs=1e-9)
