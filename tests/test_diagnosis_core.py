"""Diagnosis numerics against exact answers: Ritz models vs full FE, sensitivities, recovery, gap metrics."""

from __future__ import annotations

import numpy as np
import pytest

from flexmodal.compare.diagnosis import diagnose, folds_for
from flexmodal.compare.gap import comac, damped_frequency_shift, gap_summary
from flexmodal.compare.parametric import handles_for, lam_to_hz, pose_basis, reduce_family, solve_family
from flexmodal.contract.mac import mac_pairs as mac
from flexmodal.contract.table import ModalTable
from flexmodal.models.effects import apply_effect
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import load_rig

POSES = [{"theta_deg": t} for t in (0.0, 45.0, 90.0, 135.0)]


@pytest.fixture(scope="module")
def rig(rigs_dir):
    return load_rig(rigs_dir / "seed003_two_link.toml")


@pytest.fixture(scope="module")
def bases(rig):
    handles = handles_for(rig)
    return handles, [pose_basis(rig, handles, p, 4) for p in POSES]


@pytest.mark.parametrize("effects", [
    [("joint_stiffness", "elbow", {"k_Nm_per_rad": 400.0})],
    [("tip_mass", "tip", {"mass_kg": 0.3, "inertia_kgm2": 1e-3})],
    [("grounded_spring", "link2@0.5", {"k_N_per_m": 5e3})],
    [("link_stiffness", "link2", {"scale": 0.6}), ("base_stiffness", "base", {"k_Nm_per_rad": 3e3})],
    [("sensor_mass", "sensors", {"mass_kg": 0.05}), ("link_mass", "link1", {"scale": 1.7})],
])
def test_reduced_model_matches_full_fe(rig, bases, effects):
    handles, pb = bases
    names = [h.name for h in handles]
    key = {"joint_stiffness": "k@elbow", "tip_mass": "m@tip", "grounded_spring": "ks@link2@0.5",
           "link_stiffness": "EI@link2", "base_stiffness": "k@base", "sensor_mass": "m@sensors",
           "link_mass": "mu@link1"}
    idx, vals = [], []
    for effect, _, params in effects:
        idx.append(names.index(key[effect]))
        vals.append(next(iter(params.values())))
        if effect == "tip_mass":
            idx.append(names.index("J@tip"))
            vals.append(params["inertia_kgm2"])
    fam = reduce_family(pb, idx, np.array([handles[i].nominal for i in idx]))
    lam, _, _ = solve_family(fam, np.tile(np.array(vals), (1, len(POSES), 1)), 4)
    augmented = rig
    for effect, loc, params in effects:
        augmented = apply_effect(augmented, effect, loc, params)
    full = np.array([frame_modes(augmented, p, 4).freq_hz for p in POSES])
    np.testing.assert_allclose(lam_to_hz(lam)[0], full, rtol=1e-3)  # Ritz basis: <= 0.1 %


def test_eigenvalue_sensitivities_match_finite_differences(rig, bases):
    handles, pb = bases
    names = [h.name for h in handles]
    idx = [names.index("k@elbow"), names.index("m@tip")]
    fam = reduce_family(pb, idx, np.array([handles[i].nominal for i in idx]))
    h = np.tile(np.array([800.0, 0.1]), (1, len(POSES), 1))
    lam, dlam, _ = solve_family(fam, h, 4)
    for j, step in ((0, 0.8), (1, 1e-4)):
        h2 = h.copy()
        h2[..., j] += step
        lam2, _, _ = solve_family(fam, h2, 4)
        np.testing.assert_allclose((lam2 - lam) / step, dlam[..., j], rtol=2e-3)


def _table(rig, augmented, poses, n=4):
    recs = []
    for i, p in enumerate(poses):
        f = frame_modes(augmented, p, n).freq_hz
        recs += [{"config": f"c{i}", "mode": k + 1, "freq_hz": f[k], "pose.theta_deg": p["theta_deg"]}
                 for k in range(n)]
    return ModalTable.from_records(recs, "<synthetic>")


def test_noise_free_joint_stiffness_is_recovered_exactly(rig):
    k_true = 2500.0
    table = _table(rig, apply_effect(rig, "joint_stiffness", "elbow", {"k_Nm_per_rad": k_true}), POSES)
    res = diagnose(rig, table, effects="joint_stiffness,tip_mass,link_stiffness")
    top = res.ranking[0]
    assert (top.effect, top.location) == ("joint_stiffness", "elbow")
    assert top.params["k_Nm_per_rad"] == pytest.approx(k_true, rel=1e-3)
    assert top.heldout_rms_rel_error < 1e-4
    assert res.verdict.explained is True


def test_no_effect_gives_none(rig):
    """Exact nominal data: ``none``; the singles fitted to say what might be there do no better held out
    than the nominal model, so the verdict is not ambiguous."""
    res = diagnose(rig, _table(rig, rig, POSES))
    assert res.verdict.effect == "none" and not res.verdict.ambiguous and not res.verdict.alternatives
    assert all(r.heldout_rms_rel_error < 1e-4 for r in res.ranking)
    assert res.baseline.rms_rel_error < 1e-5


def test_gap_summary_and_folds():
    err = np.array([[0.1, -0.3], [0.0, 0.4]])
    s = gap_summary(err, ("a", "b"))
    assert s["rms_rel_error"] == pytest.approx(np.sqrt((0.01 + 0.09 + 0.16) / 4), rel=1e-14)
    assert s["max_rel_error"] == 0.4
    assert s["per_mode"]["2"] == pytest.approx(np.sqrt((0.09 + 0.16) / 2), rel=1e-14)
    assert s["per_config"]["a"] == pytest.approx(np.sqrt(0.05), rel=1e-14)
    train, scheme = folds_for(["a", "b", "c"], "auto")
    assert scheme == "leave-one-configuration-out"
    np.testing.assert_array_equal(train, [[1, 1, 1], [0, 1, 1], [1, 0, 1], [1, 1, 0]])
    train, _ = folds_for(["a", "b", "c", "d"], "b,d")
    np.testing.assert_array_equal(train, [[1, 1, 1, 1], [1, 0, 1, 0]])


def test_mac_comac_and_damping_shift():
    a = np.array([[1.0, 0.0], [2.0, 1.0], [3.0, -1.0]])
    np.testing.assert_allclose(mac(a, -2 * a), [1.0, 1.0], rtol=1e-14)
    assert mac(a[:, :1], a[:, 1:])[0] == pytest.approx((2 - 3) ** 2 / (14 * 2), rel=1e-14)
    np.testing.assert_allclose(comac(a[None], 3 * a[None]), [1.0, 1.0, 1.0], rtol=1e-14)
    assert damped_frequency_shift(0.13) == pytest.approx(1 - np.sqrt(1 - 0.13**2), rel=1e-14)
    assert damped_frequency_shift(0.13) < 0.0086
