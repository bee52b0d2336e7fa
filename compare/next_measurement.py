"""The next measurement: the untested pose (and mode) that would best tell an ambiguous verdict from its
rivals, ranked by expected information.

Every fitted candidate predicts a new measurement at a pose it has not seen as a normal of the relative
frequency of each mode, with mean its fitted reduced model's frequency and variance ``scatter^2 +
g^T C g`` (dimensionless, relative frequency squared; ``g`` the relative sensitivities to the fitted
parameters there, ``C`` their linearised Gauss-Newton covariance from the measured poses: Seber & Wild
1989 §5.1).  How well a measurement at that pose tells candidate ``a`` from ``b`` is the symmetric
Kullback-Leibler divergence of their predictive normals (Box & Hill 1967, "Discrimination among
mechanistic models", Technometrics 9: 57-71; Kullback 1959), in nats, summed over modes.

Functions (``ctx`` is the diagnosis' fit context, ``FitContext``; ``entry`` a fitted candidate of its
ranking: ``_cand``, ``_fam``, ``_theta0``):

``trial_poses(rig, poses)``
    The candidate poses {label: pose} after measuring ``poses`` (labels ``<var>=<value>``).
``separating_measurement(ctx, a, b)``
    The pose and mode where two fitted candidates differ most (``separate_at`` of an alternative).
``next_measurements(ctx, best, rivals, scatter)``
    Untested poses ranked by expected information against the verdict's rivals.

Examples
--------
>>> from flexmodal.models.rig import load_rig
>>> rig = load_rig("examples/rigs/seed003_two_link.toml")
>>> list(trial_poses(rig, [{"theta_deg": 0.0}, {"theta_deg": 60.0}, {"theta_deg": 120.0}]))[:4]
['theta_deg=0', 'theta_deg=10', 'theta_deg=20', 'theta_deg=30']
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from flexmodal.compare.fit import Target, design, evaluate, linear_cov
from flexmodal.compare.gap import Measured
from flexmodal.compare.parametric import ReducedFamily, lam_to_hz, solve_family
from flexmodal.models.rig import Rig

TRIAL_POINTS = 13
MAX_ADVICE = 3


class FitContext(Protocol):
    """What the advice needs of the diagnosis' fit context (compare/diagnosis.py ``_Context``)."""

    rig: Rig
    meas: Measured
    target: Target
    trial: tuple[tuple[str, ...], FitContext] | None     # the trial context of ``_trial_context``

    def family(self, handles: Sequence[str]) -> ReducedFamily: ...

    def at(self, poses: Sequence[dict[str, float]], n_modes: int) -> FitContext: ...


def trial_poses(rig: Rig, poses: Sequence[dict[str, float]]) -> dict[str, dict[str, float]]:
    """Candidate poses for a next measurement after measuring ``poses``: each pose variable moved over
    ``TRIAL_POINTS`` points of its measured range (the others at the first pose's values),
    {``<var>=<value>``: pose}; ``verdict.next_measurements`` and ``separate_at`` name them."""
    trial: dict[str, dict[str, float]] = {}
    for v in rig.pose_variables:
        vals = np.array([p[v] for p in poses])
        trial.update({f"{v}={x:g}": {**poses[0], v: float(x)}
                      for x in np.linspace(vals.min(), vals.max(), TRIAL_POINTS)})
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


def separating_measurement(ctx: FitContext, a: dict, b: dict) -> dict:
    """The pose (``trial_poses``) and model mode (up to two beyond the measured ones) where the fitted
    candidates ``a`` and ``b`` differ most (their reduced models, compare/parametric.py):
    ``{"separate_at", "separate_mode", "separate_rel_diff"}`` (empty when there is no such pose)."""
    trial = trial_poses(ctx.rig, ctx.meas.poses)
    if not trial:
        return {}
    diff = np.abs(_trial_frequencies(ctx, a, trial) / _trial_frequencies(ctx, b, trial) - 1.0)
    if not np.isfinite(diff).any():
        return {}
    i, m = np.unravel_index(np.nanargmax(diff), diff.shape)
    return {"separate_at": list(trial)[i], "separate_mode": int(m + 1),
            "separate_rel_diff": float(diff[i, m])}


