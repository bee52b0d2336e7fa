"""Opt-in Timoshenko frame elements (models/frame.py ``Shear``) against the closed-form Timoshenko beam."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flexmodal.models.errors import ModelError
from flexmodal.models.frame import Shear, element_matrices, frame_modes
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


# -- the rig path: section.shear_coefficient (kappa) and the material's nu -----------------------------

def thick_rig_toml(depth_m: float, kappa: str = repr(KAPPA), nu: str = repr(NU),
                   support: str = "pinned") -> str:
    """The simply supported beam above as a rig file: a solid rectangle of the material, shear set on its
    section (``support = "clamped"`` and no tip springs: a cantilever)."""
    springs = "".join(f'[[spring]]\nat = "tip"\nk_N_per_m = 1e14\ndirection = "{d}"\n'
                      for d in ("transverse", "axial")) if support == "pinned" else ""
    return (f'name = "thick"\n[material.al]\nE_Pa = {E!r}\nrho_kg_m3 = {RHO!r}\nnu = {nu}\n'
            f'[base]\nsupport = "{support}"\n'
            f'[[link]]\nname = "l1"\nlength_m = {L!r}\nmaterial = "al"\nelements = 40\n'
            f'section = {{ shape = "solid_rect", width_m = {B!r}, height_m = {depth_m!r}, '
            f'shear_coefficient = {kappa} }}\n{springs}')


def test_a_rig_with_shear_coefficient_predicts_the_timoshenko_frequencies(tmp_path):
    """Through the rig file and ``predict`` (the path of the CLI and the diagnosis): the thick (L/h = 8)
    beam with ``shear_coefficient`` = 5/6 and the material's nu = 0.3 gives the frequency equation's
    roots; without the key the same file is the Euler-Bernoulli frame (shear lowers modes 1-3 1.9-12 %)."""
    from flexmodal.models.predict import predict

    depth = L / 8
    (tmp_path / "thick.toml").write_text(thick_rig_toml(depth), encoding="utf-8")
    rig = load_rig(tmp_path / "thick.toml")
    assert rig.links[0].section.shear == Shear(KAPPA, NU)
    f = predict(rig, {"c": {}}, "fe", 3).freq_hz("c")
    exact = np.array([timoshenko_ss_hz(depth, n) for n in (1, 2, 3)])
    assert np.max(np.abs(f / exact - 1)) < 1e-3   # measured 5.5e-4, as with the keyword
    plain = thick_rig_toml(depth).replace(f", shear_coefficient = {KAPPA!r}", "")
    (tmp_path / "plain.toml").write_text(plain, encoding="utf-8")
    euler = predict(load_rig(tmp_path / "plain.toml"), {"c": {}}, "fe", 3).freq_hz("c")
    assert np.all(euler / f - 1 > 0.015)


def test_each_section_has_its_own_kappa_links_segments_and_members(rigs_dir):
    """seed001 (round tubes, a rectangular-tube pusher, a custom cylinder): kappa 0.5 set on every section
    equals the keyword ``Shear(0.5, nu)`` exactly (sections, segments and members all reach the frame);
    set on the pusher only, the frequencies lie between none and all."""
    import tomllib

    from flexmodal.models.rig import parse_rig

    doc = tomllib.loads((rigs_dir / "seed001_arm.toml").read_text(encoding="utf-8"))
    assert all(lk.section.shear is None for lk in load_rig(rigs_dir / "seed001_arm.toml").links)
    doc["material"]["aluminium"]["nu"] = NU
    pose = {"shoulder_deg": 60.0, "elbow_deg": 90.0, "payload_kg": 0.0}
    off = frame_modes(parse_rig(doc, "seed001"), pose, 6).freq_hz
    for table in doc["member"]:
        table["material"] = "aluminium"
    doc["member"][1]["section"]["shear_coefficient"] = 0.5
    pusher = frame_modes(parse_rig(doc, "seed001"), pose, 6).freq_hz
    for table in doc["link"] + doc["member"]:
        table["section"]["shear_coefficient"] = 0.5
    every = frame_modes(parse_rig(doc, "seed001"), pose, 6).freq_hz
    arm = load_rig(rigs_dir / "seed001_arm.toml")
    assert np.array_equal(every, frame_modes(arm, pose, 6, shear=Shear(0.5, NU)).freq_hz)
    assert np.all(every <= pusher) and np.all(pusher <= off) and np.any(pusher < off * (1 - 1e-4))
    assert np.any(every < pusher * (1 - 1e-3))


BAD_SHEAR = {"negative": ("-0.5", "0.3"), "nan": ("nan", "0.3"), "inf": ("inf", "0.3"),
             "zero": ("0.0", "0.3"), "below 1e-3": ("0.0009", "0.3"), "string": ('"0.5"', "0.3"),
             "bool": ("true", "0.3"),
             "nu 0.5": ("0.5", "0.5"), "nu -1": ("0.5", "-1.0"), "nu string": ("0.5", '"0.3"'),
             "nu above 0.5": ("0.5", "0.7"), "no nu": ("0.5", None)}


@pytest.mark.parametrize("case", sorted(BAD_SHEAR))
def test_a_bad_shear_value_gives_one_line_naming_file_and_field_and_exit_2(tmp_path, capsys, case):
    from conftest import one_line

    from flexmodal.app import main

    kappa, nu = BAD_SHEAR[case]
    text = thick_rig_toml(L / 8, kappa, nu or "0.3")
    (tmp_path / "bad.toml").write_text(text if nu else text.replace("nu = 0.3\n", ""), encoding="utf-8")
    (tmp_path / "poses.csv").write_text("config\nc\n", encoding="utf-8")
    code = main(["predict", str(tmp_path / "bad.toml"), "--model", "fe", "--poses",
                 str(tmp_path / "poses.csv"), "--out", str(tmp_path / "p.csv")])
    line = one_line(capsys, code, "bad.toml")
    assert "link[0].section.shear_coefficient" in line or "material.al.nu" in line
    assert not (tmp_path / "p.csv").exists()


def test_nu_one_half_is_refused_at_the_material_field(tmp_path, capsys):
    """The rig schema and ``Shear`` take the same range of nu, (-1, 0.5): nu = 0.5 is one line naming
    ``material.al.nu`` and the range, exit 2 (before, the schema took 0.5 and ``Shear`` refused it
    at ``link[0].section.shear_coefficient``)."""
    from conftest import one_line

    from flexmodal.app import main

    (tmp_path / "bad.toml").write_text(thick_rig_toml(L / 8, nu="0.5"), encoding="utf-8")
    (tmp_path / "poses.csv").write_text("config\nc\n", encoding="utf-8")
    code = main(["predict", str(tmp_path / "bad.toml"), "--model", "fe", "--poses",
                 str(tmp_path / "poses.csv"), "--out", str(tmp_path / "p.csv")])
    one_line(capsys, code, "bad.toml: material.al.nu: ", "(-1, 0.5)", "(got 0.5)")


@pytest.mark.parametrize("model", ["blevins", "assumed-modes", "lumped-mass"])
def test_the_beam_models_refuse_a_rig_with_shear(tmp_path, model):
    """Euler-Bernoulli beam models cannot represent shear deformation: they say so (the fe model can)."""
    from flexmodal.models.predict import predict

    (tmp_path / "c.toml").write_text(thick_rig_toml(L / 8, support="clamped"), encoding="utf-8")
    rig = load_rig(tmp_path / "c.toml")
    assert predict(rig, {"c": {}}, "fe", 2).freq_hz("c").size == 2
    with pytest.raises(ModelError, match="c.toml: model .* has no shear deformation but link 'l1' sets "
                                         "shear_coefficient"):
        predict(rig, {"c": {}}, model, 2)


def _usable(x, lo: float, hi: float, hi_open: bool = True) -> bool:
    return (isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) and lo <= x
            and (x < hi if hi_open else x <= hi))


NUMBERISH = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 3), st.booleans(),
                      st.text(max_size=4), st.none(), st.lists(st.floats(), max_size=2))


@given(kappa=NUMBERISH, nu=NUMBERISH)
@settings(max_examples=300)
def test_the_shear_field_parser_accepts_exactly_the_usable_values(kappa, nu):
    """Any value of ``shear_coefficient`` and ``nu``: a section with Shear(kappa, nu) when kappa >= 1e-3
    (finite) and -1 < nu < 0.5, else one ModelError naming the file and the field; nothing else."""
    from flexmodal.models.rig import parse_rig

    doc = {"material": {"al": {"E_Pa": E, "rho_kg_m3": RHO, "nu": nu}},
           "link": [{"name": "l1", "length_m": 1.0, "material": "al",
                     "section": {"shape": "solid_rect", "width_m": B, "height_m": 0.1,
                                 "shear_coefficient": kappa}}]}
    ok = _usable(kappa, 1e-3, math.inf, hi_open=False) and _usable(nu, -1.0, 0.5) and nu != -1.0
    try:
        section = parse_rig(doc, "rig.toml").links[0].section
    except ModelError as e:
        assert not ok, e
        assert str(e).startswith(("rig.toml: link[0].section.shear_coefficient: ",
                                  "rig.toml: material.al.nu: "))
        assert "\n" not in str(e)
        return
    assert ok and section.shear == Shear(kappa, nu)


def test_lumped_mass_with_shear_converges_to_the_timoshenko_frequencies(tmp_path):
    """The HRZ diagonal mass ignores phi, the stiffness is Timoshenko (Review 46 L3): on the thick beam
    through a rig file (``predict --lumped-mass-matrix``) the error falls as h^2 toward the frequency
    equation's roots (measured 9.3e-4 at 40 elements, 2.3e-4 at 80 on mode 3), not toward the
    Euler-Bernoulli ones (+1.9 to +14 %)."""
    from flexmodal.models.predict import predict

    exact = np.array([timoshenko_ss_hz(L / 8, n) for n in (1, 2, 3)])
    errors = []
    for elements in (40, 80):
        text = thick_rig_toml(L / 8).replace("elements = 40", f"elements = {elements}")
        (tmp_path / "thick.toml").write_text(text, encoding="utf-8")
        f = predict(load_rig(tmp_path / "thick.toml"), {"c": {}}, "fe", 3, lumped_mass=True).freq_hz("c")
        errors.append(np.max(np.abs(f / exact - 1)))
    assert errors[0] < 1.5e-3 and errors[1] < errors[0] / 3


@pytest.mark.parametrize("lumped", [False, True], ids=["consistent", "lumped"])
def test_an_infinite_shear_rigidity_is_the_euler_bernoulli_element_bit_for_bit(lumped: bool):
    """The default (no shear) and an infinite kappa G A run the same arithmetic (phi = 0 exactly), so a
    rig without ``shear_coefficient`` keeps the Euler-Bernoulli matrices bit for bit (Review 47 L6)."""
    rng = np.random.default_rng(47)
    n = 50
    props = (rng.uniform(0.01, 0.5, n), rng.uniform(1e5, 1e8, n), rng.uniform(1.0, 1e4, n),
             rng.uniform(0.1, 5.0, n), rng.uniform(1e-6, 1e-3, n))
    K0, M0 = element_matrices(*props, lumped)
    K1, M1 = element_matrices(*props, lumped, shear_rigidity_N=np.full(n, np.inf))
    assert np.array_equal(K0, K1) and np.array_equal(M0, M1)
    K2, _ = element_matrices(*props, lumped, shear_rigidity_N=np.full(n, 1e3))   # a finite one does act
    assert not np.array_equal(K0, K2)
