"""Bounded least-squares fit of a candidate's parameters to measured frequencies, all folds at once.

The residuals are relative frequency errors ``f_model / f_measured - 1`` over the training configurations
of each fold.  The folds' parameter vectors are stacked into one block-diagonal problem so that a single
``scipy.optimize.least_squares`` (trust-region reflective, bounds on the log-parameters) fits the full
data set and every cross-validation fold together, with the analytic Jacobian from the eigenvalue
sensitivities (``d f / d lambda = 1 / (8 pi^2 f)``).  Starts: the best points of a coarse grid evaluated in
one batch (a multi-start without repeated solver calls), chosen per fold on its training configurations
only, refined to convergence and the best kept per fold, so held-out scores come from honest refits.

Mode pairing: model modes below 1e-3 of the lowest measured frequency are rigid-body modes and skipped,
and so are modes the rig's sensors cannot see (e.g. axial modes of a straight arm under transverse
accelerometers: sensor response below 1e-6 of the largest);
with measured shapes each measured mode is paired with the model mode of highest MAC (Allemang & Brown
1982) weighted by frequency proximity, ``MAC * exp(-|ln(f_model/f_measured)| / 0.25)`` (a few sensors alias
distant modes), by an optimal assignment re-done at every evaluation so that modes that swap order as
parameters move keep their identity; without shapes modes are paired in ascending order.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, linear_sum_assignment

from flexmodal.compare.candidates import Candidate
from flexmodal.compare.parametric import ReducedFamily, lam_to_hz, solve_family

EXTRA_PAIRING_MODES = 2
MAX_GRID = 81
PAIRING_LOG_WIDTH = 0.25
OBSERVABLE = 1e-6
MAX_NFEV = 60
N_STARTS = 3


@dataclass(frozen=True)
class Target:
    """Measured data: frequencies [C, n] Hz, optional shapes [C, n_sensors, n] at the family's sensors."""

    freq_hz: np.ndarray
    shapes: np.ndarray | None
    joint_angle_rad: dict[str, np.ndarray]   # per joint: its angle at each configuration


@dataclass(frozen=True)
class FitResult:
    theta: np.ndarray          # [F, J] fitted parameters per fold (fold 0 = all configurations)
    freq_hz: np.ndarray        # [F, C, n] model frequencies of each fold's fit at every configuration
    mac: np.ndarray | None     # [F, C, n] MAC of the paired modes with the measured shapes
    train: np.ndarray          # [F, C] training mask


def design(cand: Candidate, target: Target) -> np.ndarray:
    """D [C, H, J]: log h[c, i] = sum_j D[c, i, j] theta_j for the candidate's handles ``cand.handles``."""
    C = target.freq_hz.shape[0]
    D = np.zeros((C, len(cand.handles), cand.n_params))
    for j, p in enumerate(cand.params):
        i = cand.handles.index(p.handle)
        if p.power == 0:
            D[:, i, j] = 1.0
        else:
            joint = p.handle.partition("@")[2]
            D[:, i, j] = target.joint_angle_rad[joint] ** p.power
    return D


def _pair(f_all: np.ndarray, shapes: np.ndarray, target: Target) -> tuple[np.ndarray, np.ndarray | None]:
    """Indices [B, C, n] of the model modes paired with the measured ones (see module docstring), and the
    MAC [B, C, n, n_all] of every measured mode with every model mode (None without measured shapes)."""
    n = target.freq_hz.shape[1]
    valid = f_all > 1e-3 * target.freq_hz.min(axis=1)[None, :, None]
    seen = np.sum(shapes * shapes, axis=-2)                               # [B, C, n_all]
    if seen.size and np.any(seen > 0):
        valid &= seen > OBSERVABLE**2 * np.max(seen, axis=-1, keepdims=True)
    idx = np.argsort(~valid, axis=-1, kind="stable")[..., :n]
    if target.shapes is None:
        return idx, None
    meas = target.shapes
    num = np.abs(np.swapaxes(meas, -1, -2).conj() @ shapes) ** 2           # [B, C, n, n_all]
    mac = num / np.maximum(np.sum(np.abs(meas) ** 2, axis=-2)[None, :, :, None] * seen[:, :, None, :], 1e-300)
    near = np.exp(-np.abs(np.log(np.maximum(f_all[:, :, None, :], 1e-300) / target.freq_hz[None, :, :, None]))
                  / PAIRING_LOG_WIDTH)
    score = np.where(valid[:, :, None, :], mac * near, -1.0)
    usable = ~np.isnan(meas).any(axis=(1, 2))                             # configs with complete shapes
    best = np.argmax(score, axis=-1)                                      # [B, C, n]
    srt = np.sort(best, axis=-1)
    unique = np.all(srt[..., 1:] != srt[..., :-1], axis=-1)               # greedy choice is a permutation
    idx = np.where((usable[None, :] & unique)[..., None], best, idx)
    for b, c in zip(*np.nonzero(usable[None, :] & ~unique), strict=True):
        idx[b, c] = linear_sum_assignment(-score[b, c])[1]
    return idx, mac


