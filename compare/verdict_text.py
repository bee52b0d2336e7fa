"""The diagnosis' verdict in words a test engineer reads correctly: the share of the held-out gap an
effect removes, what remains against the measurement scatter, and the scatter the ranking used."""

from __future__ import annotations

import math

from flexmodal.checked_io.percent import percent
from flexmodal.compare.gap import FALLBACK_SOURCE
from flexmodal.compare.result import MIN_CHANCE, Diagnosis

EXPLAINED_FACTOR = 3.0
"""A held-out RMS within 3x the measurement scatter (and unstructured, unflagged) is explained."""


def gap_words(before: float, after: float, sigma: float, grade: str, feature: str = "") -> str:
    """The graded verdict in words: the share of the held-out gap the effect removes and what remains,
    judged against the measurement scatter ``sigma`` (fractions).

    Examples
    --------
    >>> import textwrap
    >>> words = gap_words(0.106, 0.015, 5e-6, "largely explained", "mode 1 rising with theta")
    >>> print(textwrap.fill(words, 100))
    largely explained: 86 % of the held-out gap removed (from 10.6 % to 1.5 %); the remaining 1.5 % is
    more than 100 times the measurement scatter (0.0005 %), so it is not noise: no effect in the library
    accounts for it; it shows as mode 1 rising with theta
    >>> gap_words(0.127, 0.000497, 0.000204, "explained").split(";")[0]
    'explained: 99.6 % of the held-out gap removed (from 12.7 % to 0.0497 %)'
    >>> print(textwrap.fill(gap_words(0.05, 0.004, 0.003, "explained"), 100))
    explained: 92 % of the held-out gap removed (from 5 % to 0.4 %); the remaining 0.4 % is 1.3 times
    the measurement scatter (0.3 %), within the 3 times counted as noise
    """
    removed = 1.0 - after / before if before > 0 else 0.0
    share = f"{100 * removed:.0f}"
    if share == "100" and after > 0:   # "100 % removed" beside "the remaining 0.0497 %" contradicts it
        share = f"{min(100 * removed, 99.9):.1f}"
    head = (f"{grade}: {share} % of the held-out gap removed "
            f"(from {percent(before)} to {percent(after)})")
    ratio = after / sigma if sigma > 0 else math.inf
    note = f"; it shows as {feature}" if feature else ""
    if ratio <= EXPLAINED_FACTOR:
        near = (f"the remaining {percent(after)} is below the measurement scatter ({percent(sigma)})"
                if ratio <= 1 else
                f"the remaining {percent(after)} is {ratio:.2g} times the measurement scatter "
                f"({percent(sigma)}), within the {EXPLAINED_FACTOR:g} times counted as noise")
        if grade == "explained":
            return f"{head}; {near}"
        return f"{head}; {near}, but not random: it has structure{note}"
    times = "more than 100 times" if ratio > 100 else f"{ratio:.0f} times"
    return (f"{head}; the remaining {percent(after)} is {times} the measurement scatter "
            f"({percent(sigma)}), so it is not noise: no effect in the library accounts for it{note}")


def verdict_words(result: Diagnosis) -> str:
    """``gap_words`` of a diagnosis' verdict (empty for ``none``)."""
    v = result.verdict
    src = result.scatter_source
    if v.effect == "none" or v.grade is None:
        return ""
    sigma = src.measurement if src is not None and src.measurement else result.scatter or 0.0
    return gap_words(v.heldout_rms_rel_error_before, v.heldout_rms_rel_error_after, sigma, v.grade,
                     v.residual_feature or "")


