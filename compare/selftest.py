"""Blind self-check of the gap diagnosis: random rigs with withheld effects, diagnosed without being told.

Each case draws a two-link arm (lengths, tube sections and sensor positions at random), six elbow poses
(0-150 deg) and, in five cases out of six, one effect (docs/formats.md) at a random location with a random
magnitude (redrawn until it moves the first four frequencies by 3-25 % RMS, i.e. a gap well above the
noise).  "Measured" modes are the four lowest FE modes of the augmented rig (models/frame.py) that the
transverse sensors see (axial modes of the straight arm are invisible to them), with relative
frequency scatter drawn from 0.3-0.9 % (seed 003 Table 4) and 1 % shape noise.  The diagnosis runs with
its default settings (it is not told the scatter) and is scored on the top-ranked effect and location,
``none`` for the cases without an effect, and the held-out gap after the verdict against 2x the scatter.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass

import numpy as np

from flexmodal.compare.diagnosis import diagnose
from flexmodal.modal.table import ModalTable
from flexmodal.models.effects import apply_effect, effect_locations
from flexmodal.models.frame import frame_modes
from flexmodal.models.rig import parse_rig

SELFTEST_EFFECTS = ("joint_stiffness", "joint_stiffness_pose", "joint_mass", "tip_mass", "base_stiffness",
                    "sensor_mass", "grounded_spring", "link_stiffness", "link_mass")
POSES_DEG = (0.0, 30.0, 60.0, 90.0, 120.0, 150.0)
N_MODES = 4


@dataclass(frozen=True)
class Case:
    effect: str            # "none" when nothing was added
    location: str
    params: dict
    scatter: float
    verdict: dict
    top: dict | None
    seconds: float

    @property
    def effect_ok(self) -> bool:
        return self.verdict["effect"] == self.effect

    @property
    def location_ok(self) -> bool:
        return self.effect == "none" or (self.top is not None and self.top["location"] == self.location)


def random_rig(rng: np.random.Generator):
    """A random clamped two-link aluminium arm with a rigid elbow and four sensors."""
    def tube() -> dict:
        outer = rng.uniform(0.025, 0.05)
        return {"shape": "square_tube", "outer_m": outer, "wall_m": outer * rng.uniform(0.03, 0.08)}

    doc = {"name": "selftest-arm", "material": {"al": {"E_Pa": 70e9, "rho_kg_m3": 2700}},
           "link": [{"name": "link1", "length_m": rng.uniform(0.4, 0.8), "material": "al", "section": tube()},
                    {"name": "link2", "length_m": rng.uniform(0.4, 0.9), "material": "al",
                     "section": tube()}],
           "base": {"support": "clamped"},
           "joint": [{"name": "elbow", "parent": "link1", "child": "link2", "angle": "theta_deg"}],
           "sensor": [{"name": f"a{i + 1}", "at": f"{lk}@{rng.uniform(lo, hi):.2f}"}
                      for i, (lk, lo, hi) in enumerate((("link1", 0.4, 0.7), ("link1", 0.8, 1.0),
                                                       ("link2", 0.3, 0.7), ("link2", 0.8, 1.0)))]}
    return parse_rig(doc, "<selftest rig>")


def _draw_params(rng: np.random.Generator, rig, effect: str, location: str) -> dict:
    arm_m = sum(lk.section.mass_per_m_kg * lk.length_m for lk in rig.links)
    l1, l2 = rig.links

    def ei_l(link) -> float:
        return link.section.EI_Nm2 / link.length_m

    if effect in ("joint_stiffness", "joint_stiffness_pose"):
        p = {"k_Nm_per_rad": ei_l(l2) * 10 ** rng.uniform(-0.5, 1.5)}
        if effect == "joint_stiffness_pose":
            p["log_slope_per_rad"] = rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0)
        return p
    if effect in ("joint_mass", "tip_mass"):
        m = arm_m * 10 ** rng.uniform(-1.0, 0.0)
        return {"mass_kg": m, "inertia_kgm2": m * rng.uniform(0.01, 0.04) ** 2}
    if effect == "base_stiffness":
        return {"k_Nm_per_rad": ei_l(l1) * 10 ** rng.uniform(0.0, 2.0)}
    if effect == "sensor_mass":
        return {"mass_kg": arm_m / len(rig.sensors) * 10 ** rng.uniform(-1.3, -0.3)}
    if effect == "grounded_spring":
        link = rig.link(location.partition("@")[0])
        return {"k_N_per_m": 3 * link.section.EI_Nm2 / link.length_m**3 * 10 ** rng.uniform(-0.5, 1.0)}
    return {"scale": float(rng.choice([rng.uniform(0.5, 0.8), rng.uniform(1.25, 2.0)]))}


def _modes(rig, effect: str, location: str, params: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per pose: the frequencies [Hz] and sensor shapes of the N_MODES lowest modes the sensors can see."""
    out = []
    for th in POSES_DEG:
        pose = {"theta_deg": th}
        r = apply_effect(rig, effect, location, params, pose=pose) if effect != "none" else rig
        m = frame_modes(r, pose, 2 * N_MODES)
        seen = np.linalg.norm(m.sensor_shapes, axis=0)
        keep = np.flatnonzero(seen > 1e-3 * seen.max())[:N_MODES]
        out.append((m.freq_hz[keep], m.sensor_shapes[:, keep]))
    return out


