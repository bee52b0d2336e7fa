"""A cross-validation fold stuck in a local minimum is refitted from another fold's optimum
(compare/fit.py ``_stuck_folds``): blind draw 1788 case 7 (counted from 0), regenerated from its seed."""

from __future__ import annotations

import numpy as np
import pytest

import flexmodal.compare.fit as fit
from flexmodal.compare.diagnosis import _combo_starts, _Context, _rebuild, diagnose, folds_for, prepare
from flexmodal.fixtures.blind import draw_cases

TRIPLE = ("grounded_spring+joint_stiffness+tip_mass", "link2@0.5+elbow+tip")
PAIR_FOLDS = [[6.5112, 4.1571], [6.4655, 4.3526], [6.4698, 4.2888], [6.4618, 4.3256], [6.4606, 4.3461]]
"""log k [N/m], log k [N m/rad]: the link2@0.5 spring with the elbow stiffness, per fold (main b0d6f71)."""
TIP_FOLDS = [[-3.3549, -8.3314], [-3.5216, -8.2528], [-3.4184, -8.4086], [-3.4550, -8.3722],
             [-3.4942, -8.2958]]
"""log mass [kg], log inertia [kg m^2] of the tip mass alone, per fold (main b0d6f71)."""


@pytest.fixture(scope="module")
def case():
    """Blind draw 1788 case 7: pusher rig, a grounded spring at link2@0.5 with a tip mass (~12 s)."""
    *_, last = draw_cases(8, 1788)
    return last


def _triple_folds(case) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triple's cross-validation as the diagnosis seeds it (from the pair's and the tip mass's fold
    optima): training sums of squares [F], the unseeded fit's [F], and the training masks."""
    meas = prepare(case.rig, case.table)
    train, _ = folds_for(meas.configs, "auto", meas.poses)
    ctx = _Context(case.rig, meas, train)
    cand = _rebuild(case.rig, meas, *TRIPLE)
    pair = _rebuild(case.rig, meas, "grounded_spring+joint_stiffness", "link2@0.5+elbow")
    tip = _rebuild(case.rig, meas, "tip_mass", "tip")
    starts = _combo_starts(cand, [(pair, np.array(PAIR_FOLDS)), (tip, np.array(TIP_FOLDS))])
    fam, folds = ctx.family(cand.handles), train[1:]

    def costs(res: fit.FitResult) -> np.ndarray:
        err = res.freq_hz / ctx.target.freq_hz[None] - 1.0
        return np.array([np.sum(err[f][folds[f]] ** 2) for f in range(len(folds))])

    seeded = costs(fit.fit_candidate(fam, cand, ctx.target, folds, starts=starts))
    return seeded, costs(fit.fit_candidate(fam, cand, ctx.target, folds)), folds


@pytest.mark.slow   # ~15 s: generating the draw's first 8 cases
def test_a_fold_stuck_in_a_local_minimum_reaches_the_training_optimum(case, monkeypatch):
    """Seeded from its parts' fold optima, fold 0 of the triple ends at a training RMS of 5.0 % (a spring
    of 700 N/m and a 6 g mass) where the other folds reach 0.39-0.43 % (spring 4500 N/m, mass 0.13 kg).
    Refitted from another fold's optimum on its own training configurations, its cost equals that of
    an independent multi-start (the candidate's own 81-point grid, no seeds) to 1e-5 (the flat inertia
    direction leaves the folds' optima 1.5e-6 apart by start)."""
    seeded, grid, folds = _triple_folds(case)
    n = folds.sum(axis=1) * case.n_modes
    assert np.all(np.sqrt(seeded / n) < 0.0045)
    np.testing.assert_allclose(seeded, grid, rtol=1e-5)
    monkeypatch.setattr(fit, "_stuck_folds", lambda *args: None)       # the fit before the rescue
    stuck, _, _ = _triple_folds(case)
    assert np.sqrt(stuck[0] / n[0]) > 0.04
    np.testing.assert_allclose(stuck[1:], grid[1:], rtol=1e-5)


@pytest.mark.slow   # ~25 s: the draw's first 8 cases and one diagnosis
def test_the_rescued_fold_lets_the_hidden_pair_be_found(case):
    """With the stuck fold the triple was held out at 3.4 % and the verdict was the tip mass alone
    (frequency RMS 17.8 %); refitted, the triple is held out at 0.44 %, and dropping its joint stiffness
    gives the hidden pair, the verdict."""
    v = diagnose(case.rig, case.table).verdict
    assert (v.effect, v.location) == (case.effect, case.location)
    assert case.location == "link2@0.5+tip"


# -- the rule on a toy with two basins (default suite) ------------------------------------------------
TOY_W2 = 0.3
"""Weight^2 of the toy's linear residuals (below)."""


