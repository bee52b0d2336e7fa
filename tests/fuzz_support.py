"""Shared pieces of the fuzz suites (tests/test_fuzz_*.py): profiles and the escape check.

Every fuzz property runs twice: a bounded profile in the default test run (a fixed seed, so CI is
reproducible; the whole default fuzz run stays under 60 s) and a long profile marked ``slow`` (random
seeds, at least 10^3 inputs per loader).  A property fails when any exception other than the loader's
package error type escapes; pytest-timeout turns a hang into a failure.
"""

from __future__ import annotations

from collections.abc import Callable

from hypothesis import HealthCheck, settings

LONG_EXAMPLES = 1000


def run_profile(prop: Callable[[], None], examples: int, *, long: bool = False) -> None:
    """Run a ``@given`` property for ``examples`` inputs (reproducible unless ``long``)."""
    settings(max_examples=examples, deadline=None, database=None, derandomize=not long,
             suppress_health_check=list(HealthCheck))(prop)()
