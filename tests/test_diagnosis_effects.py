"""models/effects.py: every effect of docs/formats.md, where it applies and what it changes in the rig."""

from __future__ import annotations

import math

import pytest

from flexmodal.models.effects import EFFECT_PARAMS, EFFECTS, apply_effect, effect_locations, pose_stiffness
from flexmodal.models.errors import ModelError
from flexmodal.models.rig import load_rig, parse_rig

PUSHER_RIG = {
    "name": "pusher",
    "material": {"al": {"E_Pa": 70e9, "rho_kg_m3": 2700}},
    "link": [
        {"name": "lower", "length_m": 1.0, "material": "al",
         "section": {"shape": "round_tube", "outer_m": 0.14, "wall_m": 0.0034}},
        {"name": "upper", "length_m": 1.0, "material": "al",
         "section": {"shape": "round_tube", "outer_m": 0.11, "wall_m": 0.003}},
    ],
    "base": {"support": "pinned"},
    "joint": [{"name": "elbow", "parent": "lower", "child": "upper", "angle": "theta_deg"}],
    "member": [{"name": "pusher", "from": "lower@0.3", "to": "upper@0.1", "material": "al",
                "section": {"shape": "rect_tube", "width_m": 0.1, "height_m": 0.044, "wall_m": 0.003}}],
    "sensor": [{"name": "s1", "at": "upper@1.0", "mass_kg": 0.01}],
}


@pytest.fixture(scope="module")
def seed003(rigs_dir):
    return load_rig(rigs_dir / "seed003_two_link.toml")


def test_effect_names_are_the_contract_ones():
    assert EFFECTS == ("joint_stiffness", "joint_stiffness_pose", "joint_mass", "tip_mass", "base_stiffness",
                       "end_restraint", "sensor_mass", "grounded_spring", "link_stiffness", "link_mass")
    assert set(EFFECT_PARAMS) == set(EFFECTS)


def test_locations_on_seed003(seed003):
    assert effect_locations(seed003, "joint_stiffness") == ["elbow"]
    assert effect_locations(seed003, "joint_stiffness_pose") == ["elbow"]
    assert effect_locations(seed003, "joint_mass") == ["elbow"]  # clamped base: no hub location
    assert effect_locations(seed003, "tip_mass") == ["tip"]
    assert effect_locations(seed003, "base_stiffness") == ["base"]
    assert effect_locations(seed003, "end_restraint") == []
    assert effect_locations(seed003, "sensor_mass") == ["sensors"]
    assert effect_locations(seed003, "grounded_spring") == [
        "link1@0.25", "link1@0.5", "link1@0.75", "link1@1",
        "link2@0.25", "link2@0.5", "link2@0.75", "link2@1"]
    assert effect_locations(seed003, "link_stiffness") == ["link1", "link2"]
    assert effect_locations(seed003, "link_mass") == ["link1", "link2"]


def test_locations_with_member_and_pinned_base():
    rig = parse_rig(PUSHER_RIG, "pusher.toml")
    assert effect_locations(rig, "end_restraint") == ["pusher"]
    assert effect_locations(rig, "joint_mass") == ["base", "elbow"]
    assert "lower@0.25" in effect_locations(rig, "grounded_spring")


def test_joint_stiffness_replaces_the_rigid_joint(seed003):
    out = apply_effect(seed003, "joint_stiffness", "elbow", {"k_Nm_per_rad": 13100.0})
    assert out.joint("elbow").kind == "spring" and out.joint("elbow").k_Nm_per_rad == 13100.0
    assert seed003.joint("elbow").kind == "rigid"  # the nominal rig is untouched


def test_pose_law_is_log_quadratic(seed003):
    params = {"k_Nm_per_rad": 1000.0, "log_slope_per_rad": 0.5, "log_curv_per_rad2": -0.2}
    q = math.radians(90.0)
    assert pose_stiffness(params, 90.0) == pytest.approx(1000.0 * math.exp(0.5 * q - 0.2 * q * q), rel=1e-14)
    out = apply_effect(seed003, "joint_stiffness_pose", "elbow", params, pose={"theta_deg": 90.0})
    assert out.joint("elbow").k_Nm_per_rad == pytest.approx(pose_stiffness(params, 90.0), rel=1e-14)
    with pytest.raises(ModelError, match="theta_deg"):
        apply_effect(seed003, "joint_stiffness_pose", "elbow", params)


def test_masses_are_added_at_joint_tip_and_hub(seed003):
    out = apply_effect(seed003, "joint_mass", "elbow", {"mass_kg": 0.2, "inertia_kgm2": 1e-4})
    (m,) = out.masses
    assert (m.at.link, m.at.fraction, m.mass_kg, m.inertia_kgm2) == ("link2", 0.0, 0.2, 1e-4)
    out = apply_effect(out, "tip_mass", "tip", {"mass_kg": 0.05})
    tip = out.masses[1]
    assert (tip.at.link, tip.at.fraction, tip.inertia_kgm2) == ("link2", 1.0, 0.0)
    hub = apply_effect(parse_rig(PUSHER_RIG), "joint_mass", "base", {"mass_kg": 0.0, "inertia_kgm2": 0.3})
    assert (hub.masses[0].at.link, hub.masses[0].at.fraction) == ("lower", 0.0)


def test_base_member_sensor_spring_and_link_effects(seed003):
    assert apply_effect(seed003, "base_stiffness", "base", {"k_Nm_per_rad": 5e4}).base.support == "spring"
    pusher = apply_effect(parse_rig(PUSHER_RIG), "end_restraint", "pusher", {"k_Nm_per_rad": 800.0})
    assert pusher.members[0].end_k_Nm_per_rad == 800.0
    loaded = apply_effect(parse_rig(PUSHER_RIG), "sensor_mass", "sensors", {"mass_kg": 0.0024})
    assert loaded.sensors[0].mass_kg == pytest.approx(0.0124, rel=1e-14)
    sprung = apply_effect(seed003, "grounded_spring", "link2@0.5", {"k_N_per_m": 2e3})
    (s,) = sprung.springs
    assert (s.at.link, s.at.fraction, s.k_N_per_m, s.direction) == ("link2", 0.5, 2e3, "transverse")
    twice = apply_effect(apply_effect(seed003, "link_stiffness", "link2", {"scale": 0.5}),
                         "link_stiffness", "link2", {"scale": 0.5})
    assert twice.link("link2").stiffness_scale == 0.25 and twice.link("link1").stiffness_scale == 1.0
    assert apply_effect(seed003, "link_mass", "link1", {"scale": 1.3}).link("link1").mass_scale == 1.3


def test_bad_location_and_params_name_the_problem(seed003):
    with pytest.raises(ModelError, match="'shoulder'"):
        apply_effect(seed003, "joint_stiffness", "shoulder", {"k_Nm_per_rad": 1.0})
    with pytest.raises(ModelError, match="k_Nm_per_rad"):
        apply_effect(seed003, "joint_stiffness", "elbow", {})
    with pytest.raises(ModelError, match="unknown effect"):
        effect_locations(seed003, "gearbox_backlash")
    with pytest.raises(ModelError, match="scale"):
        apply_effect(seed003, "link_mass", "link1", {"scale": -1.0})
