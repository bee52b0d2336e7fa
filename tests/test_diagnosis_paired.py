"""The diagnosis' nested comparisons are paired, and its ``none`` test trusts no scatter above what a
candidate predicts held out (issue 26: a weak effect declared ``none``, a pair reduced to one part)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import t as student_t
from scipy.stats import ttest_1samp

from flexmodal.compare.diagnosis import _beam_theory_form, _equivalent, _noise, _paired_noise, diagnose
from flexmodal.contract.table import ModalTable
from flexmodal.fixtures.blind import _measure, random_rig
from flexmodal.fixtures.truth_arm import TruthOptions
from flexmodal.models.effects import apply_effect
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig


def _entry(ctx, err: np.ndarray, scatter: float) -> dict:
    eq, dof = _equivalent(ctx, err, np.zeros(0), scatter)
    return {"_held_err": err, "_held_shape": np.zeros(0), "_heldout_eq": eq, "_n_eq": dof}


@pytest.mark.parametrize("gain", [0.1, 0.25, 0.5])
def test_paired_margin_is_the_paired_t_test_on_the_residuals(gain):
    """Two candidates leave the same held-out residuals but for a part one of them removes: the margin
    is crossed exactly when the one-sample t statistic of the per-residual chi-square differences
    (scipy.stats.ttest_1samp) exceeds its two-sided 95 % quantile, and it is below the unpaired margin,
    which counts what both leave alike as noise."""
    rng = np.random.default_rng(4)
    ctx = SimpleNamespace(shape_dof=0, shape_floor=math.inf, pose_share=1.0)
    scatter = 0.005
    common = scatter * rng.standard_normal(60)
    part = 0.004 * rng.standard_normal(60)
    a = _entry(ctx, common + part, scatter)                # without the part
    b = _entry(ctx, common + (1 - gain) * part, scatter)   # removes a share of it
    t = ttest_1samp(((common + part) ** 2 - (common + (1 - gain) * part) ** 2) / scatter**2, 0.0).statistic
    q = student_t.ppf(0.975, 59)
    margin = _paired_noise(ctx, a, b, scatter)
    assert (a["_heldout_eq"] - b["_heldout_eq"] > margin) == (t > q)
    unpaired = _noise(b, scatter)
    if margin < unpaired:
        assert a["_heldout_eq"] - b["_heldout_eq"] == pytest.approx(margin * t / q, rel=1e-9)
    assert margin <= unpaired


def _table(rig, real, angles, scatter, rng, repeat_dev=0.0):
    """Two modes at each angle with relative noise ``scatter``; the first and last angles measured
    twice, the repeat ``repeat_dev`` apart in ln f (a repeat scatter of ``repeat_dev / sqrt(2)``)."""
    recs = []
    for i, th in enumerate(list(angles) + [angles[0], angles[-1]]):
        f = frame_modes(real, {"theta_deg": th}, 2).freq_hz * (1 + scatter * rng.standard_normal(2))
        if i >= len(angles):
            f = next(r for r in recs if r["config"] == f"theta{th:g}")["_f"] * math.exp(repeat_dev)
        name = f"theta{th:g}" + ("b" if i >= len(angles) else "")
        recs += [{"config": name, "mode": k + 1, "freq_hz": f[k], "pose.theta_deg": th, "_f": f}
                 for k in range(2)]
    return ModalTable.from_records([{k: v for k, v in r.items() if k != "_f"} for r in recs], "<weak>")


def test_a_weak_effect_is_not_declared_none_by_an_overestimated_repeat_scatter(rigs_dir):
    """A weak elbow stiffness (1.3 % gap) measured to 0.2 % with two repeats that disagree by 1 %
    (repeat scatter 0.71 %): the gap is within twice the repeat scatter, but the elbow stiffness
    predicts unseen poses far better than that, so the verdict is the stiffness; the same data without
    the effect stay ``none``."""
    rig = load_rig(rigs_dir / "seed003_two_link.toml")
    angles = (0, 30, 60, 90, 120, 150)
    real = apply_effect(rig, "joint_stiffness", "elbow", {"k_Nm_per_rad": 1.5e5})
    weak = diagnose(rig, _table(rig, real, angles, 0.002, np.random.default_rng(1), 0.010),
                    effects="joint_stiffness,link_stiffness,tip_mass")
    assert weak.scatter_source.source == "repeated configurations"
    assert weak.baseline.rms_rel_error <= 2 * weak.scatter_source.measurement     # the old test: none
    assert (weak.verdict.effect, weak.verdict.location) == ("joint_stiffness", "elbow")
    nothing = diagnose(rig, _table(rig, rig, angles, 0.002, np.random.default_rng(1), 0.010),
                       effects="joint_stiffness,link_stiffness,tip_mass")
    assert nothing.verdict.effect == "none"


def test_beam_theory_form_is_timoshenkos_first_order_correction():
    """The model-form level of an Euler-Bernoulli frame (``_beam_theory_form``) against the exact
    frequencies of a simply supported uniform Timoshenko beam (the lower root of ``EI k^4 - w^2 (rho A +
    rho I k^2 + rho A EI k^2 / (kappa G A)) + w^4 rho A rho I / (kappa G A) = 0``, ``k = n pi / L``;
    Han, Benaroya & Wei 1999): for the first four modes of a thin-walled aluminium tube (kappa 0.5,
    nu 0.3) the relative error ``f_EB / f_T - 1`` (1.1-16 %) is within 5 % of the level at the true
    frequency."""
    from flexmodal.compare.diagnosis import _beam_theory_form
    from flexmodal.models.rig import parse_rig

    rig = parse_rig({"name": "tube", "material": {"al": {"E_Pa": 70e9, "rho_kg_m3": 2700}},
                     "link": [{"name": "l", "length_m": 0.5, "material": "al",
                               "section": {"shape": "square_tube", "outer_m": 0.025, "wall_m": 0.0015}}]},
                    "<test>")
    sec = rig.links[0].section
    EI, EA, mu, rho_i = sec.EI_Nm2, sec.EA_N, sec.mass_per_m_kg, sec.rotary_inertia_per_m_kgm
    kga = 0.5 * EA / (2 * 1.3)
    for n in range(1, 5):
        k = n * math.pi / 0.5
        a, b, c = mu * rho_i / kga, -(mu + rho_i * k**2 + mu * EI * k**2 / kga), EI * k**4
        w_t = math.sqrt((-b - math.sqrt(b * b - 4 * a * c)) / (2 * a))
        w_eb = k * k * math.sqrt(EI / mu)
        level = _beam_theory_form(rig, np.array([[w_t / (2 * math.pi)]]))
        assert level == pytest.approx(w_eb / w_t - 1.0, rel=0.05)


def test_a_gap_the_beam_theory_explains_needs_no_effect():
    """No effect on an arm of the blind generator (axial-sensor rig, ``random_rig(default_rng(15))``)
    measured by the independent Timoshenko truth model (fixtures/truth_arm.py) at six poses, 4 modes,
    0.2 % scatter given as ``freq_std_hz``: the Euler-Bernoulli frame's gap (0.57 % RMS) is almost all
    its known shear/rotary-inertia error (0.54 % by ``_beam_theory_form``), well beyond twice the
    scatter.  Without that level in the ``none`` test a link stiffness took it (blind draw 316 #14 is
    such a case); with it the verdict is ``none``."""
    rig = random_rig(np.random.default_rng(15), "axial")
    poses = [{"theta_deg": float(t)} for t in (0, 30, 60, 90, 120, 150)]
    freq, _ = _measure(rig, poses, 4, TruthOptions(), ())
    noisy = freq * (1 + 0.002 * np.random.default_rng(1).standard_normal(freq.shape))
    table = ModalTable.from_records(
        [{"config": f"c{c}", "mode": k + 1, "freq_hz": noisy[c, k], "freq_std_hz": 0.002 * noisy[c, k],
          "pose.theta_deg": p["theta_deg"]} for c, p in enumerate(poses) for k in range(freq.shape[1])],
        "<model form only>")
    result = diagnose(rig, table)
    assert result.baseline.rms_rel_error > 2.5 * result.scatter_source.measurement
    assert abs(_beam_theory_form(rig, freq) - 0.0054) < 0.0005
    assert result.verdict.effect == "none"
