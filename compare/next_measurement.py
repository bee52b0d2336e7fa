"""The next measurement: the untested pose (and mode) that would best tell an ambiguous verdict from its
rivals, ranked by expected information.

Every fitted candidate predicts a new measurement at a pose it has not seen as a normal of the relative
frequency of each mode, with mean its fitted reduced model's frequency and variance ``scatter^2 +
g^T C g`` (dimensionless, relative frequency squared; ``g`` the relative sensitivities to the fitted
parameters there, ``C`` their linearised Gauss-Newton covariance from the measured poses: Seber & Wild
1989 §5.1).  How well a measurement at that pose tells candidate ``a`` from ``b`` is the symmetric
Kullback-Leibler divergence of their predictive normals (Box & Hill 1967, "Discrimination among
mechanistic models", Technometrics 9: 57-71; Kullback 1959), in nats, summed over modes.  The chance
that one measurement decides also counts the mode shapes the candidates predict there, when shapes were
measured: two candidates with the same frequencies at a pose may still differ in shape.

Functions (``ctx`` is the diagnosis' fit context, ``FitContext``; ``entry`` a fitted candidate of its
ranking: ``_cand``, ``_fam``, ``_theta0``):

``trial_poses(rig, poses)``
    The candidate poses {label: pose} after measuring ``poses`` (labels ``<var>=<value>``).
``separating_measurement(ctx, a, b)``
    The unmeasured pose and mode where two fitted candidates differ most (``separate_at`` of an
    alternative that is not the verdict plus a component).
``next_measurements(ctx, best, rivals, scatter)``
    Untested poses ranked by the chance to decide against the verdict's rivals of another effect or
    place (``adds_to``: a rival that is the verdict plus a component is not one a pose can decide);
    none below ``MIN_CHANCE``; a pose beyond the measured range says how far (``beyond``).
``no_pose_decides(best, alts, paired, model_form_margin, n_poses)``
    Why no pose is advised when every alternative is the verdict plus one component.

Examples
--------
>>> from flexmodal.models.rig import load_rig
>>> rig = load_rig("examples/rigs/seed003_two_link.toml")
>>> labels = list(trial_poses(rig, [{"theta_deg": 0.0}, {"theta_deg": 60.0}, {"theta_deg": 120.0}]))
>>> len(labels), labels[:3], labels[-1]          # 10 deg steps, widened by 60 deg each way
(25, ['theta_deg=-60', 'theta_deg=-50', 'theta_deg=-40'], 'theta_deg=180')
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np
from scipy.special import ndtr

from flexmodal.checked_io.percent import percent
from flexmodal.compare.fit import Target, design, evaluate, linear_cov
from flexmodal.compare.gap import Measured
from flexmodal.compare.parametric import ReducedFamily, lam_to_hz, solve_family
from flexmodal.compare.result import MIN_CHANCE
from flexmodal.contract.table import pose_unit
from flexmodal.models.rig import Rig

TRIAL_POINTS = 13
WIDEN = 0.5
"""Candidate poses: 13 points over the measured range of each pose variable, and on at that step up to
half the range beyond each end (``trial_poses``)."""
MAX_ADVICE = 3
SHAPE_SCATTER_MIN = 1e-3
"""No mode shape is measured better than 0.1 % of its norm per sensor (floor of the shape noise)."""


class FitContext(Protocol):
    """What the advice needs of the diagnosis' fit context (compare/diagnosis.py ``_Context``)."""

    rig: Rig
    meas: Measured
    target: Target
    pose_share: float                                   # distinct poses / configurations
    shape_dof: int                                      # measured sensors - 1 (0 without shapes)
    shape_floor: float                                  # smallest in-sample mean 1 - MAC (inf: none)
    trial: tuple[tuple[str, ...], FitContext] | None     # the trial context of ``_trial_context``

    def family(self, handles: Sequence[str]) -> ReducedFamily: ...

    def at(self, poses: Sequence[dict[str, float]], n_modes: int) -> FitContext: ...