def paired_modes(fam: ReducedFamily, h: np.ndarray, target: Target
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Model modes paired with the measured ones at handle values ``h`` [B, C, H]: frequencies [B, C, n],
    d lambda / d h [B, C, n, H], sensor shapes [B, C, n_sensors, n] and MAC [B, C, n] (None w/o shapes)."""
    n = target.freq_hz.shape[1]
    lam, dlam, shapes = solve_family(fam, h, n + EXTRA_PAIRING_MODES)
    f_all = lam_to_hz(lam)
    idx, mac_all = _pair(f_all, shapes, target)
    mac = None if mac_all is None else np.take_along_axis(mac_all, idx[..., None], -1)[..., 0]
    return (np.take_along_axis(f_all, idx, -1), np.take_along_axis(dlam, idx[..., None], 2),
            np.take_along_axis(shapes, idx[:, :, None, :], -1), mac)


def evaluate(fam: ReducedFamily, D: np.ndarray, theta: np.ndarray, target: Target
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """Model at parameters ``theta`` [B, J]: paired freqs [B, C, n], d f/d theta [B, C, n, J], MAC, h."""
    h = np.exp(D @ theta.T).transpose(2, 0, 1) if D.size else np.ones((theta.shape[0],) + D.shape[:2])
    f, dlam, _, mac = paired_modes(fam, h, target)
    dl = dlam * h[:, :, None, :]                                          # d lambda / d log h
    df = (dl @ D[None]) / (8 * math.pi**2 * np.maximum(f, 1e-12))[..., None]
    return f, df, mac, h


def _grid(cand: Candidate) -> np.ndarray:
    pts = np.array(list(itertools.product(*[p.grid for p in cand.params])), float)
    if len(pts) > MAX_GRID:
        pts = pts[np.linspace(0, len(pts) - 1, MAX_GRID).round().astype(int)]
    return pts


def fit_candidate(fam: ReducedFamily, cand: Candidate, target: Target, train: np.ndarray,
                  reg_weight: float = 0.02, starts: np.ndarray | None = None) -> FitResult:
    """Fit ``cand`` on every fold's training configurations (``train`` [F, C] bool, fold 0 = all).

    Every fold is an independent fit to convergence that never sees its held-out configurations:
    the start points are the product of the parameters' start grids (at most ``MAX_GRID``) plus
    ``starts``, shared ``[G, J]`` or per fold ``[F, G, J]`` (seeded starts of a combination, built from
    each fold's own part optima); each fold keeps the ``N_STARTS`` with the lowest cost on its
    *training* configurations, and all folds' starts are refined together in one stacked trust-region
    solve (block-diagonal Jacobian, so each block converges to its own fold's optimum); the best refined
    start of each fold is kept.  The pose-law slope/curvature are regularised towards a constant
    stiffness by residual rows ``reg_weight * theta * span^power`` (``span`` = joint angle range).
    """
    D = design(cand, target)
    fm = target.freq_hz
    F, J = len(train), cand.n_params
    lower = np.array([p.lower for p in cand.params])
    upper = np.array([p.upper for p in cand.params])
    reg = np.array([0.0 if p.power == 0 else reg_weight * _span(target, p.handle) ** p.power
                    for p in cand.params])
    grid = _grid(cand)
    if starts is not None:                                              # seeded starts + the own grid
        starts = np.asarray(starts, float)
        grid = np.vstack([starts, grid]) if starts.ndim == 2 else np.concatenate(
            [starts, np.repeat(grid[None], F, axis=0)], axis=1)
    pts = grid.reshape(-1, J)
    f, _, _, _ = evaluate(fam, D, pts, target)
    sq = np.sum(((f / fm) - 1.0) ** 2, axis=2)                           # [P, C]
    penalty = np.sum((reg * pts) ** 2, axis=1)                            # [P]
    if grid.ndim == 3:                                                    # per-fold starts [F, G, J]
        G = grid.shape[1]
        cost = np.einsum("fgc,fc->fg", sq.reshape(F, G, -1), train.astype(float)) + penalty.reshape(F, G)
        best = np.argsort(cost, axis=1)[:, :N_STARTS]
        x0 = grid[np.arange(F)[:, None], best].reshape(-1, J)
    else:
        cost = train.astype(float) @ sq.T + penalty[None]                 # [F, G]
        best = np.argsort(cost, axis=1)[:, :N_STARTS]
        x0 = grid[best].reshape(-1, J)
    k = best.shape[1]
    x, c = _solve(fam, D, target, np.repeat(train, k, axis=0), reg, lower, upper, x0, MAX_NFEV)
    pick = np.argmin(c.reshape(F, k), axis=1)
    theta = x.reshape(F, k, J)[np.arange(F), pick]
    f, _, mac, _ = evaluate(fam, D, theta, target)
    return FitResult(theta, f, mac, train)


def _solve(fam: ReducedFamily, D: np.ndarray, target: Target, train: np.ndarray, reg: np.ndarray,
           lower: np.ndarray, upper: np.ndarray, x0: np.ndarray, max_nfev: int
           ) -> tuple[np.ndarray, np.ndarray]:
    """One stacked trust-region least-squares solve over folds ``train`` [F, C]: theta [F, J], costs [F]."""
    fm = target.freq_hz
    F, J = x0.shape
    mask = np.repeat(train[:, :, None], fm.shape[1], axis=2)             # [F, C, n]
    cache: dict[bytes, tuple] = {}

    def model(x: np.ndarray) -> tuple:
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = evaluate(fam, D, x.reshape(F, J), target)
        return cache[key]

    def fun(x: np.ndarray) -> np.ndarray:
        f = model(x)[0]
        return np.concatenate([(f / fm - 1.0)[mask], (reg * x.reshape(F, J)).ravel()])

    def jac(x: np.ndarray) -> np.ndarray:
        g = model(x)[1] / fm[None, :, :, None]                           # [F, C, n, J]
        out = np.zeros((int(mask.sum()) + F * J, F * J))
        row = 0
        for fo in range(F):
            k = int(mask[fo].sum())
            out[row:row + k, fo * J:(fo + 1) * J] = g[fo][mask[fo]]
            row += k
        out[row:] = np.kron(np.eye(F), np.diag(reg))
        return out

    lo, hi = np.tile(lower, F), np.tile(upper, F)
    x0 = np.clip(x0.ravel(), lo + 1e-9, hi - 1e-9)
    sol = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", max_nfev=max_nfev,
                        xtol=1e-6, ftol=1e-8, gtol=1e-10)
    return sol.x.reshape(F, J), _fold_costs(sol.fun, mask, F, J, reg, sol.x)


def _fold_costs(r: np.ndarray, mask: np.ndarray, F: int, J: int, reg: np.ndarray, x: np.ndarray
                ) -> np.ndarray:
    counts = mask.reshape(F, -1).sum(axis=1)
    edges = np.concatenate([[0], np.cumsum(counts)])
    data = np.array([np.sum(r[edges[i]:edges[i + 1]] ** 2) for i in range(F)])
    return data + np.sum((reg * x.reshape(F, J)) ** 2, axis=1)


def _span(target: Target, handle: str) -> float:
    q = target.joint_angle_rad[handle.partition("@")[2]]
    return max(float(np.ptp(q)), 1e-3)
