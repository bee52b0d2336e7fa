"""Sim-to-real gap diagnosis (docs/formats.md): where the gap lies, which effect explains it, judged held out.

1. Baseline: the nominal rig's FE modes (models/frame.py) against the measured ones, per mode and
   configuration.  When its RMS is within ``NONE_FACTOR`` times the measurement scatter, on top of the
   error the frame's beam theory is known to make (``_none_level``), the verdict is ``none`` -- the
   scatter never taken above what the best single candidate leaves held out, or with the fallback
   scatter above that RMS's 95 % chi-square upper limit (``_none_scatter``).
2. ``where``: the modes and configurations that carry the gap, and the region of the arm whose handles'
   frequency sensitivities best explain the error pattern (R^2, compare/gap.py; among regions within
   ``REGION_TIE`` of the best, the verdict's), plus MAC/COMAC when shapes were measured.
3. Ranking: every effect at every location (compare/candidates.py) fitted to all data; the
   ``PAIR_POOL`` best singles and their pairs, the best of each of the ``LEADS`` best effects among
   them paired with every other single (``_lead_pairs``), and, only when no pair explains the gap,
   each of the ``TRIPLE_PAIRS`` best pairs extended by its ``PARTNERS`` score-test partners
   (``_partners``); a chosen combination with each component replaced by every other single, and a
   chosen pair with every pair of a pooled single (``_swapped``).  Candidates are
   cross-validated, best in-sample score first, while they can still win, and the ``MAX_ALTERNATIVES``
   best-fitting ones not nested in the lowest held-out one that could still equal it within noise
   (possible alternatives, ``_cross_validate_promising``): every fold is refitted to
   convergence from starts chosen on its own training data (compare/fit.py), so held-out errors are
   honest.  Score (lower is better):
   ``sqrt(h^2 + scatter^2) * (1 + PENALTY * n_params)``: a complexity penalty, with the scatter as a
   floor so that candidates within the noise are ordered by simplicity; ``h`` is the held-out frequency
   RMS, or with measured shapes the frequency-equivalent error of the held-out frequencies and shape
   misfits together (``_equivalent``).
   ``joint_stiffness_pose`` ranks above the constant ``joint_stiffness`` at the same joint only when its
   held-out error is lower.  The scatter comes from the data when it can (compare/gap.py
   ``estimate_scatter``), else from the caller.
4. Verdict: the simplest candidate not worse held out than the best beyond the nested margin, pruned
   of components that do not improve the held-out error beyond that margin (the noise of a paired
   comparison on the same held-out residuals, or what absorbing the model-form error can gain,
   ``_nested_margin``, that error never taken below the frame's known beam-theory error,
   ``_beam_theory_form``) or
   sit at their lower bound, passed over when a parameter runs out of range; the nested margin
   applies to candidates of which one contains the other, the paired noise margin between different
   effects (``_order``); ``none`` when the verdict's candidate does not beat the nominal model (no
   parameters, nested in every candidate) beyond the nested margin, its noise part never judged at a
   level above ``NONE_NOISE_FACTOR`` times the measurement scatter (``_none_margin``).  When that
   choice is an ambiguous effect, every ranked single that is an added mass is refitted as a point mass
   (no rotary inertia, one parameter fewer, ``_point_masses``) and the verdict chosen again.
   ``explained``
   is false when the held-out RMS is above ``EXPLAINED_FACTOR`` times the scatter or the held-out
   residuals are structured; parameters at bounds and parameters the data cannot identify are
   flagged; candidates equal within noise, and candidates with one component more within the
   nested margin, are listed as alternatives with the measurement that would separate them (a
   ``none`` verdict lists the candidates held out better than the nominal model).  Parameter
   intervals include a model-form term (the held-out error taken as systematic per mode).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy.special import stdtrit
from scipy.stats import chi2
from threadpoolctl import threadpool_limits

from flexmodal.checked_io.percent import percent
from flexmodal.checked_io.plural import counted
from flexmodal.checked_io.progress import progress_bar
from flexmodal.compare.candidates import Candidate, combine, components, parse_effects, single_candidates
from flexmodal.compare.errors import CompareError
from flexmodal.compare.fit import Target, design, evaluate, fit_candidate, linear_cov, paired_modes
from flexmodal.compare.gap import (
    FALLBACK_SOURCE,
    MIN_SCATTER_REL,
    Measured,
    Scatter,
    carriers,
    comac,
    estimate_scatter,
    gap_summary,
    joint_angles_rad,
    prepare,
    region_scores,
    rms,
)
from flexmodal.compare.next_measurement import (
    adds_to,
    next_measurements,
    no_pose_decides,
    separating_measurement,
    shape_noise_var,
)
from flexmodal.compare.parametric import handles_for, pose_basis, reduce_family
from flexmodal.compare.result import (
    Alternative,
    Baseline,
    CandidateCount,
    CandidateScore,
    Diagnosis,
    Holdout,
    NextMeasurement,
    Predictions,
    Remaining,
    ScatterSource,
    Verdict,
    Where,
)
from flexmodal.compare.sensor_flag import flag_text, sensor_check, sensor_flag
from flexmodal.compare.tables import shape_warnings
from flexmodal.compare.verdict_text import EXPLAINED_FACTOR, SHEAR_UNCALIBRATED, UNLIKELY, gap_words
from flexmodal.contract.mac import mac_pairs
from flexmodal.contract.table import ModalTable
from flexmodal.models.effects import REGISTRY, get_effect
from flexmodal.models.rig import Link, Rig

DEFAULT_SCATTER = 0.005
MIN_SCATTER = 1e-3
"""No candidate is ranked against a scatter below the reduced (Ritz) model's own accuracy, 0.1 %."""
BOUND_TOL = 1e-3
"""A fitted parameter within this fraction of its range from a bound is at the bound."""
UNIDENTIFIED_STD = 1.0
HELDOUT_INFLATION = 1.5
STRUCTURE_QUANTILE = 0.999
MAX_ALTERNATIVES = 3
MAX_SUPERSETS = 2
"""Alternatives: up to 3 candidates within noise, and up to 2 with one component more (``_nested_margin``)."""
NONE_FACTOR = 2.0
NONE_NOISE_FACTOR = 4.0
"""A held-out RMS above 4x the measurement scatter is model form, not noise (``_none_margin``)."""
PENALTY = 0.15
PAIR_POOL = 8
PARTNERS = 3
"""Score-test partners (``_partners``) of each of the best pairs when no pair explains (triples)."""
LEADS = 3
LEAD_TRAIN = 6
LEAD_PARTNERS = 5
"""The ``LEADS`` best singles (held-out score) and the best of each of the ``LEADS`` best effects
are each paired with every single outside the pair pool, given at least ``LEAD_TRAIN`` training
frequencies per leave-one-pose-out fold; with fewer, the best single with its ``LEAD_PARTNERS``
score-test partners (``_lead_pairs``)."""
TRIPLE_PAIRS = 3
MIN_CROSS_VALIDATED = 6
REGION_TIE = 0.8
FEATURE_Z = 3.3
"""A residual feature beyond 3.3 standard errors (two-sided 0.1 %) points outside the library."""
Z95 = 1.959963984540054
RIVAL_MARGIN = 3.0
MAX_RIVALS = 6
"""An ambiguous verdict's next measurement is chosen against its rivals: the candidates (not supersets)
within 3x the noise margin of its held-out error, at most 6 (the alternatives are those within 1x)."""
INTERVAL_METHOD = ("linearised (Gauss-Newton) covariance at the ranking scatter, widened to the "
                   "jackknife over the cross-validation refits where larger, plus a model-form term: the "
                   "held-out RMS error taken as systematic per mode (fully correlated over poses); "
                   "Student t quantile")
RANKING_LENGTH = 25
POISSON = 0.3
"""Poisson's ratio of the links' metal for the beam-theory model-form level (``_beam_theory_form``)."""


def folds_for(configs: Sequence[str], holdout: str | Sequence[str] = "auto",
              poses: Sequence[dict[str, float]] | None = None) -> tuple[np.ndarray, str]:
    """Training masks [F, C] (fold 0 = all configurations) and a description of the scheme.

    ``auto``: leave one *pose* out up to 10 distinct poses, else 5-fold over poses (interleaved); the
    configurations of one pose (repeated measurements, e.g. impact and random runs) are held out
    together, so a held-out configuration never has its twin in the training set.  Without ``poses``
    every configuration is its own pose.  A list of configurations: one fold holding those out.
    """
    C = len(configs)
    if isinstance(holdout, str) and holdout.strip() == "auto":
        keys = [tuple(sorted(p.items())) for p in poses] if poses is not None else list(range(C))
        group = np.array([list(dict.fromkeys(keys)).index(k) for k in keys])
        G = int(group.max()) + 1
        k = G if G <= 10 else 5
        held = [group % k == i for i in range(k)]
        scheme = ("leave-one-configuration-out" if G == C else "leave-one-pose-out") if k == G else \
            f"{k}-fold over {'configurations' if G == C else 'poses'}"
    else:
        listed = holdout.split(",") if isinstance(holdout, str) else holdout
        names = [h.strip() for h in listed if h.strip()]
        bad = [h for h in names if h not in configs]
        if bad:
            raise CompareError(f"--holdout: no configuration {bad[0]!r} in the measured table "
                               f"(have {', '.join(configs)})")
        held = [np.isin(np.array(configs), names)]
        if (~held[0]).sum() < 2 or not held[0].any():
            raise CompareError(f"--holdout: holding out {len(names)} of {C} configurations leaves "
                               f"{int((~held[0]).sum())} to fit (need >= 2 to fit and >= 1 held out)")
        scheme = "held out: " + ", ".join(names)
    train = np.array([np.ones(C, bool)] + [~h for h in held])
    return train, scheme


def _effect_region(rig: Rig, effect: str, location: str) -> str:
    """The ``where.region`` label of one effect's location (e.g. ``joint:elbow``, ``link:link2``): the
    registry entry's region kind, else the kind of the part the location names."""
    kind = get_effect(effect).region
    if kind:
        return f"{kind}:{location}"
    if location in [j.name for j in rig.joints]:
        return f"joint:{location}"
    if location in [m.name for m in rig.members]:
        return f"member:{location}"
    return location  # base, tip, sensors


class _Context:
    """Everything the candidate fits share: pose bases, handles, target, folds."""

    def __init__(self, rig: Rig, meas: Measured, train: np.ndarray, n_modes: int | None = None) -> None:
        self.rig, self.meas, self.train = rig, meas, train
        self.handles = handles_for(rig)
        self.index = {h.name: i for i, h in enumerate(self.handles)}
        n = meas.freq_hz.shape[1] if n_modes is None else n_modes
        exact = [tuple(sorted((k, float(v).hex()) for k, v in p.items())) for p in meas.poses]
        distinct = dict(zip(exact, meas.poses, strict=True))
        made = {k: pose_basis(rig, self.handles, p, n) for k, p in distinct.items()}
        if meas.sensors:                   # one basis per distinct pose (a repeat is the same object)
            rows = [s.name for s in rig.sensors]
            keep = [rows.index(s) for s in meas.sensors]
            made = {k: replace(b, sensors=b.sensors[keep]) for k, b in made.items()}
        self.bases = [made[k] for k in exact]
        self.target = Target(meas.freq_hz, meas.shapes, joint_angles_rad(rig, meas.poses))
        self.shape_dof = len(meas.sensors) - 1 if meas.shapes is not None else 0
        self.shape_floor = math.inf      # smallest in-sample mean (1 - MAC) of any model fitted so far
        keys = [tuple(sorted(p.items())) for p in meas.poses]
        self.pose_share = len(set(keys)) / max(len(keys), 1)   # repeats add no model-form information
        self.trial: tuple[tuple[str, ...], _Context] | None = None   # next_measurement's trial context
        self.model_form = 0.0            # model-form level of nested comparisons (``_nested_margin``)
        self.none_form = 0.0             # model-form level of the ``none`` test (``_none_margin``)
        self.beam_form = _beam_theory_form(rig, meas.freq_hz)   # the frame's known beam-theory error

    def family(self, handles: Sequence[str]):
        idx = [self.index[h] for h in handles]
        return reduce_family(self.bases, idx, np.array([self.handles[i].nominal for i in idx]))

    def at(self, poses: Sequence[dict[str, float]], n_modes: int) -> _Context:
        """A context over other ``poses`` (reduced models of ``n_modes`` modes there; its measured
        frequencies are placeholders, the first configuration's)."""
        new = Measured(tuple(f"q{i}" for i in range(len(poses))), tuple(poses),
                       np.repeat(self.meas.freq_hz[:1], len(poses), axis=0), None, ())
        return _Context(self.rig, new, np.ones((1, len(poses)), bool), n_modes=n_modes)


def _params(cand: Candidate, theta: np.ndarray) -> dict[str, float]:
    """Reported parameters (SI) from fitted theta.

    Names that collide in a combination are qualified, as little as needed: ``<effect>.<name>``, then
    ``<effect>.<name>@<location>``.
    """
    def keys(level: int) -> list[str]:
        out = []
        for p in cand.params:
            loc = p.handle.partition("@")[2]
            out.append([p.name, f"{p.effect}.{p.name}", f"{p.effect}.{p.name}@{loc}"][level])
        return out

    names = keys(0)
    for level in (1, 2):
        clash = [names.count(n) > 1 for n in names]
        finer = keys(level)
        names = [f if c else n for n, f, c in zip(names, finer, clash, strict=True)]
    return {k: float(math.exp(t)) if p.power == 0 else float(t)
            for k, p, t in zip(names, cand.params, theta, strict=True)}


def _score(heldout: float, n_params: int, scatter: float) -> float:
    return math.hypot(heldout, scatter) * (1 + PENALTY * n_params)


