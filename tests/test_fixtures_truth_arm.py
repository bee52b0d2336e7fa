"""The independent truth model against known answers (its blind check: tests/test_blind.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flexmodal.fixtures.truth_arm import POISSON, TruthOptions, truth_modes
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig, parse_rig


@pytest.mark.parametrize("name, pose", [("seed003_two_link.toml", {"theta_deg": 60.0}),
                                        ("demo_arm.toml", {"theta_deg": 120.0})])
def test_without_shear_it_equals_the_euler_bernoulli_frame(rigs_dir, name, pose):
    """Two separately written frame models agree once shear is switched off: this one (80 elements a
    link, linear mass interpolation) against models/frame.py (80 Hermite elements) to 0.1 %."""
    rig = load_rig(rigs_dir / name)
    no_shear = TruthOptions(elements=80, shear_flexibility={lk.name: 0.0 for lk in rig.links})
    t = truth_modes(rig, pose, 5, no_shear)
    f = frame_modes(rig, pose, 8, elements_per_link=80).freq_hz
    np.testing.assert_allclose(t.freq_hz, f[f > 1e-3][:5], rtol=1e-3)


def test_simply_supported_thick_beam_matches_timoshenko_closed_form():
    """Pinned base, tip held by a stiff vertical spring: the Timoshenko frequency equation per mode n,
    ``EI k^4 - w^2 (mu + (r + EI mu / s) k^2) + w^4 r mu / s = 0`` with ``k = n pi / L``, ``s = kappa G A``
    (Timoshenko 1921; Han, Benaroya & Wei 1999 eq. 46)."""
    E, rho, w, h, L = 70e9, 2700.0, 0.05, 0.10, 0.8                  # L/h = 8: shear matters
    doc = {"name": "ss", "material": {"al": {"E_Pa": E, "rho_kg_m3": rho}},
           "link": [{"name": "b", "length_m": L, "material": "al",
                     "section": {"shape": "solid_rect", "width_m": w, "height_m": h}}],
           "base": {"support": "pinned"}, "joint": [],
           "spring": [{"at": "b@1", "k_N_per_m": 1e15, "direction": "y"}]}
    got = truth_modes(parse_rig(doc), {}, 6, TruthOptions(elements=120)).freq_hz
    A, I = w * h, w * h**3 / 12
    EI, mu, r, s = E * I, rho * A, rho * I, 5 / 6 * E / (2 * (1 + POISSON)) * A
    bending = []
    for n in (1, 2, 3):
        k = n * math.pi / L
        poly = np.array([r * mu / s, -(mu + (r + EI * mu / s) * k * k), EI * k**4])
        bending.append(math.sqrt(min(np.roots(poly).real)) / (2 * math.pi))
    flexural = [f for f in got if min(abs(f / b - 1) for b in bending) < 0.01]
    np.testing.assert_allclose(sorted(flexural)[:3], bending, rtol=2e-3)
    euler = [(n * math.pi / L) ** 2 * math.sqrt(EI / mu) / (2 * math.pi) for n in (1, 2, 3)]
    assert bending[2] < 0.9 * euler[2]                                # and shear lowers mode 3 by > 10 %
