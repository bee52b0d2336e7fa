"""Planar frame FE (models/frame.py) against exact answers: Blevins' beam roots, statics, seed 003 Table 6."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from flexmodal.models.frame import assemble, frame_modes, frame_modes_many, solve_modes
from flexmodal.models.rig import load_rig, parse_rig

EI, MU, L = 3240.0, 0.4621, 1.36  # N m^2, kg/m, m  (seed 003's tube, whole arm length)


def beam_doc(support: str = "clamped", links: int = 1, **extra) -> dict:
    """A uniform Euler-Bernoulli beam (no rotary inertia) of total length L split into ``links`` links."""
    section = {"shape": "custom", "EA_N": 1.28e7, "EI_Nm2": EI, "mass_per_m_kg": MU,
               "rotary_inertia_per_m_kgm": 0.0}
    doc = {"name": "beam", "base": {"support": support},
           "link": [{"name": f"l{i + 1}", "length_m": L / links, "section": section} for i in range(links)],
           "joint": [{"name": f"j{i + 1}", "parent": f"l{i + 1}", "child": f"l{i + 2}", "angle_deg": 0.0}
                     for i in range(links - 1)]}
    doc.update(extra)
    return doc


def lam_to_hz(lam: np.ndarray, length: float = L) -> np.ndarray:
    return np.asarray(lam) ** 2 / (2 * math.pi * length**2) * math.sqrt(EI / MU)


def test_clamped_free_matches_blevins_roots():
    f = frame_modes(parse_rig(beam_doc()), {}, 3).freq_hz
    exact = lam_to_hz([1.87510407, 4.69409113, 7.85475744])
    assert np.max(np.abs(f / exact - 1)) < 1e-3  # measured 2.5e-4 (mode 3) with the default 10 elements


def test_lumped_mass_converges_to_the_same_roots():
    f = frame_modes(parse_rig(beam_doc()), {}, 3, elements_per_link=40, lumped_mass=True).freq_hz
    assert np.max(np.abs(f / lam_to_hz([1.87510407, 4.69409113, 7.85475744]) - 1)) < 3e-3


def test_free_free_beam_has_three_rigid_modes_then_4_730():
    modes = frame_modes(parse_rig(beam_doc("free")), {}, 5)
    assert np.all(modes.freq_hz[:3] < 1e-3 * modes.freq_hz[3])
    assert modes.freq_hz[3] == pytest.approx(lam_to_hz(4.73004074), rel=1e-4)
    assert modes.freq_hz[4] == pytest.approx(lam_to_hz(7.85320462), rel=5e-4)


def test_stiff_grounded_spring_gives_clamped_pinned_without_ill_conditioning():
    def f(k: float) -> np.ndarray:
        doc = beam_doc(spring=[{"at": "tip", "k_N_per_m": k, "direction": "transverse"}])
        return frame_modes(parse_rig(doc), {}, 2).freq_hz

    assert f(1e12) / lam_to_hz([3.92660231, 7.06858275]) == pytest.approx([1, 1], abs=5e-4)
    # the compliance 1/k shows as a clean 1/k trend up to 1e20 (no digits lost to the stiff spring)
    gap14, gap16 = f(1e14) - f(1e20), f(1e16) - f(1e20)
    assert gap14 == pytest.approx(100 * gap16, rel=1e-2)
    assert f(1e18) == pytest.approx(f(1e20), rel=1e-12)


def test_joint_spring_limits_rigid_and_pin():
    rigid = frame_modes(parse_rig(beam_doc(links=2)), {}, 4).freq_hz
    stiff = beam_doc(links=2)
    stiff["joint"][0].update(kind="spring", k_Nm_per_rad=1e15)
    assert frame_modes(parse_rig(stiff), {}, 4).freq_hz == pytest.approx(rigid, rel=1e-11)
    pin = beam_doc(links=2)
    pin["joint"][0].update(kind="pin")
    soft = beam_doc(links=2)
    soft["joint"][0].update(kind="spring", k_Nm_per_rad=1e-9)
    f_pin = frame_modes(parse_rig(pin), {}, 4).freq_hz
    assert f_pin[0] < 1e-3  # the outer link swings freely
    assert frame_modes(parse_rig(soft), {}, 4).freq_hz[1:] == pytest.approx(f_pin[1:], rel=1e-8)


def test_member_equals_an_axial_spring():
    """A massless pin-pin bar from ground to the tip acts as a spring EA/L along the bar."""
    bar = {"shape": "custom", "EA_N": 2.0e4, "EI_Nm2": 1e-6, "mass_per_m_kg": 1e-12,
           "rotary_inertia_per_m_kgm": 0.0}
    with_member = beam_doc(member=[{"name": "prop", "from": "ground@1.36,-0.5", "to": "tip", "section": bar,
                                    "elements": 1}])
    with_spring = beam_doc(spring=[{"at": "tip", "k_N_per_m": 2.0e4 / 0.5, "direction": "y"}])
    f_member = frame_modes(parse_rig(with_member), {}, 4).freq_hz
    assert f_member == pytest.approx(frame_modes(parse_rig(with_spring), {}, 4).freq_hz, rel=1e-6)


def test_statics_tip_load_is_exact():
    """Cantilever with a tip load P: deflection, slope and curvature are exact for Hermite elements."""
    rig = parse_rig(beam_doc(links=2))
    sys_ = assemble(rig, {})
    P = 10.0
    f = P * sys_.observe("tip", "transverse")  # a unit tip force is the transverse row
    u = np.linalg.solve(sys_.K, f)
    for frac in (0.33, 1.0):
        x = frac * L / 2
        w = P * x**2 * (3 * L - x) / (6 * EI)
        assert sys_.observe(f"l1@{frac}", "transverse") @ u == pytest.approx(w)
        assert sys_.observe(f"l1@{frac}", "rotation") @ u == pytest.approx(P * x * (2 * L - x) / (2 * EI))
        assert sys_.observe(f"l1@{frac}", "curvature") @ u == pytest.approx(P * (L - x) / EI)
    assert sys_.observe("tip", "y") @ u == pytest.approx(P * L**3 / (3 * EI))
    assert sys_.observe("tip", "x") @ u == pytest.approx(0.0, abs=1e-15)
    assert not np.any(sys_.joint_rotation("j1"))  # rigid joint: zero row


def test_spring_joint_relative_rotation_is_moment_over_k():
    doc = beam_doc(links=2)
    doc["joint"][0].update(kind="spring", k_Nm_per_rad=500.0)
    sys_ = assemble(parse_rig(doc), {})
    u = np.linalg.solve(sys_.K, 3.0 * sys_.observe("tip", "transverse"))
    assert sys_.joint_rotation("j1") @ u == pytest.approx(3.0 * (L / 2) / 500.0)


def test_modes_are_mass_normalised_with_a_deterministic_sign(rigs_dir):
    rig = load_rig(rigs_dir / "demo_arm.toml")
    sys_ = assemble(rig, {"theta_deg": 45.0})
    modes = solve_modes(sys_, 4)
    assert modes.phi.T @ sys_.M @ modes.phi == pytest.approx(np.eye(4), abs=1e-9)
    omega2 = (2 * np.pi * modes.freq_hz) ** 2
    assert modes.phi.T @ sys_.K @ modes.phi == pytest.approx(np.diag(omega2), abs=1e-9 * omega2.max())
    shapes = modes.sensor_shapes
    assert np.allclose(shapes, sys_.sensor_matrix @ modes.phi)
    assert np.all(shapes[np.argmax(np.abs(shapes), axis=0), range(4)] > 0)
    assert modes.sensor_names == ("a1", "a2", "a3", "a4", "a5")


def test_point_masses_and_sensor_mass_lower_the_frequencies(rigs_dir):
    rig = load_rig(rigs_dir / "demo_arm.toml")
    batch = frame_modes_many(rig, [{"theta_deg": 0.0}, {"theta_deg": 90.0}])
    assert batch[1].freq_hz == pytest.approx(frame_modes(rig, {"theta_deg": 90.0}).freq_hz)
    doc = beam_doc(mass=[{"at": "tip", "mass_kg": "payload_kg"}])
    rig = parse_rig(doc)
    f0 = frame_modes(rig, {"payload_kg": 0.0}, 1).freq_hz[0]
    # a tip mass equal to the beam's mass: Blevins table 8-8, lambda = 1.2479 for m_tip / (mu L) = 1
    f1 = frame_modes(rig, {"payload_kg": MU * L}, 1).freq_hz[0]
    assert f0 == pytest.approx(lam_to_hz(1.87510407), rel=1e-4)
    assert f1 == pytest.approx(lam_to_hz(1.24792), rel=2e-4)


def test_seed003_rigid_joint_table6_within_half_a_percent(rigs_dir, data_dir):
    rig = load_rig(rigs_dir / "seed003_two_link.toml")
    table = pd.read_csv(data_dir / "seeds/seed003_table6_rigid_joint_fem.csv")
    ansys = table[["f1_hz", "f2_hz", "f3_hz", "f4_hz"]].to_numpy()
    ours = np.array([m.freq_hz for m in frame_modes_many(rig, [{"theta_deg": t} for t in table.theta_deg])])
    err = np.abs(ours / ansys - 1)
    assert err.max() < 0.005
    assert err.max() > 0.003  # the measured gap to ANSYS BEAM3 at mode 4, theta 0 (0.37 %), documented


def test_seed001_pusher_end_restraint_spans_pin_to_clamped(rigs_dir):
    """Seed 001: the pusher's pin friction moves the system between its pin-pin and clamped-clamped modes."""
    from dataclasses import replace

    rig = load_rig(rigs_dir / "seed001_arm.toml")
    pose = {"shoulder_deg": 60.0, "elbow_deg": 90.0, "payload_kg": 0.0}
    pusher = next(m for m in rig.members if m.name == "pusher")

    def with_pusher(**change) -> np.ndarray:
        members = tuple(replace(m, **change) if m.name == "pusher" else m for m in rig.members)
        return frame_modes(replace(rig, members=members), pose, 6).freq_hz

    pin, clamped = with_pusher(), with_pusher(ends="clamped-clamped")
    half = with_pusher(ends="clamped-pin")
    assert np.all(pin <= half + 1e-9) and np.all(half <= clamped + 1e-9)
    # the pusher-bending mode: 31.9 -> 48.8 -> 64.5 Hz here (seed 001 FEM: 30.1, 46 and 64 Hz)
    assert clamped[3] > 1.9 * pin[3] and 1.4 * pin[3] < half[3] < 1.7 * pin[3]
    assert with_pusher(end_k_Nm_per_rad=1e13) == pytest.approx(clamped, rel=1e-6)
    assert with_pusher(end_k_Nm_per_rad=1e-6) == pytest.approx(pin, rel=1e-9)
    assert pusher.ends == "pin-pin" and frame_modes(rig, pose, 6).freq_hz == pytest.approx(pin)


