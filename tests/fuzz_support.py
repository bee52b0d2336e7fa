"""Shared pieces of the fuzz suites (tests/test_fuzz_*.py): profiles and the escape check.

Every fuzz property runs twice: a bounded profile in the default test run (a fixed seed, so CI is
reproducible; the whole default fuzz run stays under 60 s) and a long profile marked ``slow`` (random
seeds, at least 10^3 inputs per loader).  A property fails when any exception other than the loader's
package error type escapes; pytest-timeout turns a hang into a failure.
"""

from __future__ import annotations

from collections.abc import Callable

from hypothesis import HealthCheck, given, settings
from hypothesis.strategies import SearchStrategy

LONG_EXAMPLES = 1000


def prop(*strategies: SearchStrategy) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Mark a property with the strategies of its arguments (a fresh ``@given`` test per profile)."""
    def mark(fn: Callable[..., None]) -> Callable[..., None]:
        fn.strategies = strategies  # type: ignore[attr-defined]
        return fn
    return mark


def run_profile(fn: Callable[..., None], examples: int, *, long: bool = False) -> None:
    """Run property ``fn`` (see :func:`prop`) for ``examples`` inputs (reproducible unless ``long``)."""
    test = given(*fn.strategies)(fn)  # type: ignore[attr-defined]
    settings(max_examples=examples, deadline=None, database=None, derandomize=not long,
             suppress_health_check=list(HealthCheck))(test)()