def _shape_misfit(mac: np.ndarray | None) -> np.ndarray:
    """``1 - MAC`` of the paired modes with complete measured shapes (flat; empty without shapes)."""
    if mac is None:
        return np.zeros(0)
    d = 1.0 - np.asarray(mac, float).ravel()
    return np.clip(d[np.isfinite(d)], 0.0, None)


def _equivalent(ctx: _Context, freq_err: np.ndarray, shape_misfit: np.ndarray, scatter: float
                ) -> tuple[float, int]:
    """Frequency-equivalent RMS error of frequencies and shapes together, and its degrees of freedom.

    Gaussian log-likelihood of both kinds of residual, each over its own noise level (a chi-square
    sum): a relative frequency error counts ``(e / scatter)^2`` with one degree of freedom; a mode with
    ``s`` measured sensors counts ``(1 - MAC) / floor`` with ``s - 1`` (1 - MAC of a shape with independent
    per-sensor noise is a chi-square over the ``s - 1`` directions orthogonal to the true shape, scaled by
    the relative noise squared, Allemang 2003).  ``floor`` is the shape noise per degree of freedom: the
    smallest in-sample mean ``1 - MAC`` of any model fitted to these data (the noise estimate of the
    largest model, as in Mallows' Cp, Mallows 1973), never below ``SHAPE_SCATTER_MIN^2``.  The result is
    ``scatter * sqrt(chi2 / dof)``: the frequency RMS itself without shapes; with shapes, the frequency
    RMS a candidate would need to be as unlikely as it is on both."""
    chi2, dof = float(np.sum(np.square(freq_err))) / scatter**2, freq_err.size
    if ctx.shape_dof > 0 and shape_misfit.size and math.isfinite(ctx.shape_floor):
        chi2 += float(np.sum(shape_misfit)) / shape_noise_var(ctx)
        dof += ctx.shape_dof * shape_misfit.size
    return scatter * math.sqrt(chi2 / max(dof, 1)), dof


def _rescore(ctx: _Context, entry: dict, scatter: float) -> None:
    """(Re)compute ``entry``'s scores from its stored residuals with the current shape noise floor."""
    fit, _ = _equivalent(ctx, entry["_fit_err"], entry["_fit_shape"], scatter)
    entry.update(_lower=_score(fit, entry["n_params"], scatter), _fit_eq=fit)
    if "_held_err" in entry:
        held, dof = _equivalent(ctx, entry["_held_err"], entry["_held_shape"], scatter)
        entry.update(score=_score(held, entry["n_params"], scatter), _heldout_eq=held, _n_eq=dof)


def _screen(ctx: _Context, cand: Candidate, scatter: float, parts: Sequence[dict] = ()) -> dict:
    """Fit ``cand`` to all configurations (fold 0 only); seeded from the ``parts``' optima for a
    combination.  ``_lower`` is the score it would get if its held-out error equalled this in-sample one
    (a held-out error is in practice never below it)."""
    fam = ctx.family(cand.handles)
    starts = _combo_starts(cand, [(p["_cand"], p["_theta0"][None]) for p in parts]) if parts else None
    res = fit_candidate(fam, cand, ctx.target, ctx.train[:1], starts=starts)
    err = res.freq_hz[0] / ctx.meas.freq_hz - 1.0
    entry = {"effect": cand.effect, "location": cand.location, "params": _params(cand, res.theta[0]),
             "fit_rms_rel_error": rms(err), "n_params": cand.n_params}
    if res.mac is not None:
        entry["mac_mean"] = float(np.nanmean(res.mac[0]))
    shape = _shape_misfit(None if res.mac is None else res.mac[0])
    if shape.size:
        ctx.shape_floor = min(ctx.shape_floor, float(np.mean(shape)))
    entry.update(_cand=cand, _parts=tuple(parts), _fam=fam, _theta0=res.theta[0], _freq_hz=res.freq_hz[0],
                 _fit_err=err.ravel(), _fit_shape=shape)
    _rescore(ctx, entry, scatter)
    return entry


def _cross_validate(ctx: _Context, entry: dict, scatter: float) -> None:
    """Refit ``entry``'s candidate on every cross-validation fold to convergence from starts chosen on
    that fold's training data only (a combination is seeded from its parts' own fold optima when they
    were cross-validated), and add the held-out error and the score to ``entry``."""
    cand, parts, train = entry["_cand"], entry["_parts"], ctx.train[1:]
    seeded = parts and all("_theta_folds" in p for p in parts)
    starts = _combo_starts(cand, [(p["_cand"], p["_theta_folds"]) for p in parts]) if seeded else None
    res = fit_candidate(entry["_fam"], cand, ctx.target, train, starts=starts)
    err = res.freq_hz / ctx.meas.freq_hz[None] - 1.0                    # [F, C, n]
    held = np.concatenate([err[f][~train[f]].ravel() for f in range(len(train))])
    shape = _shape_misfit(None if res.mac is None else
                          np.concatenate([res.mac[f][~train[f]].ravel() for f in range(len(train))]))
    entry.update(heldout_rms_rel_error=rms(held), heldout_max_rel_error=float(np.max(np.abs(held))),
                 _theta_folds=res.theta, _held_err=held, _held_shape=shape,
                 _heldout_freq_hz=_heldout_prediction(res.freq_hz, train))
    if shape.size:
        entry["heldout_shape_rms_error"] = math.sqrt(float(np.mean(shape)) / max(ctx.shape_dof, 1))
    _rescore(ctx, entry, scatter)


def _none_scatter(noise: Scatter, ranked: Sequence[dict]) -> float:
    """The scatter against which the nominal model's gap is judged (``NONE_FACTOR``): the
    measurement's scatter ``noise.value``, but never more than what the held-out frequency residuals
    of the cross-validated candidates ``ranked`` allow.  A candidate that predicts configurations it
    did not see to ``h`` shows that the noise is at most about ``h``, while a scatter from a few repeats
    (a chi-square of 4-6 degrees of freedom) or the fallback can be well above the true scatter and
    would then declare a weak effect ``none``.  Without an effect the best candidate's held-out error
    is the scatter itself (within 1.4x in the blind draws), so a gap within twice the scatter stays
    ``none``.

    With a measured scatter (repeats or ``freq_std_hz``) ``h`` is a second measurement and the lower of
    the two is taken.  With the fallback, an assumption, ``h`` is the only measurement of the noise and
    its own uncertainty counts: an RMS of ``N`` held-out values has ``N h^2 / sigma^2 ~ chi2(N)``, so
    ``h`` stands for the noise up to its one-sided 95 % upper confidence limit
    ``h sqrt(N / chi2_0.05(N))`` (1.92 h for N = 6, 1.36 h for N = 20).  Blind draw 736 #14 (no
    effect, 3 poses x 2 modes, fallback 0.5 %): a best single's 0.144 % on 6 values set the scatter
    and a 0.384 % gap became a link stiffness; its upper limit, 0.275 %, leaves it ``none``.

    Examples
    --------
    >>> best = [{"heldout_rms_rel_error": 0.00144, "_held_err": np.full(6, 0.00144)}]
    >>> round(_none_scatter(Scatter(0.005, FALLBACK_SOURCE, ""), best), 5)
    0.00276
    >>> _none_scatter(Scatter(0.005, "repeated configurations", ""), best)
    0.00144
    """
    held = [(e["heldout_rms_rel_error"], int(np.isfinite(e["_held_err"]).sum())) for e in ranked]
    if noise.source == FALLBACK_SOURCE:
        return min([noise.value] + [h * math.sqrt(n / chi2.ppf(0.05, n)) for h, n in held if n])
    return min([noise.value] + [h for h, _ in held])


def _none_level(none_sigma: float, theory: float) -> float:
    """The largest baseline RMS gap that needs no effect: ``NONE_FACTOR`` times the scatter
    ``none_sigma`` (``_none_scatter``) on top of the error ``theory`` the model's beam theory is known
    to make (``_beam_theory_form``), ``hypot(NONE_FACTOR * none_sigma, theory)``.  The noise gets the
    two-sigma allowance; the beam theory's error is a deterministic level, counted once.  Without it
    an arm whose Euler-Bernoulli error (0.54 % RMS, blind draw 316 #14, axial-sensor rig) is twice the
    scatter (0.25 %) was given a link mass for a gap of 0.68 % it does not have; with it, no weak
    effect of the used blind draws (gaps of 1-3 % beyond the model form) is declared ``none``.

    Examples
    --------
    >>> round(_none_level(0.003, 0.0), 6), round(_none_level(0.003, 0.008), 6)
    (0.006, 0.01)
    """
    return math.hypot(NONE_FACTOR * none_sigma, theory)


def _scoring_scatter(noise, ranked: Sequence[dict]) -> tuple[float, float, float | None]:
    """The scatter that ranks candidates, its model-form floor and the least scatter used in its place:
    ``sqrt(sigma^2 + floor^2)``, raised to ``MIN_SCATTER`` (then the third value, else None).

    ``sigma`` is the measurement's own scatter (repeats or ``freq_std_hz``), else the fallback: the
    lowest held-out error of many candidates fitted to a few residuals underestimates the noise (it
    is the minimum of many), so it never stands for the noise alone.  ``floor`` is the model-form
    error the best candidate still leaves on configurations it did not see,
    ``sqrt(max(h^2 - sigma^2, 0))`` with ``h`` the lowest held-out frequency RMS of the
    cross-validated candidates.  So the penalty of an extra parameter is measured against what no
    candidate can remove, however small the repeat scatter: the same data give the same ranking
    whether a pose's runs come as one row or as repeats."""
    sigma = noise.value
    if not ranked:
        return sigma, 0.0, None
    h = min(e["heldout_rms_rel_error"] for e in ranked)
    floor = math.sqrt(max(h * h - sigma * sigma, 0.0))
    combined = math.hypot(sigma, floor)
    return max(combined, MIN_SCATTER), floor, (MIN_SCATTER if combined < MIN_SCATTER else None)


def _cross_validate_promising(ctx: _Context, entries: Sequence[dict], scatter: float) -> None:
    """Cross-validate, best in-sample score first, every entry that could still beat the best held-out
    score so far (``_lower`` below it), and at least ``MIN_CROSS_VALIDATED`` in all; then the
    ``MAX_ALTERNATIVES`` entries with the lowest in-sample error (frequency-equivalent, ``_fit_eq``, a
    lower bound of the held-out one) within the noise margin (``_noise``) of the lowest held-out
    error, among those not nested in the candidate that has it (``_nested``).

    Those could be alternatives equal within noise (``_verdict``), but the score's complexity penalty
    can keep them from being cross-validated: blind draw 947 #7, a base joint mass with a sensor mass
    (3 parameters), held out as well as a link-1 mass with the sensor mass (2 parameters, 0.440 %
    against 0.446 % frequency-equivalent, noise margin 0.16 %), was never cross-validated and the
    verdict was not flagged (947 #19, 948 #24, 950 #7 and #19 likewise: each hidden pair is now an
    alternative).  Candidates nested in that one are judged by the nested margin (one component more
    or less) and left to the score."""
    for e in entries:
        _rescore(ctx, e, scatter)            # the shape noise floor may have dropped since
    done = [e for e in entries if "score" in e]
    for e in sorted((e for e in entries if "score" not in e), key=lambda e: e["_lower"]):
        if len(done) >= MIN_CROSS_VALIDATED and e["_lower"] >= min(d["score"] for d in done):
            break
        _cross_validate(ctx, e, scatter)
        done.append(e)
    if not done:
        return
    lead = min(done, key=lambda d: d["_heldout_eq"])
    near = sorted((e for e in entries if not _nested(lead, e)
                   and e["_fit_eq"] - lead["_heldout_eq"] <= _noise(lead, scatter, ctx.pose_share)),
                  key=lambda e: e["_fit_eq"])[:MAX_ALTERNATIVES]
    for e in near:
        if "score" not in e:
            _cross_validate(ctx, e, scatter)


def _combo_starts(cand: Candidate, parts: Sequence[tuple[Candidate, np.ndarray]]) -> np.ndarray:
    """Per-fold start points [F, G, J] of a combination (theta in ``cand.params`` order): all parts at
    that fold's own optima (``parts``' theta [F, J_part], fitted without the fold's held-out data), and
    each part over its start grid with the others at their fold optima."""
    F = parts[0][1].shape[0]
    base = np.zeros((F, cand.n_params))
    where = []
    for c, theta in parts:
        idx = [cand.params.index(p) for p in c.params]
        base[:, idx] = theta
        where.append((idx, np.array(list(itertools.product(*[p.grid for p in c.params])))))
    starts = [base[:, None]]
    for idx, grid in where:
        block = np.repeat(base[:, None], len(grid), axis=1)
        block[:, :, idx] = grid[None]
        starts.append(block)
    return np.concatenate(starts, axis=1)