def shape_noise_var(ctx: FitContext) -> float:
    """Shape noise per degree of freedom, the variance each ``1 - MAC`` is divided by: the context's
    smallest in-sample mean ``1 - MAC`` over its ``shape_dof`` degrees of freedom (the noise estimate
    of the largest model, Mallows 1973), never below ``SHAPE_SCATTER_MIN^2``.  Defined only when
    ``ctx.shape_dof > 0`` and ``ctx.shape_floor`` is finite.

    Parameters
    ----------
    ctx : FitContext
        Needs ``shape_floor`` (mean 1 - MAC, dimensionless) and ``shape_dof`` (sensors - 1).

    Returns
    -------
    float
        Variance of the relative per-sensor shape noise (dimensionless).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> shape_noise_var(SimpleNamespace(shape_floor=2e-4, shape_dof=2))
    0.0001
    >>> shape_noise_var(SimpleNamespace(shape_floor=0.0, shape_dof=2)) == SHAPE_SCATTER_MIN**2
    True
    """
    return max(ctx.shape_floor / ctx.shape_dof, SHAPE_SCATTER_MIN**2)


def _components(entry: dict) -> set[tuple[str, str]]:
    cand = entry["_cand"]
    return set(zip(cand.effects, cand.locations, strict=True))


def adds_to(best: dict, other: dict) -> bool:
    """Whether the fitted candidate ``other`` is ``best`` with components added (a nested alternative:
    its held-out gain over ``best`` is judged against the diagnosis' nested margin)."""
    return _components(best) < _components(other)