def test_segments_equal_separate_links_on_the_same_mesh():
    thick = {"shape": "custom", "EA_N": 2.0e7, "EI_Nm2": 2 * EI, "mass_per_m_kg": 1.5 * MU}
    thin = {"shape": "custom", "EA_N": 1.28e7, "EI_Nm2": EI, "mass_per_m_kg": MU}
    stepped = {"name": "s", "link": [{"name": "a", "length_m": 1.0, "section": thin, "elements": 10,
                                      "segments": [{"from": 0.0, "to": 0.5, "section": thick}]}]}
    joined = {"name": "j", "link": [{"name": "a", "length_m": 0.5, "section": thick, "elements": 5},
                                    {"name": "b", "length_m": 0.5, "section": thin, "elements": 5}],
              "joint": [{"name": "j", "parent": "a", "child": "b", "angle_deg": 0.0}]}
    f_stepped = frame_modes(parse_rig(stepped), {}, 5).freq_hz
    assert f_stepped == pytest.approx(frame_modes(parse_rig(joined), {}, 5).freq_hz, rel=1e-10)
    assert f_stepped[0] > frame_modes(parse_rig({"link": [{"name": "a", "length_m": 1.0, "section": thin}]}),
                                      {}, 1).freq_hz[0]


def test_rotating_the_whole_arm_changes_nothing_but_directions():
    doc = beam_doc(links=2)
    doc["base"]["angle"] = "base_deg"
    doc["joint"][0]["angle"] = "elbow_deg"
    rig = parse_rig(doc)
    a = assemble(rig, {"base_deg": 0.0, "elbow_deg": 40.0})
    b = assemble(rig, {"base_deg": 73.0, "elbow_deg": 40.0})
    fa, fb = solve_modes(a, 4), solve_modes(b, 4)
    assert fa.freq_hz == pytest.approx(fb.freq_hz, rel=1e-10)
    # transverse at the tip = -sin(angle) x + cos(angle) y, angle = 73 + 40 deg
    ang = math.radians(113.0)
    combo = -math.sin(ang) * b.observe("tip", "x") + math.cos(ang) * b.observe("tip", "y")
    assert combo == pytest.approx(b.observe("tip", "transverse"), abs=1e-12)
    assert b.node_xy_m[-1] == pytest.approx(L / 2 * np.array([math.cos(math.radians(73)) + math.cos(ang),
                                                              math.sin(math.radians(73)) + math.sin(ang)]))