def _partners(ctx: _Context, lead: dict, others: Sequence[dict], count: int = PARTNERS) -> list[dict]:
    """The ``count`` singles of ``others`` whose parameters best explain what ``lead`` (a fitted single)
    leaves: forward stepwise selection by the score (Lagrange-multiplier) test, Rao 1948.

    Each candidate's columns are the derivatives of the relative frequencies with respect to its
    parameters at ``lead``'s fit (every handle at its nominal value except ``lead``'s), from one solve of
    the model with every handle; its statistic is the fraction R^2 of ``lead``'s in-sample residual that
    a linear least-squares fit by those columns removes.  A single that is poor on its own (its fit
    alone runs to a bound) but completes ``lead`` is found this way although it misses the pair pool."""
    others = [e for e in others if combine(lead["_cand"], e["_cand"]) is not None]
    if not others:
        return []
    fam = ctx.family([h.name for h in ctx.handles])
    cand = lead["_cand"]
    h_lead = evaluate(lead["_fam"], design(cand, ctx.target), lead["_theta0"][None], ctx.target)[3][0]
    h = np.repeat(fam.nominal[None, None], len(ctx.meas.configs), axis=1)
    h[0][:, [ctx.index[n] for n in cand.handles]] = h_lead
    f, dlam, _, _ = paired_modes(fam, h, ctx.target)
    dfdh = dlam[0] / (8 * math.pi**2 * f[0][..., None] * ctx.meas.freq_hz[..., None])   # [C, n, H]
    resid = lead["_fit_err"]
    total = float(resid @ resid)
    stats = []
    for e in others:
        c = e["_cand"]
        cols = np.einsum("cnh,chj->cnj", dfdh[..., [ctx.index[n] for n in c.handles]],
                         design(c, ctx.target)).reshape(-1, c.n_params)
        norm = np.linalg.norm(cols, axis=0)
        if total == 0 or not np.any(norm > 0):
            stats.append(0.0)
            continue
        coef, *_ = np.linalg.lstsq(cols[:, norm > 0] / norm[norm > 0], resid, rcond=None)
        fit = cols[:, norm > 0] / norm[norm > 0] @ coef
        stats.append(float(fit @ fit) / total)
    return [others[i] for i in np.argsort(stats)[::-1][:count]]


def _lead_pairs(ctx: _Context, pool: Sequence[dict], singles: Sequence[dict]) -> list[tuple[dict, dict]]:
    """The pairs beyond the pool's: the ``LEADS`` best-scored singles of ``pool``, and the best one of
    each of its ``LEADS`` best effects, each with every single of ``singles`` outside the pool that
    combines with it; when a fold that
    holds one pose out trains on fewer than ``LEAD_TRAIN`` frequencies ((distinct poses - 1) x modes),
    the best single with its ``LEAD_PARTNERS`` score-test partners (``_partners``).

    A hidden pair's second part often fits poorly alone (its in-sample score keeps it out of the pool)
    and is not what the score test (``_partners``) picks either: that test sees the lead's frequency
    residual only.  On the used blind draws (106-110, 211-215, 316-320, 421-425) 19 hidden pairs on
    the axial-sensor rig were missed with the best single's five score-test partners; in the four
    re-diagnosed with the pool kept the second part ranked 9th-18th of 18 singles in-sample and
    5th-14th among the partners, and in three of them the truth's first part was the second best
    single.  With every single paired with each of the best three, 10 of the 19 are right.  That costs
    ~30 screening fits (one fit on all configurations, no cross-validation) where the five partners
    cost 5: +12 % CPU on the default suite's blind cases.  With three poses every fold fits on two,
    and the ~30 more pairs add look-alikes the held-out residuals cannot tell apart: on the sparse
    advice arms (3 poses x 2 modes: four training frequencies per fold for a pair's two to four
    parameters) verdicts turned ambiguous and the advised pose resolved none of them, so such data
    keep the five partners; three poses with three or four modes (six or eight training frequencies,
    as four poses of two modes have) are enumerated (blind draws 528 #29, 530 #7, #19, #24: the true
    second part was the lead's 6th-17th score-test partner).  One effect at several points (the
    grounded spring at four points of a link) can fill all three best places, and the leads then add
    the best of the next effects: blind draws 526 #7 and 527 #24, whose true pairs' pooled parts were
    the 8th and 5th best single (while in draw 7 of the axial rig the true spring is the second best
    point of the same spring, so the best three stay leads)."""
    ranked = sorted(pool, key=lambda e: e["score"])
    best_of: dict[str, dict] = {}
    for e in ranked:
        best_of.setdefault(e["effect"], e)
    leads = ranked[:LEADS] + [e for e in list(best_of.values())[:LEADS] if e not in ranked[:LEADS]]
    rest = [e for e in singles if e not in pool and len(e["_cand"].effects) == 1]
    if _few_poses(ctx):
        return [(leads[0], b) for b in _partners(ctx, leads[0], rest, LEAD_PARTNERS)] if leads else []
    return [(a, b) for a in leads for b in rest if combine(a["_cand"], b["_cand"]) is not None]


def _few_poses(ctx: _Context) -> bool:
    """Whether a fold that holds one pose out trains on fewer than ``LEAD_TRAIN`` frequencies
    ((distinct poses - 1) x modes): too few to tell many look-alike pairs apart (``_lead_pairs``)."""
    poses = len({tuple(sorted(p.items())) for p in ctx.meas.poses})
    return (poses - 1) * ctx.meas.freq_hz.shape[1] < LEAD_TRAIN


def _triples(ctx: _Context, pairs: Sequence[dict], singles: Sequence[dict], scatter: float) -> list[dict]:
    """Each of the best pairs extended by its ``PARTNERS`` score-test partners among the singles
    (``_partners``; only tried when no pair explains)."""
    out, seen = [], set()
    for pair in pairs:
        for single in _partners(ctx, pair, singles):
            cand = combine(pair["_cand"], single["_cand"])
            if cand is None or (cand.effect, cand.location, cand.params) in seen:
                continue
            seen.add((cand.effect, cand.location, cand.params))
            out.append(_screen(ctx, cand, scatter, (pair, single)))
    return out


def _heldout_prediction(freq: np.ndarray, train: np.ndarray) -> np.ndarray:
    """Each configuration's frequencies predicted by the (last) fold that held it out [C, n]
    (``freq`` [F, C, n] and ``train`` [F, C] of the cross-validation folds only)."""
    out = np.full(freq.shape[1:], np.nan)
    for f in range(len(train)):
        out[~train[f]] = freq[f][~train[f]]
    return out


def _refinement_guard(ranking: list[dict]) -> None:
    """Rank an effect that refines another (registry ``refines``, e.g. ``joint_stiffness_pose`` of
    ``joint_stiffness``) below that one at the same location unless better held out."""
    plain = {(e["effect"], e["location"]): e for e in ranking}
    for e in ranking:
        refines = REGISTRY[e["effect"]].refines if e["effect"] in REGISTRY else ""
        c = plain.get((refines, e["location"]))
        if c and e["_heldout_eq"] >= c["_heldout_eq"]:
            e["score"] = max(e["score"], c["score"] * 1.001)


def _where(ctx: _Context, base_err: np.ndarray, base_summary: dict, scatter: float, base_shapes) -> dict:
    meas = ctx.meas
    modes = carriers(base_summary["per_mode"], scatter)
    configs = carriers(base_summary["per_config"], scatter)
    weight = np.zeros_like(base_err)
    mi = [int(m) - 1 for m in modes]
    ci = [meas.configs.index(c) for c in configs]
    weight[np.ix_(ci, mi)] = 1.0
    if not weight.any():
        weight[:] = 1.0
    fam = ctx.family([h.name for h in ctx.handles])
    f, dl, _, _ = paired_modes(fam, np.array([[fam.nominal] * len(meas.configs)]), ctx.target)
    sens = dl[0] / (8 * math.pi**2 * f[0][..., None] * meas.freq_hz[..., None])
    groups: dict[str, list[int]] = {}
    for i, hd in enumerate(ctx.handles):
        groups.setdefault(_effect_region(ctx.rig, hd.effect, hd.location), []).append(i)
    scores = region_scores(base_err, sens, groups, weight)
    region = max(scores, key=scores.get) if scores else ""
    out = {"modes": [int(m) for m in modes], "configs": configs, "region": region,
           "region_scores": dict(sorted(scores.items(), key=lambda kv: -kv[1]))}
    full = [] if meas.shapes is None or base_shapes is None else \
        [c for c in range(len(meas.configs)) if not np.isnan(meas.shapes[c]).any()]   # complete shapes
    if full:
        macs = np.array([mac_pairs(meas.shapes[c], base_shapes[c]) for c in full])
        out["mac_per_mode"] = {str(m + 1): float(np.mean(macs[:, m])) for m in range(macs.shape[1])}
        values = comac(meas.shapes[full], base_shapes[full])
        out["comac"] = {s: float(v) for s, v in zip(meas.sensors, values, strict=True)}
    return out


