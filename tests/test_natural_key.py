"""The natural order reads signed decimal pose values as numbers (review 40 L4: ``theta-30`` sorted after
``theta30``, negatives by rising magnitude, ``theta7.5`` before ``theta7.25``): ``theta=-30`` <
``theta=-15`` < ``theta=0`` < ``theta=2.5`` < ``theta=7.25`` < ``theta=7.5`` < ``theta=30``, the names
``identify --track`` and the advised poses get.  A ``-`` after a letter or a digit stays a hyphen
(``run-3``, ``theta30-impact``).  Properties on generated names, each judged against ``Decimal`` values
of numbers the test wrote itself, not against the key."""

from __future__ import annotations

from decimal import Decimal

from hypothesis import given
from hypothesis import strategies as st

from flexmodal.checked_io.text import natural_key, natural_order

DIGITS = "0123456789\u0663\u0660\u06f5"      # Arabic-Indic digits are decimal digits too


@st.composite
def signed_decimals(draw) -> tuple[str, Decimal]:
    """A signed decimal as a person or ``:g`` writes it (leading, trailing zeros allowed), and its value."""
    whole = draw(st.text(st.sampled_from(DIGITS), min_size=1, max_size=12))
    decimals = draw(st.none() | st.text(st.sampled_from(DIGITS), min_size=1, max_size=8))
    text = ("-" if draw(st.booleans()) else "") + whole + ("" if decimals is None else "." + decimals)
    return text, Decimal(text)


@given(st.sampled_from(["theta=", "theta_deg=", "q_", "", "pose "]),
       st.lists(signed_decimals(), min_size=2, max_size=8), st.sampled_from(["", "-impact", ",m=2"]))
def test_signed_decimals_are_ordered_by_value(prefix: str, numbers: list, suffix: str) -> None:
    """Names that differ only in one signed decimal, after ``=``, ``_``, a space or at the start: in the
    order of the values; equal values (``-0``, ``0.00``, ``7.50``, ``007.5``) then as text."""
    names = [prefix + text + suffix for text, _ in numbers]
    value = {prefix + text + suffix: v for text, v in numbers}
    assert sorted(names, key=natural_key) == sorted(names, key=lambda n: (value[n], n))


@given(st.sampled_from(["run-", "theta-", "test-", "theta30-"]), st.lists(st.integers(0, 10**30), min_size=2,
                                                                        max_size=8))
def test_a_hyphen_after_a_letter_or_a_digit_is_no_minus(prefix: str, numbers: list[int]) -> None:
    """``run-1``, ``run-2``, ``run-10``: a label and its number, in rising order (read as minus, the list
    would come out reversed); ``theta30-60``: a range, 60 after 30."""
    names = [f"{prefix}{n}" for n in numbers]
    assert sorted(names, key=natural_key) == sorted(names, key=lambda n: (int(n[len(prefix):]), n))


NAMES = st.text(st.sampled_from(DIGITS + "ab=_-. "), max_size=12)


@given(NAMES, NAMES, NAMES)
def test_the_order_is_total_and_consistent(a: str, b: str, c: str) -> None:
    """Any two names compare (no mixed types: text meets text, numbers meet numbers), equal keys only
    for equal names, and the order is transitive; sorting any arrangement gives one list."""
    ka, kb, kc = natural_key(a), natural_key(b), natural_key(c)
    assert [ka < kb, ka == kb, ka > kb].count(True) == 1
    assert (ka == kb) == (a == b)
    if ka <= kb <= kc:
        assert ka <= kc
    assert sorted([a, b, c], key=natural_key) == sorted([c, a, b], key=natural_key) \
        == sorted([b, c, a], key=natural_key)


def test_the_poses_of_the_review_sort_by_value():
    """The review's list, as ``identify --track`` names modal maps (``theta=-15``) and as configs are
    named with a separator before the sign (``theta_-30``); ``theta-30`` is a hyphen and 30 (the rule,
    stated in ``natural_key``)."""
    poses = ["30", "7.5", "-15", "2.5", "-30", "0", "7.25"]
    ordered = ["-30", "-15", "0", "2.5", "7.25", "7.5", "30"]
    for prefix in ("theta=", "theta_", ""):
        assert natural_order(prefix + p for p in poses) == [prefix + p for p in ordered]
    assert natural_order(["theta-30", "theta30", "theta-15", "theta0"]) == \
        ["theta0", "theta30", "theta-15", "theta-30"]
