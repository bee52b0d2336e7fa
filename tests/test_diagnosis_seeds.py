"""The seeds as worked examples of the diagnosis (docs/diagnosis.md quotes these numbers)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from flexmodal.compare.diagnosis import diagnose
from flexmodal.compare.gap import damped_frequency_shift
from flexmodal.contract.table import ModalTable
from flexmodal.models.rig import load_rig, parse_rig


def seed003_table(data_dir) -> ModalTable:
    t3 = pd.read_csv(data_dir / "seeds" / "seed003_table3_experimental.csv")
    recs = [{"config": f"theta{int(r.theta_deg)}", "mode": m, "freq_hz": r[f"f{m}_hz"],
             "source": "experiment", "pose.theta_deg": r.theta_deg} for _, r in t3.iterrows() for m in (1, 2)]
    return ModalTable.from_records(recs, "seed003 Table 3")


@pytest.fixture(scope="module")
def seed003_result(data_dir, rigs_dir):
    rig = load_rig(rigs_dir / "seed003_two_link.toml")
    return diagnose(rig, seed003_table(data_dir), holdout="theta30,theta90,theta150")


def test_seed003_rigid_joint_gap_is_on_f2_at_the_elbow(seed003_result):
    b, w = seed003_result.baseline, seed003_result.where
    assert b.max_rel_error == pytest.approx(158.41 / 92.2 - 1, abs=2e-3)   # the paper's 72 % on f2
    assert b.per_mode["2"] > 5 * b.per_mode["1"]
    assert w.modes == (2,)
    assert w.region == "joint:elbow"


def test_seed003_one_parameter_set_for_all_poses_and_its_limit(seed003_result):
    v = seed003_result.verdict
    assert v.heldout_rms_rel_error_before > 0.4
    assert v.heldout_rms_rel_error_after <= 0.08          # fit on 0/60/120 deg, predict 30/90/150 deg
    assert v.explained is False                           # still far above Table 4's < 0.85 % scatter
    assert "joint_stiffness" in v.effect and "elbow" in v.location
    pairs = [e for e in seed003_result.ranking if e.effect.count("+") == 1]
    assert min(e.heldout_rms_rel_error for e in pairs) > 0.05   # two effects are not enough


def test_seed003_joint_stiffness_alone_is_not_none(data_dir, rigs_dir):
    """The none test must not read a held-out error far above the scatter as noise: with the joint
    stiffness alone on the 3/3 split the nominal model is 43.1 % off held out, the joint stiffness 24.2 %
    (6 held-out frequencies, fallback scatter 0.5 %); the paired noise at the candidate's own 24 % level
    (19.7 %) covered that 19 % gain and the verdict was ``none``."""
    rig = load_rig(rigs_dir / "seed003_two_link.toml")
    v = diagnose(rig, seed003_table(data_dir), effects="joint_stiffness",
                 holdout="theta30,theta90,theta150").verdict
    assert (v.effect, v.location) == ("joint_stiffness", "elbow")
    assert v.heldout_rms_rel_error_before == pytest.approx(0.431, abs=5e-4)
    assert v.heldout_rms_rel_error_after == pytest.approx(0.242, abs=5e-4)
    assert v.grade == "partly explained" and v.explained is False


IN = 0.0254
SEED001_ARM = {
    "name": "seed001-two-link-with-pusher", "material": {"al": {"E_Pa": 69e9, "rho_kg_m3": 2700}},
    "link": [{"name": "lower", "length_m": 120 * IN, "material": "al",
              "section": {"shape": "round_tube", "outer_m": 5.563 * IN, "wall_m": 0.134 * IN}},
             {"name": "upper", "length_m": 120 * IN, "material": "al",
              "section": {"shape": "round_tube", "outer_m": 4.5 * IN, "wall_m": 0.12 * IN}}],
    "base": {"support": "clamped"},
    "joint": [{"name": "elbow", "parent": "lower", "child": "upper", "angle": "theta_deg", "kind": "pin"}],
    "member": [{"name": "pusher", "from": "lower@0.6", "to": "upper@0.25", "material": "al",
                "ends": "pin-pin", "section": {"shape": "rect_tube", "width_m": 1.75 * IN,
                                               "height_m": 4 * IN, "wall_m": 0.125 * IN}}],
}


def test_seed001_pusher_mode_points_at_an_end_restraint_between_pinned_and_clamped():
    """Seed 001: the pusher's pin-pin mode measured 25 % high (37.87 vs 30.19 Hz, Table 3.1 mode 3).

    The same rise is put on this arm's pusher mode (its 5th mode) by pin friction; the blind diagnosis must
    name the end restraint and land between the pin-pin and clamped-clamped pusher.
    """
    from dataclasses import replace

    from flexmodal.models.effects import apply_effect
    from flexmodal.models.frame import frame_modes

    rig = parse_rig(SEED001_ARM, "seed001 arm")
    pose = {"theta_deg": 90.0}

    def pusher_hz(r) -> float:
        return float(frame_modes(r, pose, 6).freq_hz[4])

    target = 37.87 / 30.19 * pusher_hz(rig)
    log_k = brentq(lambda lk: pusher_hz(apply_effect(rig, "end_restraint", "pusher",
                                                     {"k_Nm_per_rad": 10**lk})) - target, 2, 8)
    real = apply_effect(rig, "end_restraint", "pusher", {"k_Nm_per_rad": 10**log_k})
    recs = []
    for th in (80.0, 90.0, 100.0):
        f = frame_modes(real, {"theta_deg": th}, 6).freq_hz
        recs += [{"config": f"theta{th:g}", "mode": k + 1, "freq_hz": f[k], "pose.theta_deg": th}
                 for k in range(6)]
    res = diagnose(rig, ModalTable.from_records(recs, "seed001-like"))
    v = res.verdict
    assert (v.effect, v.location) == ("end_restraint", "pusher")
    assert res.where.modes == (5,) and res.where.region == "member:pusher"
    assert v.params["k_Nm_per_rad"] == pytest.approx(10**log_k, rel=1e-3)
    clamped = replace(rig, members=(replace(rig.members[0], ends="clamped-clamped"),))
    fitted = apply_effect(rig, "end_restraint", "pusher", v.params)
    assert pusher_hz(rig) < pusher_hz(fitted) < pusher_hz(clamped)


def _hub_beam_roots(J_over_rho: float, L: float, n: int = 2) -> np.ndarray:
    """beta*L roots of seed 002's eq. (3) with a hub inertia only (M_p = J_p = 0)."""
    def g(x: float) -> float:
        b = x / L
        return (np.cos(x) * np.sinh(x) - np.sin(x) * np.cosh(x)
                - J_over_rho * b**3 * (1 + np.cos(x) * np.cosh(x))) / np.cosh(x)
    xs = np.linspace(0.5, 12.0, 2000)
    vals = np.array([g(x) for x in xs])
    roots = [brentq(g, xs[i], xs[i + 1]) for i in range(len(xs) - 1) if vals[i] * vals[i + 1] < 0]
    return np.array(roots[:n])