def diagnose(rig: Rig, measured: ModalTable, effects: str | Sequence[str] = "all",
             holdout: str | Sequence[str] = "auto", scatter: float | None = None,
             progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Diagnose the gap between ``rig`` (nominal) and ``measured`` modes; returns the diagnosis
    (compare/result.py; ``.to_json()`` is diagnosis.json).

    ``effects``: ``"all"`` or effect names; ``holdout``: ``"auto"`` or configurations to hold out;
    ``scatter``: the fallback relative measurement scatter of the frequencies (0.005 = 0.5 %; seed 003's
    Table 4 repeatability was 0.3-0.85 %), used only when the data carry no estimate of their own
    (repeated configurations or a ``freq_std_hz`` column, compare/gap.py ``estimate_scatter``); default
    ``DEFAULT_SCATTER``.  ``progress`` is called with a line at each stage of the work (the fits of
    single effects, of pairs, the cross-validation, the verdict), and the fits are shown as a transient
    bar on a terminal.  ``warnings`` of the result: one line per reason why the measured shapes of some
    configurations pair no modes by MAC (compare.tables.shape_warnings), and one when a section of the
    rig sets shear (``SHEAR_UNCALIBRATED``); None when there is none.
    Raises CompareError (one line) on inputs that do not fit the rig.
    """
    with threadpool_limits(limits=1, user_api="blas"):  # thousands of tiny eigenproblems
        return _diagnose(rig, measured, effects, holdout, scatter, progress)


def _fitted(items: Sequence, fit: Callable[[object], dict], what: tuple[str, str],
            progress: Callable[[str], None] | None) -> list[dict]:
    """``fit(item)`` of every item in order, the stage said on ``progress`` first (``fitting 40 single
    effects``; ``what``: the noun, singular and plural) and each fit counted on a terminal's bar."""
    if progress is not None and items:
        progress(f"diagnose: fitting {counted(len(items), *what)}")
    with progress_bar(len(items), f"fitting {what[1]}", quiet=progress is None) as advance:
        done = []
        for item in items:   # a loop over candidates
            done.append(fit(item))
            advance()
    return done


def _diagnose(rig: Rig, measured: ModalTable, effects: str | Sequence[str], holdout: str | Sequence[str],
              fallback: float | None, progress: Callable[[str], None] | None = None) -> Diagnosis:
    fallback = DEFAULT_SCATTER if fallback is None else fallback
    if not MIN_SCATTER_REL <= fallback < 1:
        raise CompareError(f"--scatter must be a fraction in [{MIN_SCATTER_REL:g}, 1) (got {fallback:g})")
    names = parse_effects(effects) if isinstance(effects, str) else parse_effects(",".join(effects))
    meas = prepare(rig, measured)
    noise = estimate_scatter(measured, meas, fallback)
    sigma = scatter = noise.value       # the measurement's scatter; ``scatter`` ranks (+ model-form floor)
    floor, least = 0.0, None
    train, scheme = folds_for(meas.configs, holdout, meas.poses)
    if progress is not None:   # the inputs fit the rig: a bad one is the only line said
        progress(f"diagnose: {measured.source} against the model of {rig.source}")
    ctx = _Context(rig, meas, train)

    base_fam = ctx.family([])
    base_f, _, base_mac, _ = evaluate(base_fam, np.zeros((len(meas.configs), 0, 0)), np.zeros((1, 0)),
                                      ctx.target)
    base_f = base_f[0]
    base_err = base_f / meas.freq_hz - 1.0
    baseline = gap_summary(base_err, meas.configs)
    held_mask = ~train[1:].all(axis=0)
    before = rms(base_err[held_mask])
    base_shape = _shape_misfit(None if base_mac is None else base_mac[0][held_mask])
    if base_shape.size:
        ctx.shape_floor = float(np.mean(_shape_misfit(base_mac[0])))
    base_shapes = _paired_shapes(ctx, base_fam) if meas.shapes is not None else None
    where = _where(ctx, base_err, baseline, scatter, base_shapes)

    ranking: list[dict] = []
    n_candidates = None
    small = baseline["rms_rel_error"] <= _none_level(sigma, ctx.beam_form)
    singles = single_candidates(rig, names, {v: [p[v] for p in meas.poses] for v in rig.pose_variables})
    screened = _fitted(singles, lambda c: _screen(ctx, c, scatter), ("single effect", "single effects"),
                       progress)
    none_sigma = sigma
    if small and screened:         # the best singles say what might be there, and how low the noise is
        for e in sorted(screened, key=lambda e: e["_lower"])[:MAX_ALTERNATIVES]:
            _cross_validate(ctx, e, scatter)
        tried = [e for e in screened if "score" in e]
        none_sigma = _none_scatter(noise, tried)
        for e in tried:
            _annotate(ctx, e, scatter)
        nominal = _nominal_entry(ctx)
        _rescore(ctx, nominal, scatter)
        # a gap within the noise needs no effect -- unless a candidate predicts unseen poses better
        # than the nominal model beyond noise and beyond the beam theory's known error (a single that
        # only absorbs that error, blind 316 #14, is no evidence): then the full search and the
        # held-out test decide
        small = baseline["rms_rel_error"] <= _none_level(none_sigma, ctx.beam_form) \
            and not _beating_nominal(ctx, tried, nominal, scatter, ctx.beam_form)
    if small and screened:         # the verdict is ``none``
        ranking = sorted((e for e in screened if "score" in e), key=lambda e: e["score"])
        n_candidates = CandidateCount(fitted=len(screened), cross_validated=len(ranking))
    elif screened:
        fitted_singles = list(screened)
        pool = sorted(screened, key=lambda e: e["_lower"])[:PAIR_POOL]
        for e in pool:
            if "score" not in e:
                _cross_validate(ctx, e, scatter)
        def pair(parts: tuple[dict, dict]) -> dict:
            return _screen(ctx, combine(parts[0]["_cand"], parts[1]["_cand"]), scatter, parts)

        pairs = _fitted([(a, b) for n, a in enumerate(pool) for b in pool[n + 1:]
                         if combine(a["_cand"], b["_cand"]) is not None], pair,
                        ("pair of effects", "pairs of effects"), progress)
        pairs += _fitted(_lead_pairs(ctx, pool, screened), pair,
                         ("pair with a leading single", "pairs with a leading single"), progress)
        screened += pairs
        if progress is not None:
            progress("diagnose: cross-validating the candidates that fit best")
        _cross_validate_promising(ctx, screened, scatter)
        pairs.sort(key=lambda e: e.get("score", math.inf))
        if pairs and pairs[0].get("heldout_rms_rel_error", math.inf) > EXPLAINED_FACTOR * scatter:
            if progress is not None:
                progress("diagnose: fitting triples of effects (no pair explains the gap)")
            screened += _triples(ctx, pairs[:TRIPLE_PAIRS], fitted_singles, scatter)
            _cross_validate_promising(ctx, screened, scatter)
        _cross_validate_promising(ctx, screened, scatter)     # once more at the final shape floor
        scatter, floor, least = _scoring_scatter(noise, [e for e in screened if "score" in e])
        ctx.model_form = _model_form(noise, [e for e in screened if "score" in e],
                                      ctx.beam_form)
        ctx.none_form = _model_form(noise, [e for e in screened if "score" in e], ctx.beam_form,
                                    split=True)
        _cross_validate_promising(ctx, screened, scatter)     # rescored and extended at that scatter
        ranking = [e for e in screened if "score" in e]
        _refinement_guard(ranking)
        ranking.sort(key=lambda e: e["score"])
        n_candidates = CandidateCount(fitted=len(screened), cross_validated=len(ranking))
    if progress is not None:
        progress("diagnose: choosing the verdict")
    for e in ranking:
        _annotate(ctx, e, scatter)
    _order(ctx, ranking, scatter)
    best, notes = _chosen(ctx, ranking, screened if ranking else [], scatter)
    if best is not None and len(best["_cand"].effects) > 1:
        shape_floor, n_screened = ctx.shape_floor, len(screened)
        moved = []
        if best["heldout_rms_rel_error"] > EXPLAINED_FACTOR * sigma:
            leads = [best, *(e for e in ranking[:LEADS] if e is not best)]
            moved = [m for e in leads for m in _relocated(ctx, e, screened, scatter)]
        moved += _swapped(ctx, best, screened, scatter, pool)
        n_candidates = CandidateCount(fitted=n_candidates.fitted + len(screened) - n_screened,
                                      cross_validated=n_candidates.cross_validated + len(moved))
        lowered = _rescored(ctx, screened, ranking + moved, shape_floor, scatter)
        if lowered or any(e["score"] < best["score"] for e in moved):
            if any(e["score"] < best["score"] for e in moved):
                ranking += [e for e in moved if e not in ranking]
            ranking.sort(key=lambda e: e["score"])
            _order(ctx, ranking, scatter)
            best, notes = _chosen(ctx, ranking, screened, scatter)
    nominal = _nominal_entry(ctx)
    _rescore(ctx, nominal, scatter)
    # an ambiguous choice of an effect (not ``none``: that test stays the nominal model's against the
    # candidates as ranked) is made again with the added masses as point masses
    if not small and best is not None and _alternatives(ctx, best, ranking, scatter) \
            and any(_beats_nominal(ctx, e, nominal, scatter, sigma) for e in (best, _lead(ranking))):
        shape_floor, n_screened = ctx.shape_floor, len(screened)
        points = _point_masses(ctx, ranking, screened, scatter)
        if points:
            n_candidates = CandidateCount(fitted=n_candidates.fitted + len(screened) - n_screened,
                                          cross_validated=n_candidates.cross_validated + len(points))
            ranking += points
            _rescored(ctx, screened, ranking, shape_floor, scatter)
            ranking.sort(key=lambda e: e["score"])
            _order(ctx, ranking, scatter)
            best, notes = _chosen(ctx, ranking, screened, scatter)
    if best is not None and best not in ranking:           # a pruned candidate validated by _choose
        ranking.append(best)
        _order(ctx, ranking, scatter)
    _rescore(ctx, nominal, scatter)      # the shape noise floor may have dropped since
    verdict = _verdict(ctx, best, ranking, baseline, before, nominal, scatter, sigma, none_sigma, small,
                       notes, singles)
    if verdict["effect"] != "none":
        _confirm_region(where, rig, verdict["effect"], verdict["location"])
    else:                  # the candidates of a ``none`` verdict are alternatives, not its model
        where = {**where, "modes": [], "configs": [], "region": ""}
        best = None
    return Diagnosis(
        baseline=Baseline(**baseline), where=Where(**where),
        ranking=tuple(CandidateScore(**_public(e)) for e in ranking[:RANKING_LENGTH]),
        verdict=_typed_verdict(verdict, _per_config(rig, meas, best)), n_candidates=n_candidates,
        scatter=scatter, scatter_source=ScatterSource(source=noise.source, detail=noise.detail,
                                                      measurement=sigma, model_form_floor=floor, least=least),
        holdout=Holdout(scheme=scheme, n_folds=int(len(train) - 1)), configs=meas.configs,
        predictions=_predictions(meas, base_f, best),
        warnings=tuple(shape_warnings(rig.source, meas.shapes_unused, [measured]) + _shear_warnings(rig))
        or None)


def _shear_warnings(rig: Rig) -> list[str]:
    """``SHEAR_UNCALIBRATED`` after the rig's file when a section of it (a link's, a segment's or a
    member's) sets shear deformation: the ``none`` gate and ``_beam_theory_form`` were calibrated on
    Euler-Bernoulli rigs only."""
    sections = [s for lk in rig.links for s in (lk.section, *(seg.section for seg in lk.segments))]
    sections += [mb.section for mb in rig.members]
    return [f"{rig.source}: {SHEAR_UNCALIBRATED}"] if any(s.shear is not None for s in sections) else []


def heldout_errors(rig: Rig, measured: ModalTable, names: Sequence[tuple[str, str]], scatter: float,
                   shape_noise: float | None = None, holdout: str | Sequence[str] = "auto"
                   ) -> tuple[list[float], float]:
    """The held-out errors of named candidates (``(effect, location)``, names joined by ``+`` as in a
    verdict), each fitted and cross-validated as the diagnosis does (its folds, its starts), and the
    noise margin within which another candidate's held-out error equals the first one's (``_noise``)
    at ``scatter``.

    Returns ``([held-out frequency-equivalent RMS of each], margin)`` (fractions).  With measured shapes
    the errors count them as the ranking does (``_equivalent``), all against one shape noise per degree
    of freedom: ``shape_noise`` (the variance of ``1 - MAC`` per degree of freedom) when given, else the
    smallest in-sample misfit of these candidates.  The blind check uses it on noise-free data to tell a
    case an ideal fit can decide from one it cannot.  Raises CompareError for a name the rig has no
    candidate for.

    Examples
    --------
    >>> from flexmodal.fixtures.blind import make_case
    >>> import numpy as np
    >>> case = make_case(np.random.default_rng(1), "single", "two_link")
    >>> (h,), margin = heldout_errors(case.rig, case.table, [(case.effect, case.location)], case.scatter)
    >>> 0 <= h < 0.05 and margin > 0
    True
    """
    with threadpool_limits(limits=1, user_api="blas"):
        meas = prepare(rig, measured)
        train, _ = folds_for(meas.configs, holdout, meas.poses)
        ctx = _Context(rig, meas, train)
        entries = []
        for effect, location in names:
            if effect == "none":
                entries.append(_nominal_entry(ctx))
                continue
            cand = _rebuild(rig, meas, effect, location)
            if cand is None:
                raise CompareError(f"{effect} at {location}: no such candidate for rig {rig.name!r}")
            entries.append(_screen(ctx, cand, scatter))
        if shape_noise is not None and ctx.shape_dof > 0:
            ctx.shape_floor = shape_noise * ctx.shape_dof
        for entry in entries:
            if "_cand" in entry:
                _cross_validate(ctx, entry, scatter)
            _rescore(ctx, entry, scatter)
        return [e["_heldout_eq"] for e in entries], _noise(entries[0], scatter, ctx.pose_share)


def _nominal_entry(ctx: _Context) -> dict:
    """The nominal model (no effect, nothing fitted) as a scored entry: its errors on the held-out
    configurations are its held-out errors."""
    f, _, mac, _ = evaluate(ctx.family([]), np.zeros((len(ctx.meas.configs), 0, 0)), np.zeros((1, 0)),
                            ctx.target)
    err = f[0] / ctx.meas.freq_hz - 1.0
    held = _held_order(ctx.train)
    mac = None if mac is None else mac[0]
    return {"n_params": 0, "_fit_err": err.ravel(), "_fit_shape": _shape_misfit(mac),
            "_held_err": err[held].ravel(), "_held_shape": _shape_misfit(None if mac is None else mac[held])}


def _held_order(train: np.ndarray) -> np.ndarray:
    """The configurations in the order their held-out residuals are concatenated (``_cross_validate``:
    fold by fold), so that the nominal model's held-out residuals pair with a candidate's one to one
    (``_paired_noise``); with 5 interleaved folds over poses this is not the configurations' order.

    Examples
    --------
    >>> _held_order(np.array([[1, 1, 1, 1], [0, 1, 0, 1], [1, 0, 1, 0]], bool)).tolist()
    [0, 2, 1, 3]
    """
    return np.concatenate([np.flatnonzero(~t) for t in train[1:]])


def prediction_band(rig: Rig, measured: ModalTable, result: Diagnosis, poses: Sequence[dict[str, float]],
                    pose_var: str | None = None):
    """The verdict's model at ``poses`` (full pose dicts) with 95 % prediction intervals, as a
    compare.modal_map.PredictionBand over ``pose_var`` (default: the rig's only pose variable).

    The verdict's candidate is rebuilt from ``result`` (its effect, location and fitted parameters,
    unidentified ones included, from its entry of ``result.ranking``: ``Diagnosis.verdict_score``), its
    linearised parameter covariance ``scatter^2 (J^T J)^+`` computed on ``measured`` at
    ``result.scatter``, and at each new pose the
    interval is ``f (1 +- 1.96 sqrt(g^T C g + scatter^2))`` with ``g`` the relative sensitivities there
    (the interval of a new observation, Seber & Wild 1989 §5.1).  Modes are by ascending order, as many
    as measured.  ``result`` with a ``none`` verdict gives the nominal model with ``+- 1.96 scatter``.
    """
    from flexmodal.compare.modal_map import PredictionBand

    variables = rig.pose_variables
    pose_var = pose_var or (variables[0] if len(variables) == 1 else None)
    if pose_var not in variables:
        raise CompareError(f"prediction band: name the pose variable to map over (rig has "
                           f"{', '.join(variables) or 'none'})")
    meas = prepare(rig, measured)
    v = result.verdict
    entry = result.verdict_score()
    cand = _rebuild(rig, meas, v.effect, v.location) if entry is not None else None
    if cand is not None and entry.n_params < cand.n_params:      # a point mass (``_point_masses``)
        cand = _point_mass(cand)
    scatter = result.scatter or DEFAULT_SCATTER
    ctx = _Context(rig, meas, np.ones((1, len(meas.configs)), bool))
    nctx = ctx.at(tuple(dict(p) for p in poses), meas.freq_hz.shape[1])
    if cand is None:
        f = evaluate(nctx.family([]), np.zeros((len(poses), 0, 0)), np.zeros((1, 0)), nctx.target)[0][0]
        var = np.full(f.shape, scatter**2)
    else:
        theta = np.array([math.log(x) if p.power == 0 else x
                          for p, x in zip(cand.params, _param_values(cand, entry.params), strict=True)])
        D = design(cand, ctx.target)
        _, df, _, _ = evaluate(ctx.family(cand.handles), D, theta[None], ctx.target)
        cov = linear_cov(df[0] / meas.freq_hz[..., None], scatter)
        nfam = nctx.family(cand.handles)
        f, dfn, _, _ = evaluate(nfam, design(cand, nctx.target), theta[None], nctx.target)
        f = f[0]
        g = dfn[0] / f[..., None]
        var = np.einsum("cnj,jk,cnk->cn", g, cov, g) + scatter**2
    half = Z95 * np.sqrt(var)
    x = np.array([p[pose_var] for p in poses], float)
    label = "nominal model" if cand is None else f"{v.effect} at {v.location}"
    return PredictionBand(x, f, f * (1 - half), f * (1 + half), label)


def _rebuild(rig: Rig, meas: Measured, effect: str, location: str) -> Candidate | None:
    """The candidate named ``effect`` at ``location`` (as in a diagnosis: names joined by ``+``)."""
    singles = single_candidates(rig, tuple(dict.fromkeys(effect.split("+"))),
                                {v: [p[v] for p in meas.poses] for v in rig.pose_variables})
    for n in range(1, 4):
        for parts in itertools.combinations(singles, n):
            cand = parts[0] if n == 1 else combine(*parts)
            if cand is not None and (cand.effect, cand.location) == (effect, location):
                return cand
    return None


def _param_values(cand: Candidate, params: Mapping) -> list[float]:
    """The SI values of ``cand.params`` from a reported parameter mapping (names as ``_params`` makes)."""
    names = list(_params(cand, np.zeros(cand.n_params)))
    return [float(params[n]) for n in names]


def _per_config(rig: Rig, meas: Measured, best: dict | None) -> dict[str, dict[str, float]]:
    """Pose-dependent parameters of the candidate ``best`` per configuration, {name: {config: value}}
    (its registry entry's ``per_config``; empty when it has none)."""
    entry = REGISTRY.get(best["effect"]) if best is not None else None
    if entry is None or entry.per_config is None or not meas.poses:
        return {}
    values = [entry.per_config(rig, best["location"], best["params"], pose) for pose in meas.poses]
    return {name: {c: v[name] for c, v in zip(meas.configs, values, strict=True)} for name in values[0]}


def _typed_verdict(verdict: dict, per_config: dict[str, dict[str, float]]) -> Verdict:
    """The verdict record of ``_verdict``'s working dict, with the pose-dependent parameters
    ``per_config`` ({name: {config: value}}) of the verdict's candidate."""
    records = {"remaining": Remaining, "alternatives": Alternative, "next_measurements": NextMeasurement}
    fields = {k: tuple(records[k](**x) for x in v) if k in records else v for k, v in verdict.items()}
    return Verdict(**fields, per_config=per_config)


def _public(entry: dict) -> dict:
    return {k: v for k, v in entry.items() if not k.startswith("_")}


def _annotate(ctx: _Context, entry: dict, scatter: float) -> None:
    """Flag parameters at a bound and parameters the data cannot identify.

    Identifiability: the linearised covariance of the fitted log-parameters, ``scatter^2 (J^T J)^+`` with
    ``J`` the Jacobian of the relative frequency errors over all configurations (Gauss-Newton; Bates &
    Watts 1988 §2.3); a parameter whose standard deviation exceeds ``UNIDENTIFIED_STD`` (a factor
    e^1 = 2.7 for log-parameters, 1/rad for pose-law terms) is unidentified.
    """
    cand, theta = entry["_cand"], entry["_theta0"]
    names = list(_params(cand, theta))
    lo = np.array([p.lower for p in cand.params])
    hi = np.array([p.upper for p in cand.params])
    tol = BOUND_TOL * (hi - lo)
    at_lo, at_hi = theta <= lo + tol, theta >= hi - tol
    _, df, _, _ = evaluate(entry["_fam"], design(cand, ctx.target), theta[None], ctx.target)
    jac = (df[0] / ctx.meas.freq_hz[..., None]).reshape(-1, cand.n_params)
    u, sv, vt = np.linalg.svd(jac, full_matrices=False)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        gain = (vt.T / np.maximum(sv, 1e-300)) @ u.T                   # [J, C*n]: d theta / d residual
        std = scatter * np.sqrt(np.sum(gain**2, axis=1))
        # model form: what the candidate leaves held out may be systematic, the same for a mode at every
        # pose (as an error of the model's form is), and then it does not average out over configurations
        per_mode = gain.reshape(cand.n_params, *ctx.meas.freq_hz.shape).sum(axis=1)   # [J, n]
        systematic = np.sqrt(np.sum(per_mode**2, axis=1))
    # jackknife over the cross-validation folds (each refitted without one pose or group), Efron 1982
    folds = entry.get("_theta_folds")
    if folds is not None and len(folds) >= 3:
        k = len(folds)
        jack = np.sqrt((k - 1) / k * np.sum((folds - folds.mean(axis=0)) ** 2, axis=0))
        std = np.fmax(std, jack)
    held = entry.get("_heldout_freq_hz")
    form = rms((held / ctx.meas.freq_hz - 1.0)[np.isfinite(held)]) if held is not None else 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        std_interval = np.hypot(std, form * systematic)
    dof = max(jac.shape[0] * ctx.pose_share - cand.n_params, 1.0)
    half = float(stdtrit(dof, 0.975)) * std_interval
    lo_i, hi_i = theta - half, theta + half
    entry["_param_sd"] = std
    entry["_param_intervals"] = {
        n: (float(np.exp(min(a, 700.0))), float(np.exp(min(b, 700.0)))) if p.power == 0
        else (float(a), float(b))
        for n, p, a, b in zip(names, cand.params, lo_i, hi_i, strict=True)}
    entry["params_at_bound"] = [n for n, a, b in zip(names, at_lo, at_hi, strict=True) if a or b]
    entry["unidentified_params"] = [n for n, x in zip(names, std, strict=True) if not x <= UNIDENTIFIED_STD]
    # a component whose every parameter sits at its lower bound adds nothing: the candidate is its rest
    entry["_idle"] = [i for i, (_, _, ps) in enumerate(components(cand))
                      if all(at_lo[cand.params.index(p)] for p in ps)]
    # a parameter at its upper bound (or a pose-law term at either) is the fit running out of range
    entry["_out_of_range"] = any(b or (a and p.power)
                                 for p, a, b in zip(cand.params, at_lo, at_hi, strict=True))


def _nested(a: dict, b: dict) -> bool:
    """Whether one of the candidates ``a``, ``b`` contains the other: its components (effect, location)
    a subset of the other's, an effect counted as the one it refines (registry ``refines``, e.g.
    ``joint_stiffness_pose`` as ``joint_stiffness``) at the same location."""
    def parts(e: dict) -> set:
        cand = e["_cand"]
        return {(REGISTRY[x].refines or x if x in REGISTRY else x, loc)
                for x, loc in zip(cand.effects, cand.locations, strict=True)}
    pa, pb = parts(a), parts(b)
    return pa <= pb or pb <= pa


def _order(ctx: _Context, ranking: list[dict], scatter: float) -> None:
    """Sort ``ranking`` in place: the candidates whose held-out error is not worse than the lowest one
    beyond noise first, simplest first (fewest parameters, then score) -- the one-standard-error rule
    of cross-validated model choice (Breiman et al. 1984, §3.4.3) -- then the others by score.  Noise
    is the margin of a paired comparison on the same held-out residuals (``_paired_noise``), for a
    candidate nested in the lowest one or containing it (``_nested``) the nested margin, which also
    allows for the model-form error a component more can absorb (``_nested_margin``).  Between
    different effects that allowance does not apply: it would let a one-parameter effect of the wrong
    kind (blind draw 529 #23: base stiffness, held out 1.20 % frequency-equivalent) stand for a
    two-parameter one that predicts held-out poses better beyond noise (joint mass, 0.88 %, paired
    margin 0.20 %), only because all of the best held-out error might be model form.

    A candidate held out no worse than one of those (usable: in range, no idle component) with as many
    parameters joins them, so that within one complexity the order is that of the held-out error: the
    margins differ by kind, so without that a single of another effect held out better than the lowest
    one's own nested part, but beyond the paired margin of the lowest one, ranked below that part
    (blind 1367 #12: a base stiffness, the truth, 0.561 % against a grounded spring's 0.569 %, one
    parameter each; the spring, nested in the lowest pair at 0.498 %, was within its nested margin
    0.279 %, the stiffness 0.063 % worse than the pair against a paired margin of 0.061 %: the spring
    was the verdict).  Not with fewer parameters: a simpler candidate must be within
    the margin of the lowest one itself (blind 1368 #4: a link mass at 0.661 %, 0.077 % worse than the
    lowest, the truth's joint mass, against a paired margin of 0.064 %, is no worse than a link-mass pair
    at 0.662 % admitted by its own wider margin, 0.086 %, and would otherwise have been the verdict)."""
    if not ranking:
        return
    lead = _lead(ranking)

    def within(e: dict) -> bool:
        margin = _nested_margin(ctx, lead, e, scatter) if _nested(lead, e) else \
            _paired_noise(ctx, lead, e, scatter)
        return e["_heldout_eq"] - lead["_heldout_eq"] <= margin

    near = [e for e in ranking if within(e)]
    reach = [e for e in near if not e.get("_out_of_range") and not e.get("_idle")]
    inside = {id(e) for e in near}

    def key(e: dict) -> tuple:
        dominates = any(e["n_params"] == n["n_params"] and e["_heldout_eq"] <= n["_heldout_eq"]
                        for n in reach)
        return (0, e["n_params"], e["score"]) if id(e) in inside or dominates else (1, 0, e["score"])

    ranking.sort(key=key)


def _lead(ranking: Sequence[dict]) -> dict:
    """The candidate of ``ranking`` held out lowest (frequency-equivalent), among the usable ones (in
    range, no idle component) when there are any: the one the one-standard-error rule (``_order``)
    measures the others against."""
    usable = [e for e in ranking if not e.get("_out_of_range") and not e.get("_idle")]
    return min(usable or ranking, key=lambda e: e["_heldout_eq"])


def _noise(best: dict, scatter: float, pose_share: float = 1.0) -> float:
    """Margin by which another candidate's held-out (frequency-equivalent, ``_equivalent``) RMS may
    exceed ``best``'s and still be equal within noise: twice the standard error of the difference of two
    RMS estimates over the same ``N`` held-out degrees of freedom, each ~ ``sigma / sqrt(2N)`` (chi
    distribution) with ``sigma`` the larger of the best held-out RMS and the scatter.  Repeats of a pose
    share its model-form error: ``N`` counts distinct poses (``pose_share`` = distinct poses /
    configurations)."""
    n = max(best["_n_eq"] * pose_share, 1.0)
    return 2 * math.sqrt(2) * max(best["_heldout_eq"], scatter) / math.sqrt(2 * n)


def _model_form(noise, ranked: Sequence[dict], theory: float = 0.0, split: bool = False) -> float:
    """The model-form level against which one component more or less is judged (``_nested_margin``).

    With a measured scatter (repeats or ``freq_std_hz``) it is the model-form floor, the lowest held-out
    frequency RMS beyond the measurement (``_scoring_scatter``).  With only the fallback the data do not
    say how much of the lowest held-out error is noise and how much is model form, so all of it may be
    model form: the lowest held-out frequency RMS itself.  Never below ``theory``, the error the beam
    theory of the model is known to make (``_beam_theory_form``): the lowest held-out error is that of
    the candidate that absorbed most of the model form -- often one with a component too many -- so
    it understates the level it is meant to measure.

    ``split`` takes the fallback as the measurement's scatter all the same (the level of the ``none``
    test, ``_none_margin``): there "all of it model form" makes every candidate gain at least
    ``(sqrt 2 - 1) h`` over the nominal model to count, and a weak effect whose held-out error is at
    the fallback's level stays ``none`` however clearly the paired test prefers it (blind 1892 #16, a
    1.8 g sensor mass on 3 configurations x 3 modes with shapes: held out 0.226 % better than the
    nominal model, paired margin 0.166 %, the model-form part 0.226 %; ``split`` makes it right,
    ``tests/test_diagnosis_none_form.py``)."""
    if not ranked:
        return theory
    h = min(e["heldout_rms_rel_error"] for e in ranked)
    if noise.source.startswith("--scatter") and not split:
        return max(h, theory)
    return max(math.sqrt(max(h * h - noise.value**2, 0.0)), theory)


def _beam_theory_form(rig: Rig, freq_hz: np.ndarray, nu: float = POISSON) -> float:
    """RMS over the measured frequencies ``freq_hz`` [C, n] Hz of the relative error an Euler-Bernoulli
    frame model (models/frame.py) makes by neglecting shear deformation and rotary inertia of the
    section: ``(k r)^2 (1 + E / (kappa G)) / 2`` for a bending wave of wavenumber ``k = (omega^2 mu /
    EI)^(1/4)`` on a section of radius of gyration ``r = sqrt(EI / EA)`` (Timoshenko's first-order
    correction, Han, Benaroya & Wei 1999, J. Sound Vib. 225(5) eq. 81; Rao, *Vibration of Continuous
    Systems* 2007 §11.8), with ``(k r)^2 = omega sqrt(mu EI) / EA``, ``E / G = 2 (1 + nu)`` and the
    shear coefficient ``kappa`` 0.5 for thin-walled tubes, 5/6 for solid sections (Cowper 1966); the
    links' values averaged by length.  Where a link's section sets shear deformation (rig
    ``shear_coefficient``, ``models.rig.Shear``) the frame models it, so the shear term ``E / (kappa G)``
    counts only on the part of the link without it: the term times the fraction of the link's length
    whose section (a segment's where segments override the link section, ``Link.section_at``, as the
    frame takes it at each element's middle) has no shear.  The other properties, and kappa, are the
    link section's.  A level, not a correction: where a mode's strain energy sits, and so which link's
    section counts, is not known before a fit.  The ``none`` gate built on this level was calibrated on
    Euler-Bernoulli rigs only.

    Examples
    --------
    A solid 10 mm x 10 mm aluminium bar at 100 Hz: ``r^2 = h^2 / 12``, ``(k r)^2 = omega r / c`` with
    ``c = sqrt(E / rho)``:

    >>> from flexmodal.models.rig import parse_rig
    >>> rig = parse_rig({"name": "bar", "material": {"al": {"E_Pa": 70e9, "rho_kg_m3": 2700}},
    ...                  "link": [{"name": "l", "length_m": 1.0, "material": "al",
    ...                            "section": {"shape": "solid_rect", "width_m": 0.01, "height_m": 0.01}}]},
    ...                 "<doc>")
    >>> e = _beam_theory_form(rig, np.array([[100.0]]))
    >>> c, r = math.sqrt(70e9 / 2700), 0.01 / math.sqrt(12)
    >>> bool(abs(e - 0.5 * 2 * math.pi * 100 * r / c * (1 + 2 * 1.3 / (5 / 6))) < 1e-12)
    True

    The same bar with its shear modelled (``shear_coefficient``; the material needs ``nu``) keeps only
    the rotary-inertia term:

    >>> rig = parse_rig({"name": "bar", "material": {"al": {"E_Pa": 70e9, "rho_kg_m3": 2700, "nu": 0.33}},
    ...                  "link": [{"name": "l", "length_m": 1.0, "material": "al",
    ...                            "section": {"shape": "solid_rect", "width_m": 0.01, "height_m": 0.01,
    ...                                        "shear_coefficient": 0.85}}]}, "<doc>")
    >>> e = _beam_theory_form(rig, np.array([[100.0]]))
    >>> bool(abs(e - 0.5 * 2 * math.pi * 100 * r / c) < 1e-12)
    True
    """
    per_rad_s, lengths = [], []
    for link in rig.links:
        sec = link.section
        kappa = 0.5 if "tube" in sec.shape else 5.0 / 6.0
        shear_term = 2.0 * (1.0 + nu) / kappa * _unsheared_share(link)
        per_rad_s.append(0.5 * math.sqrt(sec.mass_per_m_kg * sec.EI_Nm2) / sec.EA_N * (1.0 + shear_term))
        lengths.append(link.length_m)
    if not lengths:
        return 0.0
    freq = np.asarray(freq_hz, float)
    return rms(2 * math.pi * freq[np.isfinite(freq)] * float(np.average(per_rad_s, weights=lengths)))


def _unsheared_share(link: Link) -> float:
    """Share [-] of ``link``'s length whose section sets no shear deformation: its stretches between the
    segment ends, each with the section at its middle (``Link.section_at``: segments override the link
    section); exactly 1 where no section sets shear and 0 where all do.

    Examples
    --------
    >>> from flexmodal.models.rig import parse_rig
    >>> sec = {"shape": "solid_rect", "width_m": 0.01, "height_m": 0.01}
    >>> rig = parse_rig({"name": "bar", "material": {"al": {"E_Pa": 70e9, "rho_kg_m3": 2700, "nu": 0.33}},
    ...                  "link": [{"name": "l", "length_m": 1.0, "material": "al", "section": sec,
    ...                            "segments": [{"from": 0.2, "to": 0.5,
    ...                                          "section": {**sec, "shear_coefficient": 0.85}}]}]}, "<doc>")
    >>> round(_unsheared_share(rig.links[0]), 12)
    0.7
    """
    ends = sorted({0.0, link.length_m} | {min(x, link.length_m) for seg in link.segments
                                          for x in (seg.from_m, seg.to_m)})
    length_m = {True: 0.0, False: 0.0}
    for a, b in itertools.pairwise(ends):
        length_m[link.section_at(0.5 * (a + b)).shear is None] += b - a
    return length_m[True] / (length_m[True] + length_m[False])


def _chi2_terms(ctx: _Context, entry: dict, scatter: float) -> np.ndarray:
    """The terms of ``entry``'s held-out chi-square (``_equivalent``), one per held-out residual:
    ``(e / scatter)^2`` per frequency, ``(1 - MAC) / floor`` per mode shape."""
    terms = [np.square(entry["_held_err"]) / scatter**2]
    if ctx.shape_dof > 0 and entry["_held_shape"].size and math.isfinite(ctx.shape_floor):
        terms.append(entry["_held_shape"] / shape_noise_var(ctx))
    return np.concatenate(terms)


def _paired_noise(ctx: _Context, a: dict, b: dict, scatter: float) -> float:
    """Margin by which the held-out (frequency-equivalent) RMS of ``a`` and ``b`` may differ and still be
    equal within noise, judged on the same held-out residuals: a paired comparison of their
    chi-square terms (``_chi2_terms``), as cross-validated models are compared (Dietterich 1998;
    Diebold & Mariano 1995).  The differences ``d`` of the terms sum to the difference of the two
    chi-squares with standard error ``SE = sqrt(N var(d) / pose_share)`` (repeats of a pose share its
    model-form error); the margin is the two-sided 95 % Student t quantile of ``N pose_share - 1``
    degrees of freedom times that, on the RMS scale (``eq^2 = scatter^2 chi2 / dof``, so
    ``eq_a - eq_b = scatter^2 sum(d) / (dof (eq_a + eq_b))`` exactly): ``t scatter^2 SE / (dof (eq_a +
    eq_b))`` -- the paired t-test of the two candidates' held-out losses.  Unlike two RMS estimates
    taken as independent (``_noise``), it does not count as noise what both candidates leave alike.
    On a few residuals the variance of ``d`` is itself uncertain (one large residual of one candidate
    inflates it), so the margin never exceeds ``_noise`` of the better of the two, the margin without
    pairing."""
    unpaired = _noise(min(a, b, key=lambda e: e["_heldout_eq"]), scatter, ctx.pose_share)
    da, db = _chi2_terms(ctx, a, scatter), _chi2_terms(ctx, b, scatter)
    if da.size != db.size or da.size < 2 or a["_n_eq"] != b["_n_eq"]:
        return unpaired
    d = da - db
    n = d.size * ctx.pose_share
    se = math.sqrt(d.size * float(np.var(d, ddof=1)) / ctx.pose_share)
    t = float(stdtrit(max(n - 1.0, 1.0), 0.975))
    return min(t * scatter**2 * se / (a["_n_eq"] * max(a["_heldout_eq"] + b["_heldout_eq"], 1e-300)),
               unpaired)


def _nested_margin(ctx: _Context, best: dict, other: dict, scatter: float) -> float:
    """How much the held-out (frequency-equivalent) RMS of ``other`` may differ from ``best``'s (e.g.
    ``best`` with one component added or removed) and the data still cannot say which is right: the
    noise margin of a paired comparison (``_paired_noise``), or the change that absorbing a
    model-form error of the level ``ctx.model_form`` can make, ``sqrt(h^2 + m^2) - h`` with ``h``
    ``best``'s held-out RMS (an extra component removes at most that error's energy from the held-out
    residuals; the model form is there for every candidate, so such a gain is not evidence for the
    component)."""
    h = best["_heldout_eq"]
    return max(_paired_noise(ctx, best, other, scatter), math.hypot(h, ctx.model_form) - h)


def _none_margin(ctx: _Context, best: dict, nominal: dict, scatter: float, sigma: float) -> float:
    """The nested margin (``_nested_margin``) of the nominal model (``nominal``, no parameters, nested in
    every candidate) against the verdict's candidate ``best``, with the noise part judged at a level
    never above ``NONE_NOISE_FACTOR`` times the measurement scatter ``sigma``.

    The nested margin allows for two readings of ``best``'s held-out RMS ``h``: all of it noise (the
    noise margin of a paired comparison, ``~ 2 h / sqrt(N)``), or all of it model form that a
    component more absorbs (``sqrt(h^2 + m^2) - h``).  Where ``h`` is far above the measurement
    scatter the first reading is not open: under noise alone the RMS of ``N`` held-out residuals
    exceeds ``4 sigma`` with probability below ``P(chi2_N > 16 N)`` (< 1e-4), and below
    ``P(chi2_N > 4 N)`` (< 0.05 for N >= 2) when the true scatter is twice the fallback's.  With ``h``
    taken as noise, seed 003's 3/3 split (docs/diagnosis.md: 6 held-out frequencies, nominal 43.1 %,
    joint stiffness 24.2 %, fallback scatter 0.5 %) read a 19 % gain as noise of level 24 %.

    Examples
    --------
    The nominal model at 40 %, the candidate at 20 % held out on six values, scatter 0.5 %, no model
    form measured: the noise part at 2 % (4 x 0.5 %), the margin that of the model form alone:

    >>> ctx = type("Ctx", (), {"pose_share": 1.0, "model_form": 0.0, "none_form": 0.0, "shape_dof": 0})()
    >>> best = {"_heldout_eq": 0.2, "_n_eq": 6, "_held_err": np.full(6, 0.2)}
    >>> nominal = {"_heldout_eq": 0.4, "_n_eq": 6, "_held_err": np.array([0.1, 0.7, 0.1, 0.2, 0.1, 0.3])}
    >>> margins = _nested_margin(ctx, best, nominal, 0.2), _none_margin(ctx, best, nominal, 0.2, 0.005)
    >>> [round(m, 4) for m in margins]
    [0.1633, 0.0163]
    """
    h = best["_heldout_eq"]
    level = max(h, scatter)
    capped = _noise(best, scatter, ctx.pose_share) * min(1.0, NONE_NOISE_FACTOR * sigma / level)
    return max(min(_paired_noise(ctx, best, nominal, scatter), capped), math.hypot(h, ctx.none_form) - h)


def _beats_nominal(ctx: _Context, entry: dict, nominal: dict, scatter: float, sigma: float) -> bool:
    """Whether candidate ``entry`` passes the held-out ``none`` test on its own: held out better than the
    nominal model (``nominal``) by more than its ``none`` margin (``_none_margin``).

    The point-mass re-choice (``_point_masses``) asks it of the verdict and of the lowest held-out
    candidate (``_lead``): the one-standard-error rule may put first a simpler candidate within noise of
    the lowest one that fails the test while the lowest one passes it.  Blind 2000 #23 (a tip mass): an
    elbow stiffness, one parameter, gains 0.316 % within its margin 0.546 %; the tip mass with its
    rotary inertia, ranked below it, gains 0.688 % beyond its own margin 0.395 %.  Asked of the verdict
    alone the re-choice never ran and the verdict was ``none``."""
    return nominal["_heldout_eq"] - entry["_heldout_eq"] > _none_margin(ctx, entry, nominal, scatter, sigma)


def _sub_candidate(ctx: _Context, entry: dict, drop: int, pool: list[dict], scatter: float) -> dict | None:
    """The candidate without component ``drop`` (found among the fitted ones or fitted now), validated."""
    comps = components(entry["_cand"])
    keep = [c for i, c in enumerate(comps) if i != drop]
    if not keep:
        return None
    cand = Candidate(tuple(e for e, _, _ in keep), tuple(loc for _, loc, _ in keep),
                     tuple(p for _, _, ps in keep for p in ps))
    found = next((e for e in pool if e["_cand"] == cand), None)
    if found is None:
        found = _screen(ctx, cand, scatter)
        pool.append(found)
    if "score" not in found:
        _cross_validate(ctx, found, scatter)
    if "params_at_bound" not in found:
        _annotate(ctx, found, scatter)
    return found


def _choose(ctx: _Context, ranking: list[dict], pool: list[dict], scatter: float
            ) -> tuple[dict | None, list[str]]:
    """The verdict's candidate and, when it is not the top of ``ranking``, why (one note per step): the
    best-scored one, with components pruned while dropping one does not worsen the held-out error
    beyond noise (or the component sits at its lower bound, i.e. is absent); candidates with a
    parameter run out of range are passed over."""
    notes: list[str] = []
    for best in ranking:
        top = best
        pruned = True
        while pruned and len(best["_cand"].effects) > 1:
            pruned = False
            for i in range(len(best["_cand"].effects)):
                sub = _sub_candidate(ctx, best, i, pool, scatter)
                worse = sub["_heldout_eq"] - best["_heldout_eq"]
                margin = _nested_margin(ctx, best, sub, scatter)
                if i in best["_idle"] or worse <= margin:
                    dropped = best["_cand"].effects[i]
                    notes.append(
                        f"{best['effect']} pruned to {sub['effect']}: its {dropped} part sits at its lower "
                        f"bound (absent)" if i in best["_idle"] else
                        f"{best['effect']} at {best['location']} pruned to {sub['effect']} at "
                        f"{sub['location']}: without {dropped} the held-out error rises by "
                        f"{percent(worse)}, within the margin {percent(margin)} (noise of a paired "
                        f"comparison on {max(best['_n_eq'] * ctx.pose_share, 1):.0f} held-out degrees of "
                        f"freedom, or the model-form level {percent(ctx.model_form)})")
                    best, pruned = sub, True
                    break
        if not best["_out_of_range"] and not best["_idle"]:
            return best, notes
        notes.append(f"{top['effect']} at {top['location']} passed over: "
                     + ("a parameter runs to the end of its range" if best["_out_of_range"]
                        else "a component sits at its lower bound"))
    return None, notes


def _relocated(ctx: _Context, best: dict, screened: list[dict], scatter: float) -> list[dict]:
    """The combinations of ``best`` with one component moved to another location of its effect (a
    grounded spring to another slot, a mass to another joint or link), fitted, cross-validated and
    annotated (added to ``screened``).  Asked only when a combination of effects is chosen but leaves a
    held-out error beyond ``EXPLAINED_FACTOR`` times the measurement scatter (``sigma``, without the
    model-form floor of the ranking ``scatter``): the pair search seeds its pairs from
    a few leads and a pool of the best singles, so a pair whose parts are each weak alone (blind draw
    845 #3: a joint mass 16th of the singles, its grounded spring one slot from a lead's) is never
    formed, and the nearest pair it did form leaves 9 times the scatter.

    With shapes, fitting a moved combination may lower ``ctx.shape_floor``; the caller then re-scores
    every cross-validated entry of ``screened`` at the lowered floor (docs/diagnosis.md)."""
    singles = {(e["effect"], e["location"]): e for e in screened if len(e["_cand"].effects) == 1}
    parts = [singles.get((eff, loc)) for eff, loc, _ in components(best["_cand"])]
    if any(p is None for p in parts):
        return []
    known = {e["_cand"] for e in screened}
    moved = []
    for i, part in enumerate(parts):
        for other in singles.values():
            if other["effect"] != part["effect"] or other is part:
                continue
            new_parts = [*parts[:i], other, *parts[i + 1:]]
            cand = combine(*(p["_cand"] for p in new_parts))
            if cand is None or cand in known:
                continue
            known.add(cand)
            entry = _screen(ctx, cand, scatter, new_parts)
            _cross_validate(ctx, entry, scatter)
            _annotate(ctx, entry, scatter)
            screened.append(entry)
            moved.append(entry)
    return moved


def _swapped(ctx: _Context, best: dict, screened: list[dict], scatter: float,
             pool: Sequence[dict] = ()) -> list[dict]:
    """The combinations of ``best`` with one component replaced by any other single (any effect, any
    location) and, when ``best`` is a pair and a fold trains on enough frequencies (``_few_poses``),
    every pair of a single of ``pool`` (the pair search's pool) with any single, those not fitted yet,
    fitted (added to ``screened``); cross-validated and annotated, best in-sample score first, while
    their in-sample score (``_lower``) is below ``best``'s score, the ones returned.  Asked whenever a
    combination is chosen: the pair search pairs the pool's singles and a few leads only, so a pair of
    which one part is chosen and the other is neither pooled nor a lead is never formed (blind 1475
    case 34 from 0: a link-1 stiffness, best single, with an elbow stiffness, 15th of 18 singles; the
    chosen grounded spring plus elbow stiffness held out 2.74 %, the truth 0.50 %), nor one whose pooled
    part is no lead and whose other part is not pooled, when the chosen pair shares neither (blind 1579
    case 24: a link-2 stiffness, 5th of the pool, with the base stiffness, 9th single, held out 1.04 %
    against the chosen link-1 plus sensor mass's 1.41 %; 1579 case 34: a tip mass, 4th of the pool,
    with a grounded spring, 12th single, 1.6 % against a spring elsewhere plus an elbow stiffness's
    5.4 %; frequency-equivalent held-out RMS, the shapes counted, at the final ranking scatter, not the
    frequencies' held-out RMS of diagnosis.json: 2.9 % for that spring plus stiffness)."""
    singles = [e for e in screened if len(e["_cand"].effects) == 1]
    found = {(e["effect"], e["location"]): e for e in singles}
    parts = [found.get((eff, loc)) for eff, loc, _ in components(best["_cand"])]
    if any(p is None for p in parts):
        return []
    tries = [[*parts[:i], other, *parts[i + 1:]] for i in range(len(parts)) for other in singles]
    if len(parts) == 2 and not _few_poses(ctx):
        tries += [[a, b] for a in pool for b in singles]
    known = {e["_cand"] for e in screened}
    new = []
    for new_parts in tries:
        cand = combine(*(p["_cand"] for p in new_parts))
        if cand is None or cand in known:
            continue
        known.add(cand)
        new.append(_screen(ctx, cand, scatter, new_parts))
    screened += new
    done = []
    for e in sorted(new, key=lambda e: e["_lower"]):
        if e["_lower"] >= best["score"]:
            break
        _cross_validate(ctx, e, scatter)
        _annotate(ctx, e, scatter)
        done.append(e)
    return done


def _rescored(ctx: _Context, screened: list[dict], ranking: list[dict], shape_floor: float,
              scatter: float) -> bool:
    """Whether fits added since the shape noise floor was ``shape_floor`` lowered it; if so, every
    cross-validated entry of ``screened`` (the ranking, the added fits and the sub-candidates
    ``_choose`` validated) is re-scored at the new floor and ``ranking``'s refinements guarded again."""
    if ctx.shape_floor >= shape_floor:
        return False
    for e in screened:
        if "score" in e:
            _rescore(ctx, e, scatter)
    _refinement_guard(ranking)
    return True


def _chosen(ctx: _Context, ranking: list[dict], screened: list[dict], scatter: float) -> tuple:
    """``_choose``, made again while the sub-candidates it validates lower the shape noise floor: every
    cross-validated entry is then re-scored at the new floor (``_rescored``) and ordered again, so the
    verdict is chosen from scores at one floor (a floor only falls, by new fits, so this ends)."""
    floor = ctx.shape_floor
    best, notes = _choose(ctx, ranking, screened, scatter)
    while _rescored(ctx, screened, ranking, floor, scatter):
        ranking.sort(key=lambda e: e["score"])
        _order(ctx, ranking, scatter)
        floor = ctx.shape_floor
        best, notes = _choose(ctx, ranking, screened, scatter)
    return best, notes


def _point_mass(cand: Candidate) -> Candidate:
    """``cand`` with every added mass a point mass: its rotary inertia left at the effect's default, zero
    (models/effects.py), not fitted."""
    return replace(cand, params=tuple(p for p in cand.params if p.name != "inertia_kgm2"))


def _point_masses(ctx: _Context, ranking: list[dict], screened: list[dict], scatter: float) -> list[dict]:
    """The single candidates of ``ranking`` that are an added mass (joint, hub or tip) refitted as a point
    mass (``_point_mass``), one parameter fewer, cross-validated and annotated (added to ``screened``; the
    ones not fitted before returned).  Singles only: a combination with its masses as point masses
    counts no more parameters than the single mass with its inertia and then ranks with it (blind 1051
    case 20, a strong elbow mass, became an elbow point mass with a link-1 mass scale).  Asked when the
    verdict is an ambiguous effect (not ``none``, which stays the nominal model's test against the
    candidates as ranked): there the
    one-standard-error rule (``_order``) puts the simplest of the candidates equal within noise first,
    and the rotary inertia of a small added mass is a parameter the data seldom identify -- it counts
    against the mass and, fitted per fold, worsens its held-out error.  Blind 1576 case 9 (from 0): a
    weak elbow mass, held out 0.815 % (inertia fitted 80 times the true one, unidentified) against a
    link-1 mass scale's 0.869 % within the paired margin 0.069 %, ranked second with two parameters
    against one; as a point mass it is held out at 0.782 %, beyond that margin, with one."""
    known = {e["_cand"] for e in screened}
    points = []
    for e in ranking:
        if len(e["_cand"].effects) > 1 or all(p.name != "inertia_kgm2" for p in e["_cand"].params):
            continue   # a combination, or a single with no rotary inertia (no added mass, or a point one)
        cand = _point_mass(e["_cand"])
        if cand in known:
            continue
        known.add(cand)
        entry = _screen(ctx, cand, scatter)
        _cross_validate(ctx, entry, scatter)
        _annotate(ctx, entry, scatter)
        screened.append(entry)
        points.append(entry)
    return points


def _structured(resid: np.ndarray, scatter: float) -> bool:
    """Residuals [C, n] correlated across configurations or modes beyond the scatter.

    Under pure scatter (held-out predictions inflate it by at most ``HELDOUT_INFLATION``) the per-mode
    means over configurations and the per-configuration means over modes are normal with variance
    ``sigma^2 / count``; their sums of squares scaled by ``count / sigma^2`` are chi-square with as many
    degrees of freedom as means.  Structured when either exceeds its ``STRUCTURE_QUANTILE`` quantile.
    """
    from scipy.special import chdtri  # inverse chi-square survival function (lighter than scipy.stats)

    sigma = HELDOUT_INFLATION * scatter
    C, n = resid.shape
    for axis, count in ((0, C), (1, n)):
        if count < 2:
            continue
        means = resid.mean(axis=axis)
        if count * np.sum(means**2) / sigma**2 > chdtri(means.size, 1.0 - STRUCTURE_QUANTILE):
            return True
    return False


def _confirm_region(where: dict, rig: Rig, effect: str, location: str) -> None:
    """Where several regions explain the error pattern about equally (R^2 within ``REGION_TIE``), name the
    region of the winning candidate's first effect; the sensitivities alone cannot tell them apart."""
    scores = where["region_scores"]
    first = _effect_region(rig, effect.split("+")[0], location.split("+")[0])
    if scores and scores.get(first, 0.0) >= REGION_TIE * max(scores.values()):
        where["region"] = first


def _paired_shapes(ctx: _Context, fam) -> np.ndarray:
    return paired_modes(fam, np.zeros((1, len(ctx.meas.configs), 0)), ctx.target)[2][0]


def _verdict(ctx: _Context, best: dict | None, ranking: list[dict], baseline: dict, before: float,
             nominal: dict, scatter: float, sigma: float, none_sigma: float, small: bool,
             notes: Sequence[str] = (), singles: Sequence[Candidate] = ()) -> dict:
    """The verdict block; ``before`` is the nominal model's held-out frequency RMS, ``nominal`` the
    nominal model as a scored entry (``_nominal_entry``, scored at ``scatter``);
    ``scatter`` ranks candidates (the measurement's ``sigma`` plus the model-form floor), ``sigma``
    judges what remains, ``none_sigma`` (``_none_scatter``) whether the nominal model's gap is within
    the noise; ``small`` that it needs no effect (within the noise, and no candidate held out better
    than the nominal model beyond noise); ``notes`` say why the verdict is not the top of the ranking
    (``_choose``); ``singles`` are the single candidates the moved-sensor check refits (``_shape_flags``)."""
    meas = ctx.meas
    none = {"effect": "none", "location": "", "heldout_rms_rel_error_before": before,
            "heldout_rms_rel_error_after": before,
            "explained": bool(before <= EXPLAINED_FACTOR * sigma), "alternatives": [],
            "gap_removed": 0.0, "remaining_over_scatter": before / sigma}
    if small:
        return _flag_none(ctx, _none_with_alternatives(ctx, {**none, "grade": "explained", "summary": (
            f"baseline RMS gap {percent(baseline['rms_rel_error'])} is within {NONE_FACTOR:g}x the "
            f"measurement scatter ({percent(none_sigma)}) on top of the beam theory's known error "
            f"({percent(ctx.beam_form)}): "
            "no unmodelled effect is needed")}, ranking, nominal, scatter))
    if not ranking or best is None:
        return _flag_none(ctx, {**none, "grade": "not explained", "flags": list(notes), "summary": (
            f"baseline RMS gap {percent(baseline['rms_rel_error'])} but no candidate effect applies to this "
            "rig "
            "within its parameter range: the gap is unexplained")})
    gain = nominal["_heldout_eq"] - best["_heldout_eq"]
    none_margin = _none_margin(ctx, best, nominal, scatter, sigma)
    if gain <= none_margin:
        return _flag_none(ctx, _none_with_alternatives(ctx, {
            **none, "grade": "not explained" if before > EXPLAINED_FACTOR * sigma else "explained",
            "summary": (f"no candidate beats the nominal model on held-out configurations beyond the "
                        f"margin {percent(none_margin)} of one "
                        "component "
                        f"more (noise of a paired comparison, or the model-form level "
                        f"{percent(ctx.none_form)}; baseline held-out RMS {percent(before)}, best "
                        f"{best['effect']} "
                        f"{percent(best['heldout_rms_rel_error'])})")}, ranking, nominal, scatter))
    after = best["heldout_rms_rel_error"]
    resid = best["_heldout_freq_hz"] / meas.freq_hz - 1.0
    structured = _structured(resid, sigma)
    feature, flags = _residual_feature(ctx, best, resid, sigma, singles)
    explained = after <= EXPLAINED_FACTOR * sigma and not structured and not flags
    removed = 1.0 - after / before if before > 0 else 0.0
    grade = ("explained" if explained else "largely explained" if removed >= 0.75 else
             "partly explained" if removed >= 0.3 else "not explained")
    unidentified = best["unidentified_params"]
    rank = ranking.index(best) + 1
    verdict = {"effect": best["effect"], "location": best["location"],
               "heldout_rms_rel_error_before": before, "heldout_rms_rel_error_after": after,
               "explained": bool(explained),
               "params": {k: v for k, v in best["params"].items() if k not in unidentified},
               "unidentified_params": list(unidentified), "params_at_bound": list(best["params_at_bound"]),
               "structured_residuals": bool(structured), "ranked": rank,
               "why_not_top": "; ".join(notes) if rank > 1 and notes else None,
               "grade": grade, "gap_removed": removed, "remaining_over_scatter": after / sigma,
               "residual_feature": feature, "flags": flags,
               "param_intervals": {k: v for k, v in best["_param_intervals"].items()
                                   if k not in unidentified},
               "heldout_in_prediction_interval": list(_heldout_intervals(ctx, best, scatter)),
               "interval_method": INTERVAL_METHOD}
    worst = np.dstack(np.unravel_index(np.argsort(-np.abs(resid), axis=None)[:3], resid.shape))[0]
    remaining = [{"config": meas.configs[c], "mode": int(m + 1), "heldout_rel_error": float(resid[c, m])}
                 for c, m in worst]
    verdict["remaining"] = remaining
    mine = set(zip(best["_cand"].effects, best["_cand"].locations, strict=True))
    alts = _alternatives(ctx, best, ranking, scatter)
    verdict["alternatives"] = [
        {"effect": e["effect"], "location": e["location"], "params": e["params"],
         "heldout_rms_rel_error": e["heldout_rms_rel_error"], **separating_measurement(ctx, best, e)}
        for e in alts]
    verdict["ambiguous"] = bool(alts)
    near = [e for e in ranking if e is not best and not e["_out_of_range"] and not e["_idle"]
            and not mine <= set(zip(e["_cand"].effects, e["_cand"].locations, strict=True))
            and e["_heldout_eq"] - best["_heldout_eq"]
            <= RIVAL_MARGIN * _noise(best, scatter, ctx.pose_share)]
    rivals = _once_per_name([*alts, *_once_per_name(near)[:MAX_RIVALS]])
    nested_only = bool(alts) and all(adds_to(best, e) for e in alts)    # advice: no pose decides these
    verdict["next_measurements"] = next_measurements(ctx, best, rivals, scatter) if alts and not nested_only \
        else []
    text = f"{best['effect']} at {best['location']}, {gap_words(before, after, sigma, grade, feature)}"
    if not explained:
        worst_txt = ", ".join(
            f"mode {r['mode']} at {r['config']} ({percent(r['heldout_rel_error'], signed=True)})"
            for r in remaining)
        text += f"; largest held-out errors: {worst_txt}"
    if flags:
        text += "; flagged: " + "; ".join(flags)
    if rank > 1 and notes:
        text += f"; ranked {rank}: " + "; ".join(notes)
    if unidentified:
        text += f"; the data cannot identify {', '.join(unidentified)}"
    if alts:
        a0 = verdict["alternatives"][0]
        names = ", ".join(f"{e['effect']} at {e['location']}" for e in alts)
        text += f"; ambiguous: {names} {'fits' if len(alts) == 1 else 'fit'} as well within noise"
        if verdict["next_measurements"]:
            if a0.get("separate_at"):
                text += (f"; measuring {a0['separate_at']} (model mode {a0['separate_mode']}) would separate "
                         f"the first by {percent(a0['separate_rel_diff'])}")
            nxt = verdict["next_measurements"][0]
            text += (f"; next measurement most likely to decide: {nxt['pose']} (mode {nxt['mode']}, "
                     f"{nxt['information_nats']:.1f} nats)")
        elif not nested_only:
            text += f"; {UNLIKELY}"
        else:
            text += "; " + no_pose_decides(
                best, alts, [_paired_noise(ctx, best, e, scatter) for e in alts],
                math.hypot(best["_heldout_eq"], ctx.model_form) - best["_heldout_eq"],
                len({tuple(sorted(p.items())) for p in meas.poses}))
    verdict["summary"] = text
    return verdict


def _alternatives(ctx: _Context, best: dict, ranking: list[dict], scatter: float) -> list[dict]:
    """The verdict's alternatives: the usable candidates of ``ranking`` (in range, no idle component) not
    containing ``best`` that are held out equal to it within noise (``_noise``), simplest first (as the
    one-standard-error rule orders them), at most ``MAX_ALTERNATIVES`` names; then, at most
    ``MAX_SUPERSETS``, those with one component more that fit better held out, but by less than the
    nested margin (``_nested_margin``): the data cannot say whether that component is there too.  A
    name is listed once (``_once_per_name``, the first: a point mass before the same mass with its
    inertia)."""
    mine = set(zip(best["_cand"].effects, best["_cand"].locations, strict=True))
    usable = [e for e in ranking if e is not best and not e["_out_of_range"] and not e["_idle"]]

    def parts(e: dict) -> set:
        return set(zip(e["_cand"].effects, e["_cand"].locations, strict=True))

    alts = _once_per_name(sorted((e for e in usable if not mine <= parts(e)
                                  and e["_heldout_eq"] - best["_heldout_eq"]
                                  <= _noise(best, scatter, ctx.pose_share)),
                                 key=lambda e: (e["n_params"], e["score"])))
    supersets = (e for e in usable if len(e["_cand"].effects) == len(best["_cand"].effects) + 1
                 and mine < parts(e)
                 and 0 < best["_heldout_eq"] - e["_heldout_eq"] <= _nested_margin(ctx, best, e, scatter))
    return alts[:MAX_ALTERNATIVES] + _once_per_name(sorted(supersets, key=lambda e: e["_heldout_eq"]))[
        :MAX_SUPERSETS]


def _once_per_name(entries: Sequence[dict]) -> list[dict]:
    """``entries`` with each name (effect and location) once, the first kept: a point mass and the same
    mass with its rotary inertia (``_point_masses``) are one candidate to the reader and one rival to the
    advice.  Cut after this, not before: cut before, the two forms of one mass could take two of the
    three alternative slots; and counted as two rivals, each had to be ruled out given the other is the
    truth, which no measurement does (the look-alike case of tests/test_next_measurement.py: decide
    chance 0.46 against 38 of 60 draws decided; once, 0.67)."""
    named: dict[tuple[str, str], dict] = {}
    for e in entries:
        named.setdefault((e["effect"], e["location"]), e)
    return list(named.values())


def _none_with_alternatives(ctx: _Context, verdict: dict, ranking: list[dict], nominal: dict,
                            scatter: float) -> dict:
    """A ``none`` verdict with the candidates that fit better held out than the nominal model by more
    than the noise margin (at most ``MAX_ALTERNATIVES``, best score first) as alternatives: nothing
    is needed, but the data cannot exclude them (``ambiguous``)."""
    alts = _once_per_name(_beating_nominal(ctx, ranking, nominal, scatter))[:MAX_ALTERNATIVES]
    if not alts:
        return verdict
    names = ", ".join(f"{e['effect']} at {e['location']} ({percent(e['heldout_rms_rel_error'])})"
                      for e in alts)
    return {**verdict, "ambiguous": True,
            "alternatives": [{"effect": e["effect"], "location": e["location"], "params": e["params"],
                              "heldout_rms_rel_error": e["heldout_rms_rel_error"]} for e in alts],
            "summary": f"{verdict['summary']}; but the data cannot exclude, held out better than the nominal "
                       f"model ({percent(verdict['heldout_rms_rel_error_before'])}): {names}"}


def _beating_nominal(ctx: _Context, ranking: Sequence[dict], nominal: dict, scatter: float,
                     form: float = 0.0) -> list[dict]:
    """The annotated candidates of ``ranking`` held out better than the nominal model (``nominal``,
    ``_nominal_entry`` scored) by more than the noise margin of a paired comparison on the same held-out
    residuals (``_paired_noise``, as the held-out ``none`` test ``_none_margin`` compares them) and by
    more than ``form`` (a known model-form error a candidate may absorb without being there), best score
    first.  Two RMS estimates taken as independent (``_noise`` at the nominal model's level, the margin
    before) count as noise what both models leave alike: blind 1262 #16 (a weak link-2 mass, 12 poses x
    4 modes) was ``none`` with the mass held out at 0.767 % against the nominal model's 1.027 %, 0.260 %
    better, the unpaired margin 0.297 %."""
    return sorted((e for e in ranking if not e["_out_of_range"] and not e["_idle"]
                   and e["_heldout_eq"] < nominal["_heldout_eq"]
                   - max(_paired_noise(ctx, e, nominal, scatter), form)), key=lambda e: e["score"])


def _flag_none(ctx: _Context, verdict: dict) -> dict:
    """A ``none`` verdict whose measured shapes disagree with the nominal model at one sensor
    (``_shape_flags``): flagged, and then not explained (the frequencies need no effect, the shapes are
    not what the rig says)."""
    sensor, flags = _shape_flags(ctx, _paired_shapes(ctx, ctx.family([]))) if ctx.meas.shapes is not None \
        else ("", [])
    if not flags:
        return verdict
    return {**verdict, "explained": False, "grade": "not explained", "residual_feature": f"sensor {sensor}",
            "flags": [*(verdict.get("flags") or []), *flags],
            "summary": f"{verdict['summary']}; flagged: {'; '.join(flags)}"}


def _residual_feature(ctx: _Context, best: dict, resid: np.ndarray, sigma: float,
                      singles: Sequence[Candidate] = ()) -> tuple[str, list[str]]:
    """What in the held-out residuals [C, n] of the verdict points outside the library, and flags.

    Candidate features, each a z-like statistic against ``HELDOUT_INFLATION * sigma``: a mode whose
    residual has one sign at every pose (its mean over configurations), a pose trend of one mode (the
    least-squares slope of its residual on one pose variable, >= 3 distinct values), one configuration
    (its mean over modes).  The largest beyond ``FEATURE_Z`` is reported.  With measured shapes (three
    sensors or more), a sensor whose shapes disagree with the verdict's fitted model beyond the shape
    noise of the other sensors (``_shape_flags``, which refits ``singles`` without that sensor in the
    mode pairing) is a flag: a sensor mounted elsewhere or on another direction than the rig says, or a
    local effect no library entry has."""
    meas = ctx.meas
    sd = HELDOUT_INFLATION * sigma
    C, n = resid.shape
    found: list[tuple[float, str]] = []
    for m in range(n):
        r = resid[:, m]
        found.append((abs(r.mean()) * math.sqrt(C) / sd,
                      f"mode {m + 1} ({percent(r.mean(), signed=True)} on average at every pose)"))
        for v in ctx.rig.pose_variables:
            q = np.array([p[v] for p in meas.poses])
            if len(np.unique(q)) < 3:
                continue
            dq = q - q.mean()
            slope = float(dq @ r / (dq @ dq))
            z = abs(slope) * math.sqrt(dq @ dq) / sd
            found.append((z, f"a trend of mode {m + 1} with {v} ({percent(slope * np.ptp(q), signed=True)} "
                             f"over "
                             f"{q.min():g}..{q.max():g})"))
    if n > 1:
        for c in range(C):
            mean = resid[c].mean()
            found.append((abs(mean) * math.sqrt(n) / sd,
                          f"configuration {meas.configs[c]} ({percent(mean, signed=True)} on every mode)"))
    z, text = max(found, key=lambda t: t[0]) if found else (0.0, "")
    feature = text if z > FEATURE_Z else ""
    sensor, flags = _shape_flags(ctx, _fit_shapes(ctx, best), singles, best["fit_rms_rel_error"])
    return feature or (f"sensor {sensor}" if sensor else ""), flags


def _shape_flags(ctx: _Context, model: np.ndarray, singles: Sequence[Candidate] = (),
                 fit_error: float = 0.0) -> tuple[str, list[str]]:
    """The sensor whose measured shapes disagree with ``model`` [C, s, n] beyond the shape noise of the
    others (``compare.sensor_flag``), and its flag; empty without shapes at three sensors or more.

    When none does and ``singles`` are given, the sensor that disagrees most with ``model`` (a fit with
    ``fit_error``, its in-sample frequency RMS) is left out of the mode pairing and the ``singles`` are
    fitted again to all configurations (``_unpaired_flag``).  A moved sensor misleads the pairing by
    MAC: the true candidate's modes are paired with the wrong measured ones, it fits the frequencies
    badly, and a wrong verdict whose shapes absorb the sensor's misfit wins (blind 1788 #10, a tip mass
    read as a link-2 mass scale: link mass 1.61 %, tip mass 7.10 % in-sample; the sensor's ratio 12.9
    against the verdict, unflagged).  Without the sensor in the pairing the tip mass fits 0.55 %, and
    against it the sensor's ratio is 2224."""
    meas = ctx.meas
    if meas.shapes is None or len(meas.sensors) < 3:
        return "", []
    sensor, text = sensor_flag(meas.shapes, model, meas.sensors)
    if not text and singles:
        sensor, text = _unpaired_flag(ctx, model, singles, fit_error)
    return sensor, [text] if text else []


def _unpaired_flag(ctx: _Context, model: np.ndarray, singles: Sequence[Candidate], fit_error: float
                   ) -> tuple[str, str]:
    """The sensor ``j`` that disagrees most with ``model`` (``sensor_check``) and its flag when, with
    ``j`` left out of the mode pairing (``Target.pairing_sensors``: the MAC's numerator and both its
    norms sum over the other sensors only), the single candidate of ``singles`` that fits the
    frequencies of all configurations best fits them no worse than the verdict's model (in-sample
    frequency RMS ``fit_error``) and ``j``'s shapes disagree with it (``sensor_check`` flags ``j``);
    empty strings otherwise.  No margin is
    chosen: with every sensor in the pairing the verdict's model is the better fit, so a candidate
    that fits better once one sensor no longer pairs the modes, and disagrees at that sensor, says the
    sensor misled the pairing."""
    meas = ctx.meas
    check = sensor_check(meas.shapes, model)
    if check is None:
        return "", ""
    target = replace(ctx.target, pairing_sensors=np.delete(np.arange(len(meas.sensors)), check.sensor))
    fits = []
    for cand in singles:
        fam = ctx.family(cand.handles)
        res = fit_candidate(fam, cand, target, ctx.train[:1])
        fits.append((rms(res.freq_hz[0] / meas.freq_hz - 1.0), cand, fam, res.theta[:1]))
    error, cand, fam, theta = min(fits, key=lambda t: t[0])
    if not error <= fit_error:   # NaN (a failed fit) is not 'no worse'
        return "", ""
    h = evaluate(fam, design(cand, target), theta, target, gradients=False)[3]
    other = paired_modes(fam, h, target, gradients=False)[2][0]
    found = sensor_check(meas.shapes, other)
    if found is None or not found.flagged or found.sensor != check.sensor:
        return "", ""
    return meas.sensors[check.sensor], flag_text(
        meas.shapes, other, meas.sensors, found,
        f" when it is left out of the mode pairing: against {cand.effect} at {cand.location}, which then "
        f"fits the frequencies to {percent(error)} (the verdict {percent(fit_error)})")


def _heldout_intervals(ctx: _Context, entry: dict, scatter: float) -> tuple[int, int]:
    """(held-out frequencies inside their 95 % prediction interval, held-out frequencies): each fold's
    fit predicts the configurations it did not see with variance ``g^T C g + scatter^2`` (``C`` the
    fold's linearised parameter covariance, ``g`` the relative sensitivities at the held-out pose;
    the prediction interval of a new observation, Seber & Wild 1989 §5.1)."""
    cand = entry["_cand"]
    train = ctx.train[1:]
    f, df, _, _ = evaluate(entry["_fam"], design(cand, ctx.target), entry["_theta_folds"], ctx.target)
    rel = df / ctx.meas.freq_hz[None, ..., None]
    inside = total = 0
    for k, tr in enumerate(train):
        cov = linear_cov(rel[k][tr], scatter)
        g = rel[k][~tr]                                                     # [h, n, J]
        var = np.einsum("hnj,jk,hnk->hn", g, cov, g) + scatter**2
        err = f[k][~tr] / ctx.meas.freq_hz[~tr] - 1.0
        inside += int(np.sum(np.abs(err) <= Z95 * np.sqrt(var)))
        total += err.size
    return inside, total


def _fit_shapes(ctx: _Context, entry: dict) -> np.ndarray:
    """Sensor shapes [C, n_sensors, n] of ``entry``'s fit to all configurations, paired as in the fit."""
    cand = entry["_cand"]
    h = evaluate(entry["_fam"], design(cand, ctx.target), entry["_theta0"][None], ctx.target)[3]
    return paired_modes(entry["_fam"], h, ctx.target)[2][0]


def _predictions(meas: Measured, base_f: np.ndarray, best: dict | None) -> Predictions:
    def table(f: np.ndarray) -> dict[str, np.ndarray]:
        return dict(zip(meas.configs, f, strict=True))

    return Predictions(measured_hz=table(meas.freq_hz), baseline_hz=table(base_f),
                       best_fit_hz=table(best["_freq_hz"]) if best is not None else None,
                       best_heldout_hz=table(best["_heldout_freq_hz"]) if best is not None else None)