def test_observe_rejects_what_it_cannot_see(rigs_dir):
    from flexmodal.models.errors import ModelError

    sys_ = assemble(load_rig(rigs_dir / "seed001_arm.toml"), {"shoulder_deg": 60, "elbow_deg": 90,
                                                               "payload_kg": 1.0})
    with pytest.raises(ModelError, match="unknown quantity"):
        sys_.observe("tip", "twist")
    with pytest.raises(ModelError, match="ground point"):
        sys_.observe("ground@0,0", "x")
    with pytest.raises(ModelError, match="names no link"):
        sys_.observe("forearm@0.5", "x")
    # a member point moves with the member: the pusher's pinned end follows its host point on the arm
    end = sys_.observe("pusher@1", "x")
    assert end == pytest.approx(sys_.observe("upper@0.08", "x"), abs=1e-12)


def test_batch_assembly_equals_one_pose_at_a_time(rigs_dir):
    """Members, pose masses, springs and spring joints: the vectorised batch gives the single-pose systems."""
    from dataclasses import replace

    from flexmodal.models.frame import assemble_many
    from flexmodal.models.rig import Spring

    rig = load_rig(rigs_dir / "seed001_arm.toml")
    rig = replace(rig, joints=(replace(rig.joints[0], kind="spring", k_Nm_per_rad=3e4),),
                  springs=(Spring(rig.point_of("upper@0.5"), 2e3, "transverse"),))
    poses = [{"shoulder_deg": s, "elbow_deg": e, "payload_kg": m} for s, e, m in
             ((40, 60, 0.0), (70, 90, 2.0), (100, 105, 5.0))]
    for batch, pose in zip(assemble_many(rig, poses), poses, strict=True):
        single = assemble(rig, pose)
        assert np.array_equal(batch.K, single.K) and np.array_equal(batch.M, single.M)
        assert np.array_equal(batch.sensor_matrix, single.sensor_matrix)
        assert batch.observe("pusher@0.5", "y") == pytest.approx(single.observe("pusher@0.5", "y"))
    f_batch = [m.freq_hz for m in frame_modes_many(rig, poses, 4, chunk=2)]
    assert np.array(f_batch) == pytest.approx(np.array([frame_modes(rig, p, 4).freq_hz for p in poses]))
    assert f_batch[0][0] > f_batch[2][0]  # the payload lowers the first mode


