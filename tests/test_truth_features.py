"""The independent truth model's bench features (fixtures/truth_arm.py) against independent answers:
the Euler-Bernoulli cantilever's closed-form shapes, models/frame.py as a second model, a converged mesh,
Rayleigh damping's state-space eigenvalues, and the simulated records they make (fixtures/rig_sim.py)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.linalg import eig

from flexmodal.contract.mac import mac
from flexmodal.fixtures.rig_sim import DEMO_RIG, simulate
from flexmodal.fixtures.truth_arm import (
    BENCH_RAYLEIGH,
    TruthOptions,
    bench_arm,
    rayleigh_damping,
    truth_modes,
)
from flexmodal.modal.compute import frf_of_record
from flexmodal.modal.identify import identify
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig, parse_rig

E, RHO, W, H, L = 70e9, 2700.0, 0.02, 0.01, 1.0          # a slender solid aluminium bar, L/h = 100
BETA_L = (1.8751040687, 4.6940911330, 7.8547574382)     # cantilever roots of cos(bL) cosh(bL) = -1


def _cantilever(extra: dict | None = None) -> dict:
    doc = {"name": "bar", "material": {"al": {"E_Pa": E, "rho_kg_m3": RHO}},
           "link": [{"name": "b", "length_m": L, "material": "al",
                     "section": {"shape": "solid_rect", "width_m": W, "height_m": H}}],
           "base": {"support": "clamped"}, "joint": [], "sensor": [{"name": "s", "at": "tip"}]}
    return doc | (extra or {})


def _euler_bernoulli() -> TruthOptions:
    return TruthOptions(elements=100, shear_flexibility={"b": 0.0})


def test_rotation_and_curvature_rows_match_the_cantilevers_closed_form_shapes():
    """phi(x) = cosh bx - cos bx - s (sinh bx - sin bx), s = (cosh bL + cos bL) / (sinh bL + sin bL)
    (Blevins 1979, table 8-1): section rotation at the tip and curvature at 0.1 L and 0.5 L, each over
    the tip deflection, for the first three modes, to 0.3 % of the largest of them."""
    obs = [("tip", "rotation"), ("b@0.1", "curvature"), ("b@0.5", "curvature")]
    m = truth_modes(parse_rig(_cantilever()), {}, 3, _euler_bernoulli(), observe=obs)
    for k, bl in enumerate(BETA_L):
        b = bl / L
        s = (math.cosh(bl) + math.cos(bl)) / (math.sinh(bl) + math.sin(bl))
        tip = math.cosh(bl) - math.cos(bl) - s * (math.sinh(bl) - math.sin(bl))
        slope = b * (math.sinh(bl) + math.sin(bl) - s * (math.cosh(bl) - math.cos(bl)))

        def curv(x: float, b: float = b, s: float = s) -> float:
            return b * b * (math.cosh(b * x) + math.cos(b * x) - s * (math.sinh(b * x) + math.sin(b * x)))

        got = m.observed[:, k] / m.sensor_shapes[0, k]
        want = np.array([slope / tip, curv(0.1 * L) / tip, curv(0.5 * L) / tip])
        np.testing.assert_allclose(got, want, rtol=0, atol=3e-3 * np.max(np.abs(want)))
        f = bl**2 * math.sqrt(E * W * H**3 / 12 / (RHO * W * H)) / (2 * math.pi * L**2)
        assert abs(m.freq_hz[k] / f - 1) < 1e-3


def _tip_body_hz(m: float, e: float, J: float, n: int) -> np.ndarray:
    """First ``n`` frequencies [Hz] of the Euler-Bernoulli cantilever carrying a rigid body (mass ``m``,
    centre ``e`` beyond the tip along the axis, inertia ``J`` about its centre).  From the stationarity
    of U - w^2 T with the body's T = m (v + e v')^2 / 2 + J v'^2 / 2 at x = L:
    EI v''' = -w^2 m (v + e v') and EI v'' = w^2 (m e (v + e v') + J v'); v = A (cosh bx - cos bx)
    + B (sinh bx - sin bx) satisfies the clamp; the roots in b of the 2 x 2 determinant."""
    from scipy.optimize import brentq

    EI, mu = E * W * H**3 / 12, RHO * W * H

    def det(b: float) -> float:
        ch, sh, c, s = math.cosh(b * L), math.sinh(b * L), math.cos(b * L), math.sin(b * L)
        d = [(ch - c, sh - s), (b * (sh + s), b * (ch - c)), (b * b * (ch + c), b * b * (sh + s)),
             (b**3 * (sh - s), b**3 * (ch + c))]                  # v, v', v'', v''' for A and B at L
        w2 = b**4 * EI / mu
        rows = [[EI * d[3][k] + w2 * m * (d[0][k] + e * d[1][k]) for k in (0, 1)],
                [EI * d[2][k] - w2 * (m * e * (d[0][k] + e * d[1][k]) + J * d[1][k]) for k in (0, 1)]]
        return (rows[0][0] * rows[1][1] - rows[0][1] * rows[1][0]) / math.cosh(b * L) ** 2

    grid = np.linspace(0.1, 12.0, 4000) / L
    vals = np.array([det(b) for b in grid])
    change = np.flatnonzero(np.sign(vals[:-1]) != np.sign(vals[1:]))
    roots = [brentq(det, grid[i], grid[i + 1]) for i in change]
    return np.array([b * b * math.sqrt(EI / mu) / (2 * math.pi) for b in roots[:n]])