def make_case(rng: np.random.Generator, with_effect: bool):
    """(rig, measured table, effect, location, params, scatter) of one random case."""
    rig = random_rig(rng)
    nominal = np.array([f for f, _ in _modes(rig, "none", "", {})])
    effect, location, params = "none", "", {}
    modes = None
    if with_effect:
        for _ in range(40):
            effect = str(rng.choice(SELFTEST_EFFECTS))
            location = str(rng.choice(effect_locations(rig, effect)))
            params = _draw_params(rng, rig, effect, location)
            modes = _modes(rig, effect, location, params)
            gap = np.sqrt(np.mean((nominal / np.array([f for f, _ in modes]) - 1) ** 2))
            if 0.03 <= gap <= 0.25:
                break
    modes = modes or _modes(rig, "none", "", {})
    scatter = float(rng.uniform(0.003, 0.009))
    records = []
    names = [s.name for s in rig.sensors]
    for th, (freq, phi) in zip(POSES_DEG, modes, strict=True):
        f = freq * (1 + scatter * rng.standard_normal(N_MODES))
        shapes = phi + 0.01 * np.abs(phi).max(axis=0) * rng.standard_normal(phi.shape)
        for k in range(N_MODES):
            rec = {"config": f"theta{th:g}", "mode": k + 1, "freq_hz": f[k], "pose.theta_deg": th}
            rec.update({f"shape.{s}": shapes[i, k] for i, s in enumerate(names)})
            records.append(rec)
    return rig, ModalTable.from_records(records, "<selftest>"), effect, location, params, scatter


def run_selftest(n: int, seed: int = 0, progress: bool = True) -> dict:
    """Run ``n`` blind cases (every sixth without an effect); returns the summary dict."""
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(n):
        rig, table, effect, location, params, scatter = make_case(rng, with_effect=(i % 6 != 5))
        t0 = time.perf_counter()
        res = diagnose(rig, table)
        cases.append(Case(effect, location, params, scatter, res["verdict"],
                          res["ranking"][0] if res["ranking"] else None, time.perf_counter() - t0))
        if progress:
            c = cases[-1]
            print(f"[{i + 1}/{n}] injected {effect}@{location or '-'} -> {c.verdict['effect']}@"
                  f"{c.verdict['location'] or '-'} ({'ok' if c.effect_ok and c.location_ok else 'WRONG'}, "
                  f"{c.seconds:.1f} s)", file=sys.stderr)
    return summarise(cases)


def summarise(cases: list[Case]) -> dict:
    eff = [c for c in cases if c.effect != "none"]
    none = [c for c in cases if c.effect == "none"]
    right = [c for c in eff if c.effect_ok]
    within = [c for c in right if c.verdict["heldout_rms_rel_error_after"] <= 2 * c.scatter]

    def frac(a: list, b: list) -> float:
        return len(a) / len(b) if b else math.nan

    return {
        "n_cases": len(cases), "n_with_effect": len(eff), "n_without_effect": len(none),
        "top1_effect_accuracy": frac(right, eff),
        "location_accuracy": frac([c for c in eff if c.effect_ok and c.location_ok], eff),
        "none_accuracy": frac([c for c in none if c.effect_ok], none),
        "heldout_after_within_2x_scatter": frac(within, right),
        "heldout_before_mean": float(np.mean([c.verdict["heldout_rms_rel_error_before"] for c in eff]))
        if eff else math.nan,
        "heldout_after_mean": float(np.mean([c.verdict["heldout_rms_rel_error_after"] for c in eff]))
        if eff else math.nan,
        "scatter_mean": float(np.mean([c.scatter for c in cases])),
        "seconds_per_case": float(np.mean([c.seconds for c in cases])),
        "misses": [f"{c.effect}@{c.location} -> {c.verdict['effect']}@{c.verdict['location']}"
                   for c in eff if not (c.effect_ok and c.location_ok)],
    }


def format_summary(s: dict) -> str:
    lines = [
        f"cases: {s['n_cases']} ({s['n_with_effect']} with a withheld effect, "
        f"{s['n_without_effect']} without)",
        f"top-1 effect accuracy: {s['top1_effect_accuracy']:.1%}",
        f"location accuracy: {s['location_accuracy']:.1%}",
        f"'none' for no-effect cases: {s['none_accuracy']:.1%}",
        f"held-out RMS gap before -> after (mean): {s['heldout_before_mean']:.2%} -> "
        f"{s['heldout_after_mean']:.2%}"
        f" (injected scatter mean {s['scatter_mean']:.2%})",
        f"held-out gap after the right effect within 2x scatter: {s['heldout_after_within_2x_scatter']:.1%}",
        f"time per case: {s['seconds_per_case']:.2f} s",
    ]
    lines += [f"miss: {m}" for m in s["misses"]]
    return "\n".join(lines)
