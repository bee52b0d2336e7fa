"""The diagnosis' verdict in words a test engineer reads correctly: the share of the held-out gap an
effect removes, what remains against the measurement scatter, and the scatter the ranking used."""

from __future__ import annotations

import math

from flexmodal.checked_io.percent import percent
from flexmodal.compare.result import Diagnosis

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
    >>> print(textwrap.fill(gap_words(0.05, 0.004, 0.003, "explained"), 100))
    explained: 92 % of the held-out gap removed (from 5 % to 0.4 %); what remains is within the
    measurement scatter (0.3 %)
    """
    removed = 1.0 - after / before if before > 0 else 0.0
    head = (f"{grade}: {100 * removed:.0f} % of the held-out gap removed "
            f"(from {percent(before)} to {percent(after)})")
    ratio = after / sigma if sigma > 0 else math.inf
    note = f"; it shows as {feature}" if feature else ""
    if ratio <= EXPLAINED_FACTOR:
        if grade == "explained":
            return f"{head}; what remains is within the measurement scatter ({percent(sigma)})"
        return (f"{head}; what remains is near the measurement scatter ({percent(sigma)}) but not random: "
                f"it has structure{note}")
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
    """One line: the scatter the ranking used and where it came from (measurement + model-form floor)."""
    src = result.scatter_source
    if src is None or result.scatter is None:
        return ""
    meas = src.measurement if src.measurement is not None else result.scatter
    floor = src.model_form_floor or 0.0
    own = f"{percent(meas)} from {src.source}"
    return (f"scatter: {percent(result.scatter)} = measurement ({own}; {src.detail}) + model-form floor "
            f"{percent(floor)} (held-out error of the best candidate beyond the measurement); what remains "
            f"is judged against {percent(meas)}")