@pytest.mark.parametrize(("offset", "e", "J"), [((0.05, 0.0), 0.05, 0.0), ((0.0, 0.05), 0.0, 0.2 * 0.05**2)])
def test_offset_mass_matches_the_cantilever_with_an_eccentric_tip_body(offset, e, J):
    """A 0.2 kg tip mass whose centre sits ``offset`` (along, across) m from the bar's tip against the
    closed-form frequency equation (``_tip_body_hz``): along the axis exactly, across it as the rotary
    inertia m d^2 it adds while the bar is axially rigid (its axial mode is far above): 0.3 %."""
    rig = parse_rig(_cantilever({"mass": [{"name": "m", "at": "tip", "mass_kg": 0.2}]}))
    got = truth_modes(rig, {}, 3, dataclasses.replace(_euler_bernoulli(), mass_offset_m={"m": offset}))
    centred = _tip_body_hz(0.2, 0.0, 0.0, 3)
    np.testing.assert_allclose(got.freq_hz, _tip_body_hz(0.2, e, J, 3), rtol=3e-3)
    np.testing.assert_allclose(truth_modes(rig, {}, 3, _euler_bernoulli()).freq_hz, centred, rtol=1e-3)
    assert np.max(np.abs(got.freq_hz / centred - 1)) > 0.01      # and the offset matters here


def test_undeclared_sensor_mass_equals_declared_sensor_mass_in_the_frame_model():
    """``sensor_mass_kg`` on the demo arm (no sensor mass declared) against models/frame.py given the
    same 10 g at every sensor in the rig description: 0.1 %."""
    rig = load_rig(DEMO_RIG)
    options = TruthOptions(elements=80, sensor_mass_kg=0.01,
                           shear_flexibility={lk.name: 0.0 for lk in rig.links})
    got = truth_modes(rig, {"theta_deg": 60.0}, 4, options).freq_hz
    heavy = dataclasses.replace(rig, sensors=tuple(dataclasses.replace(s, mass_kg=0.01) for s in rig.sensors))
    ref = frame_modes(heavy, {"theta_deg": 60.0}, 6, elements_per_link=80).freq_hz
    np.testing.assert_allclose(got, ref[ref > 1e-3][:4], rtol=1e-3)
    bare = truth_modes(rig, {"theta_deg": 60.0}, 4, dataclasses.replace(options, sensor_mass_kg=0.0)).freq_hz
    assert np.all(got < bare)


def test_the_bench_arms_mesh_is_converged():
    """The default 40 elements a link against 160 (Timoshenko, bench features): 0.1 % on the first four
    modes of the demo arm (0.07 % on mode 3), so its departure (> 1 %) from the diagnosis's 10-element
    model is model form, not discretisation."""
    rig = load_rig(DEMO_RIG)
    opts = bench_arm(rig)
    coarse = truth_modes(rig, {"theta_deg": 90.0}, 4, opts).freq_hz
    fine = truth_modes(rig, {"theta_deg": 90.0}, 4, dataclasses.replace(opts, elements=160)).freq_hz
    np.testing.assert_allclose(coarse, fine, rtol=1e-3)
    fe = frame_modes(rig, {"theta_deg": 90.0}, 6).freq_hz
    assert np.max(np.abs(coarse / fe[fe > 1e-3][:4] - 1)) > 0.01