def _predictive(ctx: FitContext, entry: dict, nctx: FitContext, scatter: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """``entry``'s fitted candidate at the poses of ``nctx``: frequencies [P, n] Hz and the variance of
    their relative prediction [P, n] (dimensionless) from its linearised parameter covariance (reduced
    model)."""
    cand = entry["_cand"]
    _, df, _, _ = evaluate(entry["_fam"], design(cand, ctx.target), entry["_theta0"][None], ctx.target)
    cov = linear_cov(df[0] / ctx.meas.freq_hz[..., None], scatter)
    n = ctx.meas.freq_hz.shape[1]
    h = np.exp(design(cand, nctx.target) @ entry["_theta0"])[None]
    lam, dlam, _ = solve_family(nctx.family(cand.handles), h, n)
    f = lam_to_hz(lam[0])
    dl = dlam[0] * h[0][:, None, :]                                    # d lambda / d log h
    g = (dl @ design(cand, nctx.target)) / (8 * math.pi**2 * np.maximum(f, 1e-12) ** 2)[..., None]
    return f, np.einsum("cnj,jk,cnk->cn", g, cov, g)


def next_measurements(ctx: FitContext, best: dict, rivals: Sequence[dict], scatter: float) -> list[dict]:
    """Untested poses ranked by the expected information a measurement there brings on the choice
    between the verdict ``best`` and its ``rivals``: the Box & Hill (1967) discrimination criterion, the
    symmetric Kullback-Leibler divergence between the two candidates' predictive normals of each
    measured mode's relative frequency, ``0.5 [(v_a - v_b)^2 / (v_a v_b) + d^2 (1/v_a + 1/v_b)]`` with
    ``d`` their relative difference and ``v = scatter^2 + g^T C g`` (each candidate's linearised
    prediction variance: where a candidate is loosely pinned down it can follow a new point, and a
    measurement there decides little), summed over modes.  Poses are ranked by ``sum (1 - exp(-I))``
    over the rivals (each rival's information saturating: a pose that tells the verdict from every
    rival beats one that tells it from one rival by a mile); ``information_nats`` is the mean over the
    rivals.  At most ``MAX_ADVICE`` poses, each with the mode that carries most of it:
    ``[{"pose", "mode", "information_nats"}]``."""
    trial = trial_poses(ctx.rig, ctx.meas.poses)
    if not trial or not rivals:
        return []
    measured = {tuple(sorted(p.items())) for p in ctx.meas.poses}
    keep = [i for i, p in enumerate(trial.values()) if tuple(sorted(p.items())) not in measured]
    if not keep:
        return []
    labels = [list(trial)[i] for i in keep]
    nctx = _trial_context(ctx, trial)
    fa, va = (x[keep] for x in _predictive(ctx, best, nctx, scatter))
    va = va + scatter**2
    info = np.zeros(fa.shape)
    value = np.zeros(len(labels))
    for e in rivals:
        fb, vb = (x[keep] for x in _predictive(ctx, e, nctx, scatter))
        vb = vb + scatter**2
        d = fb / fa - 1.0
        each = np.nan_to_num(0.5 * ((va - vb) ** 2 / (va * vb) + d**2 * (1 / va + 1 / vb)))
        info += each / len(rivals)
        value += 1.0 - np.exp(-each.sum(axis=1))        # chance-like share of this rival ruled out
    order = [i for i in np.argsort(-value, kind="stable") if value[i] > 0][:MAX_ADVICE]
    return [{"pose": labels[i], "mode": int(np.argmax(info[i]) + 1), "information_nats": float(info[i].sum())}
            for i in order]