def trial_poses(rig: Rig, poses: Sequence[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Candidate poses for a next measurement after measuring ``poses``, {label: pose}: each pose
    variable moved alone (the others at the first pose's values) over ``TRIAL_POINTS`` points of its
    measured range and on at the same step up to ``WIDEN`` of that range beyond each end (joint and
    base angles [deg] within +-180, pose masses [kg] not below 0), labelled ``<var>=<value>``; with more
    than one pose variable also every combination of each one's widened low end, middle and widened
    high end, labelled ``<var>=<value>,<var>=<value>``.  ``verdict.next_measurements`` and
    ``separate_at`` name them.  The rig does not say how far a joint can turn: an advised pose beyond
    the measured range is worth checking against the arm's limits."""
    angles = {rig.base.angle, *(j.angle for j in rig.joints)} - {None}
    reach = round(WIDEN * (TRIAL_POINTS - 1))
    trial: dict[str, dict[str, float]] = {}
    ends = []
    for v in rig.pose_variables:
        vals = np.array([p[v] for p in poses])
        lo, hi = float(vals.min()), float(vals.max())
        xs = lo + (hi - lo) / (TRIAL_POINTS - 1) * np.arange(-reach, TRIAL_POINTS + reach)
        xs = xs[(np.abs(xs) <= 180.0 + 1e-9) if v in angles else (xs >= -1e-12)] if hi > lo else xs[:1]
        trial.update({f"{v}={x:g}": {**poses[0], v: float(x)} for x in xs})
        ends.append((v, (float(xs.min()), 0.5 * (lo + hi), float(xs.max()))))
    if len(ends) > 1:
        for combo in itertools.product(*(sorted(set(e)) for _, e in ends)):
            pose = {**poses[0], **{v: x for (v, _), x in zip(ends, combo, strict=True)}}
            trial.setdefault(",".join(f"{v}={x:g}" for (v, _), x in zip(ends, combo, strict=True)), pose)
    return trial


def _trial_context(ctx: FitContext, trial: dict[str, dict[str, float]]) -> FitContext:
    """A context over the ``trial`` poses (reduced models there, two modes beyond the measured ones;
    frequencies are placeholders), cached on ``ctx``."""
    key = tuple(trial)
    if ctx.trial is None or ctx.trial[0] != key:
        ctx.trial = (key, ctx.at(tuple(trial.values()), ctx.meas.freq_hz.shape[1] + 2))
    return ctx.trial[1]


def _trial_frequencies(ctx: FitContext, entry: dict, trial: dict[str, dict[str, float]]) -> np.ndarray:
    """Frequencies [P, n + 2] Hz of ``entry``'s fitted candidate at the ``trial`` poses (its reduced
    model, modes in ascending order); cached on the entry."""
    if "_trial_f" not in entry:
        nctx = _trial_context(ctx, trial)
        cand = entry["_cand"]
        fam = nctx.family(cand.handles)
        h = np.exp(design(cand, nctx.target) @ entry["_theta0"])[None] if cand.n_params else \
            np.ones((1, len(trial), 0))
        lam, _, _ = solve_family(fam, h, ctx.meas.freq_hz.shape[1] + 2)
        entry["_trial_f"] = lam_to_hz(lam[0])
    return entry["_trial_f"]


def _same_pose(a: dict[str, float], b: dict[str, float], names: Sequence[str]) -> bool:
    """Whether two poses agree in every pose variable ``names`` (to rounding: a candidate pose is
    computed from the measured range)."""
    return all(math.isclose(a[v], b[v], rel_tol=1e-9, abs_tol=1e-9) for v in names)


def _measured_cells(ctx: FitContext, trial: dict[str, dict[str, float]], n_modes: int) -> np.ndarray:
    """Which (trial pose, mode) cells [P, n_modes] the data already hold: a configuration at that pose
    with a finite frequency of that mode (modes in ascending order, as the reduced models give them)."""
    names = ctx.rig.pose_variables
    freq = np.asarray(ctx.meas.freq_hz, float)
    out = np.zeros((len(trial), n_modes), bool)
    for i, pose in enumerate(trial.values()):
        for c, seen in enumerate(ctx.meas.poses):
            if _same_pose(pose, seen, names):
                out[i, :freq.shape[1]] |= np.isfinite(freq[c, :n_modes])
    return out


def separating_measurement(ctx: FitContext, a: dict, b: dict) -> dict:
    """The pose (``trial_poses``) and model mode (up to two beyond the measured ones) where the fitted
    candidates ``a`` and ``b`` differ most (their reduced models, compare/parametric.py), among the
    cells the data do not hold yet (a measured pose at a mode it was not measured in counts):
    ``{"separate_at", "separate_mode", "separate_rel_diff"}``; empty when there is no such cell, and when
    ``b`` only adds a component to ``a`` (``adds_to``: one more pose settles such a component by its
    noise, not by where it is taken; ``next_measurements``, ``no_pose_decides``)."""
    trial = trial_poses(ctx.rig, ctx.meas.poses)
    if not trial or adds_to(a, b):
        return {}
    diff = np.abs(_trial_frequencies(ctx, a, trial) / _trial_frequencies(ctx, b, trial) - 1.0)
    diff[_measured_cells(ctx, trial, diff.shape[1])] = np.nan
    if not np.isfinite(diff).any():
        return {}
    i, m = np.unravel_index(np.nanargmax(diff), diff.shape)
    return {"separate_at": list(trial)[i], "separate_mode": int(m + 1),
            "separate_rel_diff": float(diff[i, m])}


def beyond_measured(poses: Sequence[dict[str, float]], pose: dict[str, float], names: Sequence[str]
                    ) -> str | None:
    """How far ``pose`` lies beyond the measured ``poses`` in each pose variable ``names`` (units from the
    names' suffixes, ``pose_unit``), or None inside the measured range: the rig does not say how far a
    joint turns or what mass it carries, so such a pose is for the user to check against the arm.

    Examples
    --------
    >>> seen = [{"theta_deg": 0.0}, {"theta_deg": 120.0}]
    >>> beyond_measured(seen, {"theta_deg": 180.0}, ["theta_deg"])
    '60 deg beyond the measured theta_deg 0..120 deg'
    >>> beyond_measured(seen, {"theta_deg": 60.0}, ["theta_deg"]) is None
    True
    """
    parts = []
    for v in names:
        vals = [p[v] for p in poses]
        lo, hi = min(vals), max(vals)
        out = max(lo - pose[v], pose[v] - hi)
        if out > 1e-9 * max(1.0, abs(lo), abs(hi)):
            unit = "" if pose_unit(v) == "-" else f" {pose_unit(v)}"
            parts.append(f"{out:g}{unit} beyond the measured {v} {lo:g}..{hi:g}{unit}")
    return "; ".join(parts) or None


def _predictive(ctx: FitContext, entry: dict, nctx: FitContext, scatter: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``entry``'s fitted candidate at the poses of ``nctx``: frequencies [P, n] Hz, the variance of
    their relative prediction [P, n] (dimensionless) from its linearised parameter covariance, and its
    mode shapes at the measured sensors [P, s, n] (reduced model; s = 0 without measured shapes)."""
    cand = entry["_cand"]
    _, df, _, _ = evaluate(entry["_fam"], design(cand, ctx.target), entry["_theta0"][None], ctx.target)
    cov = linear_cov(df[0] / ctx.meas.freq_hz[..., None], scatter)
    n = ctx.meas.freq_hz.shape[1]
    h = np.exp(design(cand, nctx.target) @ entry["_theta0"])[None]
    lam, dlam, shapes = solve_family(nctx.family(cand.handles), h, n)
    f = lam_to_hz(lam[0])
    dl = dlam[0] * h[0][:, None, :]                                    # d lambda / d log h
    g = (dl @ design(cand, nctx.target)) / (8 * math.pi**2 * np.maximum(f, 1e-12) ** 2)[..., None]
    rows = [s.name for s in ctx.rig.sensors]
    keep = [rows.index(s) for s in ctx.meas.sensors] if ctx.meas.shapes is not None else []
    return f, np.einsum("cnj,jk,cnk->cn", g, cov, g), shapes[0][:, keep]


def shape_disagreement(phi: np.ndarray) -> np.ndarray:
    """``1 - MAC`` [K, K, P, n] between the mode shapes ``phi`` [K, P, s, n] that candidates predict at
    each pose: for candidate ``i``'s mode ``m``, the best match among candidate ``j``'s modes (a mode
    order swapped near a veering is not a difference the diagnosis sees: it pairs modes by MAC).

    Examples
    --------
    >>> a = np.array([[1.0, 0.0], [0.0, 1.0]])                  # sensors x modes, one pose
    >>> b = np.array([[0.0, 1.0], [1.0, 0.0]])                  # the same two modes, swapped
    >>> c = np.array([[1.0, 1.0], [1.0, -1.0]])                 # both modes turned by 45 deg
    >>> shape_disagreement(np.array([a, b, c])[:, None])[:, :, 0, 0].round(3).tolist()   # mode 1
    [[0.0, 0.0, 0.5], [0.0, 0.0, 0.5], [0.5, 0.5, 0.0]]
    """
    norm = np.maximum(np.einsum("kpsn,kpsn->kpn", phi, phi), 1e-300)
    cross = np.einsum("ipsm,jpsn->ijpmn", phi, phi) ** 2
    mac = cross / (norm[:, None, :, :, None] * norm[None, :, :, None, :])
    return np.clip(1.0 - mac.max(axis=-1), 0.0, 1.0)


def _resolve_chance(f: np.ndarray, v: np.ndarray, heldout: np.ndarray, dof: np.ndarray, pose_share: float,
                    scatter: float, shape_chi: np.ndarray | None = None, shape_dof: int = 0) -> np.ndarray:
    """The chance [P] that one measurement of the ``n`` modes at each pose decides among ``K`` fitted
    candidates: their predictions ``f`` [K, P, n] Hz with predictive variances ``v`` [K, P, n] (relative,
    scatter included), their held-out RMS errors ``heldout`` [K] (relative, frequency-equivalent) over
    ``dof`` [K] degrees of freedom.  Bayesian decision-theoretic design (the expected utility of a
    decisive outcome; Chaloner & Verdinelli 1995, Statist. Sci. 10: 273-304; Box & Hill 1967 weigh the
    hypotheses alike): each candidate ``i`` is the truth with the weight ``exp(-chi2_i / 2)`` of its
    held-out chi-square ``dof_i pose_share heldout_i^2 / scatter^2`` (normalised); given ``i``, the new
    point adds ``v_i`` to its mean squared held-out error and ``d_ij^2 + v_j`` to candidate ``j``'s
    (``d_ij = f_j / f_i - 1`` per mode), and ``j`` is ruled out when its new held-out RMS exceeds
    ``i``'s by more than the diagnosis' noise margin ``2 sqrt(2) max(h_i, scatter) / sqrt(2 N)`` with
    ``N`` the distinct held-out degrees of freedom (compare/diagnosis.py ``_noise``), with probability
    ``Phi((h_j - h_i - margin) / sd)`` (``sd`` the spread of that difference: the new residuals share
    the measurement's noise ``e``, so ``e_j^2 - e_i^2 = d^2 - 2 d e`` varies with ``4 d^2 var(e)``).
    With measured shapes (``shape_dof`` = sensors - 1 per mode) the new point's shapes count too, as the
    diagnosis counts them (``_equivalent``: a chi-square of ``1 - MAC`` over the shape noise per degree
    of freedom, ``shape_dof`` degrees of freedom a mode): the truth's adds its noise, ``shape_dof`` a mode;
    candidate ``j``'s adds that plus ``shape_chi[i, j]`` [K, K, P, n], the disagreement of the two
    predicted shapes over the shape noise (``shape_disagreement``), whose cross term with the noise
    varies by ``4 shape_chi``.  The chance is ``sum_i w_i prod_(j != i) P(j ruled out | i)``: a pose
    must rule out every rival of the right candidate, not only one, for the verdict to stop being
    ambiguous."""
    K, _, n = f.shape
    s2 = scatter**2
    new = n * (1 + shape_dof)                           # degrees of freedom one pose adds
    chi2 = dof * pose_share * heldout**2 / s2
    w = np.exp(-(chi2 - chi2.min()) / 2)
    w /= w.sum()
    total = np.zeros(f.shape[1])
    for i in range(K):
        if w[i] < 1e-6:
            continue
        win2 = (dof[i] * heldout[i] ** 2 + v[i].sum(axis=1) + s2 * n * shape_dof) / (dof[i] + new)
        win = np.sqrt(win2)
        margin = 2 * math.sqrt(2) * np.maximum(win, scatter) / math.sqrt(2 * (dof[i] * pose_share + new))
        decisive = np.ones(f.shape[1])
        for j in range(K):
            if j == i:
                continue
            d = f[j] / f[i] - 1.0
            apart = np.zeros(f.shape[1]) if shape_chi is None else shape_chi[i, j].sum(axis=1)
            lose2 = dof[j] * heldout[j] ** 2 + (d**2 + v[j]).sum(axis=1) + s2 * (n * shape_dof + apart)
            lose = np.sqrt(lose2 / (dof[j] + new))
            var = ((2 * d**2 * (v[i] + v[j])).sum(axis=1) + 4 * s2**2 * apart) / (dof[i] + new) ** 2
            sd = np.maximum(np.sqrt(var) / np.maximum(win + lose, 1e-12), 1e-12)
            decisive *= ndtr((lose - win - margin) / sd)
        total += w[i] * decisive
    return np.nan_to_num(total)


def next_measurements(ctx: FitContext, best: dict, rivals: Sequence[dict], scatter: float) -> list[dict]:
    """Untested poses (``trial_poses``) ranked by the chance that one measurement there makes the verdict
    unambiguous against its rivals of another effect or place.  A rival that is ``best`` plus a
    component (``adds_to``) is left out: whether one more pose confirms or excludes such a component is
    decided by that measurement's noise, not by where it is taken (on the used blind draws, verdicts
    with only such alternatives resolved at the advised pose about as often as at a random one:
    docs/diagnosis.md), so with no other rival nothing is advised (``no_pose_decides`` says why).
    The ranking: the chance that one measurement rules out every rival of whichever of ``best`` and
    its ``rivals`` is right
    (``_resolve_chance``), each candidate predicting the new point with its fitted reduced model and
    the variance ``scatter^2 + g^T C g`` (its linearised prediction variance: where a candidate is
    loosely pinned down it can follow a new point, and a measurement there decides little), and, when
    shapes were measured, its mode shapes at the measured sensors, whose disagreement between two
    candidates counts over the shape noise as the diagnosis counts it (``shape_disagreement``); ties
    (e.g. no pose can decide) by the expected information.  ``information_nats`` is the Box & Hill
    (1967) discrimination information, the symmetric Kullback-Leibler divergence between the verdict's
    and a rival's predictive normals of each measured mode's relative frequency, ``0.5 [(v_a - v_b)^2
    / (v_a v_b) + d^2 (1/v_a + 1/v_b)]`` with ``d`` their relative difference, summed over modes and
    averaged over the rivals; ``mode`` the mode that carries most of it; ``decide_chance`` the chance
    (0-1); ``beyond`` how far the pose lies beyond the measured range (``beyond_measured``, None
    inside it).  At most ``MAX_ADVICE`` poses, none whose chance is below ``MIN_CHANCE`` (one more
    measurement there decides about as often as anywhere else; with none left nothing is advised):
    ``[{"pose", "mode", "information_nats", "decide_chance", "beyond"}]``."""
    rivals = [e for e in rivals if not adds_to(best, e)]
    if not rivals:
        return []
    trial = trial_poses(ctx.rig, ctx.meas.poses)
    if not trial:
        return []
    names = ctx.rig.pose_variables
    keep = [i for i, p in enumerate(trial.values())
            if not any(_same_pose(p, q, names) for q in ctx.meas.poses)]
    if not keep:
        return []
    labels = [list(trial)[i] for i in keep]
    nctx = _trial_context(ctx, trial)
    everyone = [best, *rivals]
    pred = [_predictive(ctx, e, nctx, scatter) for e in everyone]
    f = np.array([p[0][keep] for p in pred])
    v = np.array([p[1][keep] for p in pred]) + scatter**2
    info = np.zeros(f.shape[1:])
    for k in range(1, len(everyone)):
        d = f[k] / f[0] - 1.0
        info += np.nan_to_num(0.5 * ((v[0] - v[k]) ** 2 / (v[0] * v[k]) + d**2 * (1 / v[0] + 1 / v[k])))
    info /= len(rivals)
    shape_chi, shape_dof = None, 0
    if ctx.shape_dof > 0 and math.isfinite(ctx.shape_floor) and pred[0][2].shape[1]:
        shape_chi = shape_disagreement(np.array([p[2][keep] for p in pred])) / shape_noise_var(ctx)
        shape_dof = ctx.shape_dof
    chance = _resolve_chance(f, v, np.array([e["_heldout_eq"] for e in everyone]),
                             np.array([e["_n_eq"] for e in everyone], float), ctx.pose_share, scatter,
                             shape_chi, shape_dof)
    total = info.sum(axis=1)
    order = [i for i in np.lexsort((-total, -np.round(chance, 3)))
             if total[i] > 0 and chance[i] >= MIN_CHANCE][:MAX_ADVICE]
    poses = list(trial.values())
    return [{"pose": labels[i], "mode": int(np.argmax(info[i]) + 1), "information_nats": float(total[i]),
             "decide_chance": float(chance[i]),
             "beyond": beyond_measured(ctx.meas.poses, poses[keep[i]], names)} for i in order]


def no_pose_decides(best: dict, alts: Sequence[dict], paired: Sequence[float], model_form_margin: float,
                    n_poses: int) -> str:
    """Why no next pose is advised for a verdict ``best`` whose alternatives ``alts`` are all ``best``
    plus one component (``adds_to``), within the nested margin (compare/diagnosis.py
    ``_nested_margin``: the larger of the paired noise margin ``paired`` [fraction, one per
    alternative] and ``model_form_margin`` [fraction], what absorbing the model-form error gives any
    candidate).  Where the gain of the extra component is within the model-form margin, no number of
    poses of the same kind decides it; where it is within the paired noise only, that margin shrinks as
    ``1 / sqrt(poses)`` (its degrees of freedom count distinct poses), so if the gain held, about
    ``n_poses ((paired / gain)^2 - 1)`` more poses would confirm the component.

    Examples
    --------
    >>> from flexmodal.compare.candidates import Candidate
    >>> best = {"_cand": Candidate(("tip_mass",), ("tip",), ()), "_heldout_eq": 0.0036}
    >>> alt = {"_cand": Candidate(("base_stiffness", "tip_mass"), ("base", "tip"), ()), "_heldout_eq": 0.0024,
    ...        "effect": "base_stiffness+tip_mass", "location": "base+tip"}
    >>> no_pose_decides(best, [alt], [0.002], 0.0008, 3)     # (0.2 / 0.12)^2 = 2.8: 3 x 1.8 more
    'no pose is advised: every alternative only adds a component, and on the blind trials one more pose \
settled such a component no more often where the candidates differ most than elsewhere; \
base_stiffness+tip_mass at base+tip: gain 0.12 % within the paired noise 0.2 %, about 6 more poses would \
confirm it if the gain held'
    """
    parts = []
    for e, noise in zip(alts, paired, strict=True):
        gain = best["_heldout_eq"] - e["_heldout_eq"]
        head = f"{e['effect']} at {e['location']}: gain {percent(gain)}"
        if gain <= model_form_margin or gain <= 0:
            parts.append(f"{head} within the model-form margin {percent(model_form_margin)}, which more "
                         "poses of this kind do not shrink")
        else:
            more = max(math.ceil(n_poses * ((noise / gain) ** 2 - 1) - 1e-9), 1)
            parts.append(f"{head} within the paired noise {percent(noise)}, about {more} more poses would "
                         "confirm it if the gain held")
    return ("no pose is advised: every alternative only adds a component, and on the blind trials one more "
            "pose settled such a component no more often where the candidates differ most than elsewhere; "
            + "; ".join(parts))
