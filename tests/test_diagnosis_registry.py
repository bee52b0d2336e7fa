"""The effect registry (models/effects.py): a new effect is one entry, and the rig augmentation, the
candidates, the fast parametric model and the diagnosis all see it.  The toy effect lives, whole, in
tests/toys/toy_effect.py: a grounded spring along the axis of the last link at the tip."""

from __future__ import annotations

import importlib
import math
import sys

import numpy as np
import pytest

from flexmodal.compare.candidates import parse_effects, single_candidates
from flexmodal.compare.diagnosis import diagnose
from flexmodal.compare.parametric import handles_for, lam_to_hz, pose_basis, reduce_family, solve_family
from flexmodal.contract.table import ModalTable
from flexmodal.models import effects as fx
from flexmodal.models.errors import ModelError
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import Point, Rig, Spring, load_rig

POSES = [{"theta_deg": t} for t in (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)]


@pytest.fixture
def toy():
    """The toy effect of tests/toys/toy_effect.py, registered by importing it and unregistered after."""
    module = importlib.import_module("toys.toy_effect")
    yield module.NAME
    fx.unregister_effect(module.NAME)
    sys.modules.pop("toys.toy_effect")


def _tip(rig: Rig) -> Point:
    return importlib.import_module("toys.toy_effect").tip_point(rig)


@pytest.fixture(scope="module")
def rig(rigs_dir):
    return load_rig(rigs_dir / "seed003_two_link.toml")


def test_the_builtin_library_is_the_registry():
    assert fx.registered_effects() == fx.EFFECTS == tuple(fx.REGISTRY)
    assert all(isinstance(e, fx.Effect) for e in fx.REGISTRY.values())
    units = {p.name: p.unit for e in fx.REGISTRY.values() for p in e.params}
    assert units["k_Nm_per_rad"] == "N m/rad" and units["k_N_per_m"] == "N/m" and units["mass_kg"] == "kg"


def test_a_registered_effect_augments_the_rig_and_is_checked(toy, rig):
    assert toy in parse_effects("all") and parse_effects(toy) == (toy,)
    assert fx.effect_locations(rig, toy) == ["tip"]
    out = fx.apply_effect(rig, toy, "tip", {"k_N_per_m": 2e5})
    assert out.springs[-1] == Spring(_tip(rig), 2e5, "axial", name=f"{toy}@tip")
    with pytest.raises(ModelError, match="k_N_per_m.*N/m"):
        fx.apply_effect(rig, toy, "tip", {})
    with pytest.raises(ModelError, match=r"'k_N_per_m' must be finite and >= 0 \(got -1.0\)"):
        fx.apply_effect(rig, toy, "tip", {"k_N_per_m": -1.0})
    with pytest.raises(ModelError, match="does not apply at 'base'"):
        fx.apply_effect(rig, toy, "base", {"k_N_per_m": 1.0})
    cands = single_candidates(rig, (toy,), {})
    assert [(c.effect, c.location, c.handles) for c in cands] == [(toy, "tip", ("ka@tip",))]


def test_the_fast_model_of_a_registered_effect_matches_the_full_fe(toy, rig):
    handles = handles_for(rig)
    names = [h.name for h in handles]
    assert names[-1] == "ka@tip" and names[:-1] == [h.name for h in handles_for(rig) if h.effect != toy]
    k = 3e5
    idx = [names.index("ka@tip")]
    bases = [pose_basis(rig, handles, p, 4) for p in POSES]
    fam = reduce_family(bases, idx, np.array([0.0]))
    lam, _, _ = solve_family(fam, np.full((1, len(POSES), 1), k), 4)
    full = np.array([frame_modes(fx.apply_effect(rig, toy, "tip", {"k_N_per_m": k}), p, 4).freq_hz
                     for p in POSES])
    nominal = np.array([frame_modes(rig, p, 4).freq_hz for p in POSES])
    assert np.max(np.abs(full / nominal - 1)) > 0.05          # the effect is visible ...
    np.testing.assert_allclose(lam_to_hz(lam)[0], full, rtol=1e-3)   # ... and the Ritz model exact to 0.1 %


def test_a_registered_effect_is_diagnosed_and_fitted(toy, rig):
    k_true = 3e5
    real = fx.apply_effect(rig, toy, "tip", {"k_N_per_m": k_true})
    recs = []
    for i, p in enumerate(POSES):
        f = frame_modes(real, p, 4).freq_hz
        recs += [{"config": f"c{i}", "mode": m + 1, "freq_hz": f[m], "pose.theta_deg": p["theta_deg"]}
                 for m in range(4)]
    result = diagnose(rig, ModalTable.from_records(recs, "<toy>"), scatter=0.002)
    v = result.verdict
    assert (v.effect, v.location, v.explained) == (toy, "tip", True)
    assert math.isclose(v.params["k_N_per_m"], k_true, rel_tol=0.01)
    assert v.heldout_rms_rel_error_after < 1e-3
    assert toy in {e.effect for e in result.ranking}