def _toy_residuals(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Relative frequency errors r [B, C=4, 1] and d r / d theta [B, 4, 1, 1] of the toy at ``theta`` [B, 1]:
    ``theta^2 - 1`` at configurations 0 and 1 (a double well), ``w (theta - 1)`` at 2 and 3."""
    t = theta[:, :1, None]                                                 # [B, 1, 1]
    w = np.sqrt(TOY_W2)
    r = np.concatenate([t * t - 1, t * t - 1, w * (t - 1), w * (t - 1)], axis=1)
    dr = np.concatenate([2 * t, 2 * t, np.full_like(t, w), np.full_like(t, w)], axis=1)
    return r, dr[..., None]


def _toy_fit(monkeypatch, train: np.ndarray) -> tuple[fit.FitResult, list]:
    """``fit_candidate`` of the toy (one parameter in [-3, 3], one start, theta = -0.5) on the folds
    ``train`` [F, 4]; the real ``_solve`` and ``_stuck_folds``, ``evaluate`` the toy's; and the
    ``(train, x0)`` of every ``_solve`` call."""
    from flexmodal.compare.candidates import Candidate
    from flexmodal.models.effects import Param

    def toy_evaluate(fam, D, theta, target, gradients=True):
        r, dr = _toy_residuals(np.asarray(theta, float))
        return 1.0 + r, dr if gradients else None, None, None

    calls, solve = [], fit._solve

    def spy(fam, D, target, train, reg, lower, upper, x0, max_iter):
        calls.append((train.copy(), x0.copy()))
        return solve(fam, D, target, train, reg, lower, upper, x0, max_iter)

    monkeypatch.setattr(fit, "evaluate", toy_evaluate)
    monkeypatch.setattr(fit, "_solve", spy)
    cand = Candidate(("toy",), ("x",), (Param("toy", "a", "a@x", 0, -3.0, 3.0, (-0.5,)),))
    target = fit.Target(np.ones((4, 1)), None, {})
    return fit.fit_candidate(None, cand, target, train), calls


def _toy_cost(theta: np.ndarray, train: np.ndarray) -> np.ndarray:
    r, _ = _toy_residuals(theta)
    return np.sum(r[..., 0] ** 2 * train, axis=1)


def test_a_stuck_fold_is_refitted_and_the_others_are_left_bit_for_bit(monkeypatch):
    """A toy family with two basins: a fold's training cost is ``A (theta^2 - 1)^2 + B (theta - 1)^2``
    (A double-well configurations, B = 0.3 per linear one), whose stationary points are the global
    minimum theta = 1 (cost 0) and, where ``B < A / 2``, a barrier and a local minimum at
    ``theta = (-1 +- sqrt(1 - 2 B / A)) / 2``.  From theta = -0.5 the fold of all configurations and the
    two folds holding out a linear one (A = 2) stop in the local minimum (-0.816, -0.918); the two
    holding out a double-well configuration (A = 1: no local minimum) reach 1.  The stuck folds are
    refitted from fold 1's optimum and keep its lower training cost (theta = 1); folds 1 and 2 are
    bit-for-bit those of the fit without the refit."""
    train = np.vstack([np.ones(4, bool), ~np.eye(4, dtype=bool)])
    monkeypatch.setattr(fit, "_stuck_folds", lambda *args: None)      # the fit before the refit
    before, _ = _toy_fit(monkeypatch, train)
    monkeypatch.undo()
    after, calls = _toy_fit(monkeypatch, train)
    A, B = np.array([2, 1, 1, 2, 2]), TOY_W2 * np.array([2, 2, 2, 1, 1])
    local = (-1 - np.sqrt(np.maximum(1 - 2 * B / A, 0))) / 2
    np.testing.assert_allclose(before.theta[:, 0], np.where(B < A / 2, local, 1.0), atol=1e-6)
    stuck, kept = [0, 3, 4], [1, 2]
    assert len(calls) == 2
    np.testing.assert_array_equal(calls[1][0], train[stuck])               # refit on its own training rows
    np.testing.assert_array_equal(calls[1][1], before.theta[[1, 1, 1]])   # from fold 1's optimum
    np.testing.assert_allclose(after.theta[stuck, 0], 1.0, atol=1e-6)
    assert np.all(_toy_cost(after.theta, train)[stuck] < _toy_cost(before.theta, train)[stuck])
    assert np.array_equal(after.theta[kept], before.theta[kept])
    assert np.array_equal(after.freq_hz[kept], before.freq_hz[kept])


def test_the_fit_on_all_configurations_alone_is_never_refitted(monkeypatch):
    """With one fold (F = 1) there is no other optimum: ``_solve`` runs once and the fold stays in the
    toy's local minimum (theta = (-1 - sqrt(1 - 2 B / A)) / 2, A = 2, B = 0.6)."""
    result, calls = _toy_fit(monkeypatch, np.ones((1, 4), bool))
    assert len(calls) == 1
    np.testing.assert_allclose(result.theta[0, 0], (-1 - np.sqrt(1 - 2 * 0.6 / 2)) / 2, atol=1e-6)


def test_the_stuck_folds_example_is_run_by_the_doctest_walk():
    """The ``_stuck_folds`` Examples are collected: tests/test_doctests.py runs compare/fit.py and doctest
    finds the private function's examples (no ``--doctest-modules`` is needed)."""
    import doctest

    from test_doctests import _modules_with_examples

    assert "flexmodal.compare.fit" in _modules_with_examples()
    found = {t.name: len(t.examples) for t in doctest.DocTestFinder().find(fit)}
    assert found["flexmodal.compare.fit._stuck_folds"] >= 4


def test_the_module_docstring_states_the_stuck_fold_threshold():
    """compare/fit.py's overview gives the refit's threshold as ``STUCK_GAIN`` is (at e1fd197 it said
    "costs less", while the code needs more than 1 % less)."""
    assert f"costs more than {100 * fit.STUCK_GAIN:g} % less" in " ".join(fit.__doc__.split())