def test_seed002_f2_over_f1_points_at_the_hub_inertia():
    L, rho, EI, J_hub = 0.7, 1.8 / 0.7, 1.97, 0.10      # forearm 0.7 m, 1.8 kg, ~1 Hz clamped
    x = _hub_beam_roots(J_hub / rho, L)
    f = (x / L) ** 2 * np.sqrt(EI / rho) / (2 * np.pi)
    rig = parse_rig({"name": "forearm", "base": {"support": "pinned"},
                     "link": [{"name": "forearm", "length_m": L, "elements": 24,
                               "section": {"shape": "custom", "EA_N": 1e8, "EI_Nm2": EI,
                                           "mass_per_m_kg": rho, "rotary_inertia_per_m_kgm": 0.0}}]})
    table = ModalTable.from_records([{"config": f"run{i}", "mode": m + 1, "freq_hz": f[m]}
                                     for i in range(3) for m in range(2)])
    res = diagnose(rig, table, effects="joint_mass")
    assert 3.24 < f[1] / f[0] < 6.27                  # between pinned-free and clamped-free
    top = res.ranking[0]
    assert (top.effect, top.location) == ("joint_mass", "base")
    assert top.params["inertia_kgm2"] == pytest.approx(J_hub, rel=0.01)


def test_seed000_damping_alone_cannot_explain_table2(data_dir):
    t2 = pd.read_csv(data_dir / "seeds" / "seed000_table2_frequencies.csv")
    zeta = pd.read_csv(data_dir / "seeds" / "seed000_damping_logdec.csv")["damping_ratio"]
    zeta = zeta.to_numpy()
    fe = t2[t2.source == "fe_undamped"].freq_hz.to_numpy()
    exp = t2[t2.source == "impact_experiment"].freq_hz.to_numpy()
    shift = 1 - exp / fe
    bound = damped_frequency_shift(zeta)
    assert bound.max() == pytest.approx(0.0085, abs=1e-4)
    assert np.all(shift > 5 * bound)                  # 6.7-15 % measured vs <= 0.85 % from damping


@pytest.mark.slow
def test_docs_quote_the_seed003_numbers_the_script_regenerates(data_dir):
    """docs/diagnosis.md's seed 003 paragraph is exactly what benchmarks/diagnosis_doc.py computes now."""
    import importlib.util

    from conftest import REPO

    spec = importlib.util.spec_from_file_location("diagnosis_doc", REPO / "benchmarks" / "diagnosis_doc.py")
    doc = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(doc)
    assert doc.doc_block("seed003") == doc.seed003_block(data_dir)