def test_rayleigh_damping_ratios_equal_the_damped_systems_eigenvalues():
    """C = alpha M + beta K on a 4-DOF system: zeta = -Re(lambda)/|lambda| of the state-space
    eigenvalues (an exact answer, no modal assumption) equals ``rayleigh_damping`` at w = |lambda|."""
    rng = np.random.default_rng(3)
    a = rng.standard_normal((4, 4))
    K = a @ a.T * 1e6 + 1e5 * np.eye(4)
    M = np.diag(rng.uniform(0.5, 2.0, 4))
    alpha, beta = BENCH_RAYLEIGH
    C = alpha * M + beta * K
    A = np.block([[np.zeros((4, 4)), np.eye(4)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam = eig(A, right=False)
    lam = lam[lam.imag > 0]
    w_n = np.abs(lam)
    np.testing.assert_allclose(np.sort(-lam.real / w_n), np.sort(rayleigh_damping(w_n / (2 * np.pi),
                                                                                  alpha, beta)), rtol=1e-9)


def test_the_bench_arms_impact_record_carries_its_modes_and_mode_dependent_damping():
    """An impact test of the bench arm (truth path) identified by pLSCF: frequencies within 0.1 %,
    damping within 5 % of the Rayleigh law (1.5 % on mode 1, ~0.65 % on mode 2), MAC >= 0.99; and
    H1 of a random test equals ``exact_frf`` (the truth's own modal superposition) within 2 % where
    coherence > 0.999."""
    rig = load_rig(DEMO_RIG)
    pose = {"theta_deg": 30.0}
    test = simulate(rig, pose, excitation="impact", duration_s=16.0, sample_rate_hz=512.0, snr_db=40,
                    seed=1, hit_period_s=4.0, truth=bench_arm(rig))
    np.testing.assert_allclose(test.damping_ratio, rayleigh_damping(test.natural_freq_hz, *BENCH_RAYLEIGH))
    assert test.damping_ratio[0] > 2 * test.damping_ratio[1]
    triggers = [e.sample_index for e in test.events if e.kind == "trigger"]
    res = frf_of_record(test.samples, test.sample_rate_hz, [c.name for c in test.channels],
                        [c.kind for c in test.channels], excitation="impact", triggers=triggers, nfft=8192,
                        window="force:0.02,exponential:0.05")
    modes = identify(res.freq_hz, res.H, fmin=2, fmax=150, decay_rate_per_s=res.decay_rate_per_s,
                     max_order=60)
    for k in np.flatnonzero(test.natural_freq_hz < 140):
        j = int(np.argmin(np.abs(modes.freq_hz - test.natural_freq_hz[k])))
        assert abs(modes.freq_hz[j] / test.natural_freq_hz[k] - 1) < 1e-3
        assert abs(modes.damping_ratio[j] / test.damping_ratio[k] - 1) < 0.05
        assert mac(modes.shapes[:, j], test.shapes[:, k])[0, 0] >= 0.99
    rnd = simulate(rig, pose, excitation="random", duration_s=60.0, sample_rate_hz=512.0, snr_db=60, seed=2,
                   truth=bench_arm(rig))
    res = frf_of_record(rnd.samples, rnd.sample_rate_hz, [c.name for c in rnd.channels],
                        [c.kind for c in rnd.channels], nfft=1024)
    exact = rnd.exact_frf(res.freq_hz)[:, 0]
    good = (res.coherence > 0.999) & (res.freq_hz > 10)
    assert good.sum() > 100
    np.testing.assert_allclose(res.H[:, 0][good], exact[good], rtol=0.02)


def test_options_naming_nothing_in_the_rig_are_refused():
    """An offset for a mass the rig does not have, or an unknown observed quantity, is one clear error."""
    from flexmodal.fixtures.errors import FixtureError

    rig = load_rig(DEMO_RIG)
    with pytest.raises(FixtureError, match="'motor' is not a mass of rig 'demo-arm'"):
        truth_modes(rig, {"theta_deg": 0.0}, 2, TruthOptions(mass_offset_m={"motor": (0.0, 0.01)}))
    with pytest.raises(FixtureError, match="'twist' is not one of"):
        truth_modes(rig, {"theta_deg": 0.0}, 2, observe=[("tip", "twist")])


def test_exact_frf_of_a_truth_path_test_is_the_frf_of_its_own_records():
    """One hammer hit on the bench arm, noise-free, decayed to e^-30 within the record: the DFT of each
    clean acceleration over the DFT of the clean force is ``exact_frf`` on every line up to 0.45 fs
    (linear convolution equals circular here), to 1e-8 of its peak (1.4e-10 measured): the exact
    reference is the simulated system."""
    rig = load_rig(DEMO_RIG)
    test = simulate(rig, {"theta_deg": 60.0}, excitation="impact", duration_s=8.0, sample_rate_hz=1024.0,
                    hit_period_s=100.0, truth=bench_arm(rig))
    n = test.clean.shape[0]
    freq = np.fft.rfftfreq(n, 1 / test.sample_rate_hz)
    spectra = np.fft.rfft(test.clean, axis=0)
    lines = freq < 0.45 * test.sample_rate_hz
    ratio = spectra[lines, 1:1 + len(rig.sensors)] / spectra[lines, :1]
    exact = test.exact_frf(freq[lines])[:, 0]
    np.testing.assert_allclose(ratio.T, exact, rtol=0, atol=1e-8 * np.abs(exact).max())
