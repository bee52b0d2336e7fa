"""Bounded least-squares fit of a candidate's parameters to measured frequencies, all folds at once.

The residuals are relative frequency errors ``f_model / f_measured - 1`` over the training configurations
of each fold.  The folds' parameter vectors are stacked into one block-diagonal problem so that a single
``scipy.optimize.least_squares`` (trust-region reflective, bounds on the log-parameters) fits the full
data set and every cross-validation fold together, with the analytic Jacobian from the eigenvalue
sensitivities (``d f / d lambda = 1 / (8 pi^2 f)``).  Starts: the best points of a coarse grid evaluated in
one batch (a multi-start without repeated solver calls), the two best refined and the better kept per fold.

Mode pairing: model modes below 1e-3 of the lowest measured frequency are rigid-body modes and skipped;
with measured shapes each measured mode is paired with the model mode of highest MAC (Allemang & Brown
1982) by an optimal assignment, re-done at every evaluation so that modes that swap order as parameters
move keep their identity; without shapes modes are paired in ascending order.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, linear_sum_assignment

from compare.candidates import Candidate
from compare.parametric import ReducedFamily, lam_to_hz, solve_family

EXTRA_PAIRING_MODES = 2
MAX_GRID = 81
MAX_NFEV = 20


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


def _pair(f_all: np.ndarray, shapes: np.ndarray, target: Target) -> np.ndarray:
    """Indices [B, C, n] of the model modes paired with the measured ones (see module docstring)."""
    B, C, n_all = f_all.shape
    n = target.freq_hz.shape[1]
    valid = f_all > 1e-3 * np.nanmin(target.freq_hz, axis=1)[None, :, None]
    order = np.argsort(~valid, axis=-1, kind="stable")
    idx = order[..., :n].copy()
    if target.shapes is None:
        return idx
    meas = target.shapes
    num = np.abs(np.einsum("csn,bcsm->bcnm", meas.conj(), shapes)) ** 2
    den = np.einsum("csn,csn->cn", meas.conj(), meas).real[None, :, :, None] * \
        np.einsum("bcsm,bcsm->bcm", shapes, shapes)[:, :, None, :]
    mac = num / np.maximum(den, 1e-300)
    mac = np.where(valid[:, :, None, :], mac, -1.0)
    usable = ~np.isnan(meas).any(axis=(1, 2))                             # configs with complete shapes
    best = np.argmax(mac, axis=-1)                                        # [B, C, n]
    srt = np.sort(best, axis=-1)
    unique = np.all(srt[..., 1:] != srt[..., :-1], axis=-1)               # greedy choice is a permutation
    idx = np.where((usable[None, :] & unique)[..., None], best, idx)
    for b, c in zip(*np.nonzero(usable[None, :] & ~unique), strict=True):
        idx[b, c] = linear_sum_assignment(-mac[b, c])[1]
    return idx


def evaluate(fam: ReducedFamily, D: np.ndarray, theta: np.ndarray, target: Target
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Model at parameters ``theta`` [B, J]: paired freqs [B, C, n], d f/d theta [B, C, n, J], MAC, h."""
    n = target.freq_hz.shape[1]
    h = np.exp(np.einsum("chj,bj->bch", D, theta))
    lam, dlam, shapes = solve_family(fam, h, n + EXTRA_PAIRING_MODES)
    f_all = lam_to_hz(lam)
    idx = _pair(f_all, shapes, target)
    f = np.take_along_axis(f_all, idx, -1)
    dl = np.take_along_axis(dlam, idx[..., None], 2)                      # [B, C, n, H]
    dl_dtheta = np.einsum("bcnh,bch,chj->bcnj", dl, h, D)
    df = dl_dtheta / (8 * math.pi**2 * np.maximum(f, 1e-12))[..., None]
    mac = None
    if target.shapes is not None:
        ps = np.take_along_axis(shapes, idx[:, :, None, :], -1)
        meas = target.shapes
        num = np.abs(np.einsum("csn,bcsn->bcn", meas.conj(), ps)) ** 2
        den = np.einsum("csn,csn->cn", meas.conj(), meas).real[None] * np.einsum("bcsn,bcsn->bcn", ps, ps)
        mac = num / np.maximum(den, 1e-300)
    return f, df, mac, h


def _grid(cand: Candidate) -> np.ndarray:
    pts = np.array(list(itertools.product(*[p.grid for p in cand.params])), float)
    if len(pts) > MAX_GRID:
        pts = pts[np.linspace(0, len(pts) - 1, MAX_GRID).round().astype(int)]
    return pts


def fit_candidate(fam: ReducedFamily, cand: Candidate, target: Target, train: np.ndarray,
                  reg_weight: float = 0.02) -> FitResult:
    """Fit ``cand`` on every fold's training configurations (``train`` [F, C] bool, fold 0 = all).

    Fold 0 is fitted from the two best grid points (multi-start); the cross-validation folds, stacked in
    one problem, start from fold 0's optimum.  The pose-law slope/curvature are regularised towards a
    constant stiffness by residual rows ``reg_weight * theta * span^power`` (``span`` = joint angle range).
    """
    D = design(cand, target)
    fm = target.freq_hz
    lower = np.array([p.lower for p in cand.params])
    upper = np.array([p.upper for p in cand.params])
    reg = np.array([0.0 if p.power == 0 else reg_weight * _span(target, p.handle) ** p.power
                    for p in cand.params])
    grid = _grid(cand)
    f, _, _, _ = evaluate(fam, D, grid, target)
    cost = np.nansum(((f / fm) - 1.0) ** 2, axis=(1, 2)) + np.sum((reg * grid) ** 2, axis=1)
    starts = grid[np.argsort(cost)[:2]]
    best = None
    for s in starts:
        x, c = _solve(fam, D, target, train[:1], reg, lower, upper, s[None])
        if best is None or c[0] < best[1]:
            best = (x, c[0])
    theta0 = best[0]
    theta = theta0
    if len(train) > 1:
        x, _ = _solve(fam, D, target, train[1:], reg, lower, upper, np.repeat(theta0, len(train) - 1, axis=0))
        theta = np.vstack([theta0, x])
    f, _, mac, _ = evaluate(fam, D, theta, target)
    return FitResult(theta, f, mac, train)


def _solve(fam: ReducedFamily, D: np.ndarray, target: Target, train: np.ndarray, reg: np.ndarray,
           lower: np.ndarray, upper: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One stacked trust-region least-squares solve over folds ``train`` [F, C]; returns theta [F, J], costs."""
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
    sol = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", max_nfev=MAX_NFEV,
                        xtol=1e-8, ftol=1e-8, gtol=1e-10)
    return sol.x.reshape(F, J), _fold_costs(sol.fun, mask, F, J, reg, sol.x)


def _fold_costs(r: np.ndarray, mask: np.ndarray, F: int, J: int, reg: np.ndarray, x: np.ndarray) -> np.ndarray:
    counts = mask.reshape(F, -1).sum(axis=1)
    edges = np.concatenate([[0], np.cumsum(counts)])
    data = np.array([np.sum(r[edges[i]:edges[i + 1]] ** 2) for i in range(F)])
    return data + np.sum((reg * x.reshape(F, J)) ** 2, axis=1)


def _span(target: Target, handle: str) -> float:
    q = target.joint_angle_rad[handle.partition("@")[2]]
    return max(float(np.ptp(q)), 1e-3)
