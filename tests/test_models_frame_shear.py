"""Opt-in Timoshenko frame elements (models/frame.py ``Shear``) against the closed-form Timoshenko beam."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexmodal.models.errors import ModelError
from flexmodal.models.frame import Shear, frame_modes
from flexmodal.models.rig import load_rig, parse_rig

E, RHO, NU, KAPPA = 70e9, 2700.0, 0.3, 5.0 / 6.0   # Pa, kg/m^3, -, - (aluminium, solid rectangle)
B, L = 0.02, 1.0                                     # m: width, span


def simply_supported(depth_m: float) -> dict:
    """A pinned-pinned solid rectangular beam of span L (the tip held by stiff springs along and across)."""
    area, inertia = B * depth_m, B * depth_m**3 / 12
    section = {"shape": "custom", "EA_N": E * area, "EI_Nm2": E * inertia, "mass_per_m_kg": RHO * area,
               "rotary_inertia_per_m_kgm": RHO * inertia}
    return {"name": "ss", "base": {"support": "pinned"},
            "link": [{"name": "l1", "length_m": L, "section": section}],
            "spring": [{"at": "tip", "k_N_per_m": 1e14, "direction": d} for d in ("transverse", "axial")]}


def timoshenko_ss_hz(depth_m: float, n: int, shear: bool = True) -> float:
    """Lowest root of the simply-supported Timoshenko beam's frequency equation for wavenumber k = n pi / L
    (Han, Benaroya & Wei 1999, J. Sound Vib. 225(5), 935-988): w = W sin kx, psi = Psi cos kx in
    kGA (w'' - psi') = rho A w_tt, EI psi'' + kGA (w' - psi) = rho I psi_tt.  ``shear=False`` is the
    Rayleigh beam (rotary inertia only, kGA -> infinity)."""
    area, inertia = B * depth_m, B * depth_m**3 / 12
    k = n * math.pi / L
    if not shear:
        return math.sqrt(E * inertia * k**4 / (RHO * area + RHO * inertia * k**2)) / (2 * math.pi)
    kga = KAPPA * E / (2 * (1 + NU)) * area
    stiff = np.array([[kga * k**2, -kga * k], [-kga * k, E * inertia * k**2 + kga]])
    lam = np.linalg.eigvals(np.linalg.solve(np.diag([RHO * area, RHO * inertia]), stiff))
    return math.sqrt(float(np.min(lam.real))) / (2 * math.pi)


def test_thick_simply_supported_beam_matches_the_timoshenko_frequency_equation():
    """Span/depth 8 (bending modes 1-3 below the first axial mode): shear lowers them by 1.9, 6.6, 12 %."""
    depth = L / 8
    f = frame_modes(parse_rig(simply_supported(depth)), {}, 3, elements_per_link=40,
                    shear=Shear(KAPPA, NU)).freq_hz
    exact = np.array([timoshenko_ss_hz(depth, n) for n in (1, 2, 3)])
    assert np.max(np.abs(f / exact - 1)) < 1e-3  # measured 5.5e-4 (mode 3), 20 elements 2.2e-3
    rayleigh = np.array([timoshenko_ss_hz(depth, n, shear=False) for n in (1, 2, 3)])
    assert np.all(1 - exact / rayleigh > 0.015)  # the shear the test checks is > 15x its tolerance


def test_slender_beam_shear_shift_is_half_kr_squared_times_E_over_kappa_G():
    """Span/depth 100: the frequency drop from shear alone is (k r)^2 E / (2 kappa G) to first order."""
    rig = parse_rig(simply_supported(L / 100))
    off = frame_modes(rig, {}, 3, elements_per_link=80).freq_hz
    on = frame_modes(rig, {}, 3, elements_per_link=80, shear=Shear(KAPPA, NU)).freq_hz
    r2 = (L / 100) ** 2 / 12
    first_order = np.array([(n * math.pi / L) ** 2 * r2 for n in (1, 2, 3)]) * (1 + NU) / KAPPA
    assert 1 - on / off == pytest.approx(first_order, rel=1e-2)  # measured 0.05-0.44 % (modes 1-3)


def test_stiff_shear_tends_to_the_euler_bernoulli_element(rigs_dir):
    """kappa -> infinity (phi -> 0) gives the default element, on links and on the pusher member alike."""
    rig = parse_rig(simply_supported(L / 5))
    stiff = frame_modes(rig, {}, 4, shear=Shear(1e9, NU)).freq_hz
    assert stiff == pytest.approx(frame_modes(rig, {}, 4).freq_hz, rel=1e-8)
    arm = load_rig(rigs_dir / "seed001_arm.toml")
    pose = {"shoulder_deg": 60.0, "elbow_deg": 90.0, "payload_kg": 0.0}
    off, soft = frame_modes(arm, pose, 6).freq_hz, frame_modes(arm, pose, 6, shear=Shear(0.5, NU)).freq_hz
    assert frame_modes(arm, pose, 6, shear=Shear(1e9, NU)).freq_hz == pytest.approx(off, rel=1e-8)
    assert np.max(np.abs(soft / off - 1)) > 1e-3  # measured 0.05-2.5 %: the tubes' shear is seen


@pytest.mark.parametrize(("kappa", "nu"), [(0.0, 0.3), (math.nan, 0.3), (0.5, 0.5), (0.5, -1.0)])
def test_shear_parameters_out_of_range_are_refused(kappa: float, nu: float):
    with pytest.raises(ModelError):
        Shear(kappa, nu)


@pytest.mark.parametrize(("kappa", "nu"), [(1e-200, 0.3), (math.inf, 0.3), ("0.5", 0.3), (None, 0.3),
                                           (True, 0.3), (0.5, "0.3"), (0.5, math.nan)])
def test_shear_parameters_that_are_no_usable_number_are_refused(kappa, nu):
    """A kappa so small that phi overflows (NaN masses, then no modes), a string, None or a bool: one
    ModelError."""
    with pytest.raises(ModelError, match="kappa|Poisson"):
        Shear(kappa, nu)


@pytest.mark.parametrize("mode", [1, 2])
def test_thick_beam_rotation_and_curvature_follow_the_timoshenko_mode(mode: int):
    """Span/depth 8, 40 elements: with shear the nodal angle is the section rotation psi, not the slope,
    so rotation and curvature come from the Timoshenko element's own interpolation (Friedman & Kosmatka
    1993).  The exact mode (Han, Benaroya & Wei 1999) is w = W sin kx, psi = Psi cos kx: curvature / w =
    -Psi k / W and rotation / w = (Psi / W) cot kx everywhere, at nodes and between them (the Hermite
    interpolation was 12-250 % off); the Euler-Bernoulli ratios (-k^2, k cot kx) differ by 4-13 %."""
    from flexmodal.models.frame import assemble, solve_modes

    depth = L / 8
    area, inertia = B * depth, B * depth**3 / 12
    kga = KAPPA * E / (2 * (1 + NU)) * area
    k = mode * math.pi / L
    stiff = np.array([[kga * k**2, -kga * k], [-kga * k, E * inertia * k**2 + kga]])
    lam, vec = np.linalg.eig(np.linalg.solve(np.diag([RHO * area, RHO * inertia]), stiff))
    W, Psi = vec[:, np.argmin(lam.real)].real
    system = assemble(parse_rig(simply_supported(depth)), {}, 40, shear=Shear(KAPPA, NU))
    shape = solve_modes(system, 3).phi[:, mode - 1]
    for x in (0.1, 0.3, 0.3125, 0.4):          # away from the mode's nodes (w = 0 at x = 0.5 in mode 2)
        w = system.observe(f"l1@{x}", "transverse") @ shape
        curvature = system.observe(f"l1@{x}", "curvature") @ shape / w
        rotation = system.observe(f"l1@{x}", "rotation") @ shape / w
        assert curvature == pytest.approx(-Psi * k / W, rel=3e-3)                  # measured <= 1.8e-3
        assert rotation == pytest.approx(Psi / W / math.tan(k * x), rel=3e-3)
        assert abs(curvature / -k**2 - 1) > 0.03                                  # shear is seen