def test_member_restraint_at_a_spring_joint_follows_the_child_link():
    """Chained changes of variables: member ends restrained (end_k -> inf) to the rotation of a spring
    joint's child and to the ground equal a member clamped to both."""
    bar = {"shape": "custom", "EA_N": 1e6, "EI_Nm2": 50.0, "mass_per_m_kg": 0.3}

    def freq(ends: str, end_k: float) -> np.ndarray:
        strut = {"name": "strut", "from": "j1", "to": "ground@0.3,-0.6", "section": bar, "ends": ends,
                 "end_k_Nm_per_rad": end_k, "elements": 4}
        doc = beam_doc(links=2, member=[strut])
        doc["joint"][0].update(kind="spring", k_Nm_per_rad=300.0, angle_deg=30.0)
        return frame_modes(parse_rig(doc), {}, 5).freq_hz

    assert freq("pin-pin", 1e12) == pytest.approx(freq("clamped-clamped", 0.0), rel=1e-7)


def test_elements_override_reaches_members_with_their_own_count():
    """``elements_per_link`` overrides every body's own ``elements``, members included: a pin-pin strut
    of n elements adds 3 DOFs at each of its n - 1 inner nodes and its two end rotations."""
    bar = {"shape": "custom", "EA_N": 1e6, "EI_Nm2": 50.0, "mass_per_m_kg": 0.3}
    strut = {"name": "strut", "from": "j1", "to": "ground@0.3,-0.6", "section": bar, "ends": "pin-pin",
             "elements": 2}
    rig = parse_rig(beam_doc(links=2, member=[strut]))
    own, six = assemble(rig, {}), assemble(rig, {}, elements_per_link=6)
    base = assemble(parse_rig(beam_doc(links=2)), {}, elements_per_link=6)
    assert six.n_dof - base.n_dof == 3 * (6 - 1) + 2           # the strut meshed with 6 elements, not 2
    assert own.n_dof - assemble(parse_rig(beam_doc(links=2)), {}).n_dof == 3 * (2 - 1) + 2