def scatter_line(result: Diagnosis) -> str:
    """One line: the scatter the ranking used and where it came from: the measurement scatter and the
    model-form floor added in quadrature (``scatter = sqrt(measurement^2 + floor^2)``), or the least
    scatter the ranking uses (compare.diagnosis.MIN_SCATTER) when that sum is below it.  The measurement
    scatter's source is named as stored (``repeated configurations``, ``freq_std_hz column``), the stored
    ``--scatter (fallback)`` as ``the --scatter fallback``."""
    src = result.scatter_source
    if src is None or result.scatter is None:
        return ""
    meas = src.measurement if src.measurement is not None else result.scatter
    floor = src.model_form_floor or 0.0
    combined = math.hypot(meas, floor)
    head = (f"scatter: {percent(result.scatter)} = sqrt(m^2 + f^2)"
            if math.isclose(result.scatter, combined, rel_tol=1e-6) else
            f"scatter: {percent(result.scatter)}, the least the ranking uses (sqrt(m^2 + f^2) = "
            f"{percent(combined)} is below it)")
    source = "the --scatter fallback" if src.source == FALLBACK_SOURCE else src.source
    return (f"{head}; measurement scatter m = {percent(meas)} ({source}: {src.detail}), model-form "
            f"floor f = {percent(floor)} (held-out error of the best candidate beyond the measurement); what "
            f"remains is judged against m = {percent(meas)}")


def alternatives_words(result: Diagnosis) -> str:
    """The candidates that fit as well as the verdict within noise, each with its held-out RMS error
    (``grounded_spring+joint_stiffness at link2@1+elbow (held-out 1.29 %)``); empty when none does."""
    alts = result.verdict.alternatives or ()
    return "; ".join(f"{a.effect} at {a.location} (held-out {percent(a.heldout_rms_rel_error)})"
                     for a in alts)


def remaining_words(result: Diagnosis) -> str:
    """The largest held-out errors the verdict leaves, signed (``mode 1 at theta90 (-3.26 %)``)."""
    return ", ".join(f"mode {r.mode} at {r.config} ({percent(r.heldout_rel_error, signed=True)})"
                     for r in result.verdict.remaining or () if r.heldout_rel_error is not None)


SHEAR_UNCALIBRATED = ("a section sets shear_coefficient, but the `none` gate and beam-theory allowance of "
                      "the diagnosis were calibrated on Euler-Bernoulli frames (no blind figure was measured "
                      "with shear on; docs/models.md, Limitations)")
"""The warning of a diagnosis on a rig that sets shear deformation (models/rig.py ``Shear``)."""

NO_POSE = "no pose is advised"
"""How the verdict's summary starts its reason for advising no pose (compare/next_measurement.py)."""

UNLIKELY = ("no untested pose is likely to decide between the verdict and its alternatives (each has less "
            f"than a {percent(MIN_CHANCE)} chance to)")
"""Why no pose is advised for an ambiguous verdict whose advice found no pose with ``MIN_CHANCE``."""


def advice_words(result: Diagnosis) -> str:
    """What to measure next, in words: the advised untested poses (model mode, expected information,
    chance that one measurement decides, how far beyond the measured range), or why no pose is advised
    (said once); empty for a ``none`` verdict.

    Examples
    --------
    >>> from flexmodal.compare.result import MIN_CHANCE, Diagnosis
    >>> d = Diagnosis.from_dict({"baseline": {"rms_rel_error": 0.1, "max_rel_error": 0.2,
    ...                  "per_mode": {"1": 0.1}, "per_config": {"a": 0.1}},
    ...     "where": {"modes": [1], "configs": ["a"], "region": ""}, "ranking": [],
    ...     "verdict": {"effect": "joint_stiffness", "location": "elbow", "explained": True,
    ...                 "heldout_rms_rel_error_before": 0.1, "heldout_rms_rel_error_after": 0.01,
    ...                 "ambiguous": False}})
    >>> advice_words(d)
    'none needed: no other candidate fits as well within noise'
    """
    v = result.verdict
    if v.effect == "none":
        return ""
    if v.next_measurements:
        def one(x) -> str:
            chance = (f", {100 * x.decide_chance:.0f} % chance to decide"
                      if x.decide_chance is not None else "")
            beyond = f"; {x.beyond}: check that the arm reaches it" if x.beyond else ""
            return f"{x.pose} (model mode {x.mode}, {x.information_nats:.1f} nats expected{chance}{beyond})"
        return "; ".join(one(x) for x in v.next_measurements)
    if not v.ambiguous:
        return "none needed: no other candidate fits as well within noise"
    summary = v.summary or ""
    at = summary.find(NO_POSE)
    if at >= 0:
        return summary[at:]
    return f"none: {UNLIKELY}"
