"""How often the ``none`` gate's overrule fires on fresh cases without an effect (compare/diagnosis.py).

    python benchmarks/none_gate.py                       # seeds 880001 (120 cases), 880002 (300): ~15 min
    python benchmarks/none_gate.py --runs 880003:50      # other draws

A gap within the noise is declared ``none`` unless a single predicts the held-out poses better than the
nominal model beyond the noise margin and beyond the beam theory's known error (``_beating_nominal``
with ``form``, docs/diagnosis.md item 6).  Each case is ``make_case(rng, "none", kind)`` of
fixtures/blind.py (no effect hidden; the five rigs in turn, the truth model's frequencies with repeat
scatter), diagnosed in full; per run: the cases, those whose gap was small enough to ask the gate, the
cases where it fired, and the ``none`` verdicts.  tests/test_diagnosis_weak.py re-runs every run of
``RUNS`` under ``-m slow`` and compares with the numbers its docstring quotes.
"""

from __future__ import annotations

import argparse
import inspect
import sys
from typing import NamedTuple
from unittest import mock

import numpy as np
from threadpoolctl import threadpool_limits

import flexmodal.compare.diagnosis as diagnosis
from flexmodal.fixtures.blind import KINDS, make_case

RUNS = ((880001, 120), (880002, 300))
"""(seed, cases) of the fresh ``none`` cases tests/test_diagnosis_weak.py quotes."""


class GateCount(NamedTuple):
    """Of ``cases`` cases without an effect: ``asked`` had a gap small enough to ask the gate, ``fired``
    (their indices) where a single overruled the gap test, and ``none`` verdicts."""

    cases: int
    asked: int
    fired: tuple[int, ...]
    none: int


def gate_count(seed: int, cases: int) -> GateCount:
    """The gate on ``cases`` fresh ``none`` cases of ``seed`` (the rigs of fixtures/blind.py in turn)."""
    beating = diagnosis._beating_nominal
    signature = inspect.signature(beating)
    calls: list[bool] = []

    def recording(*args, **kwargs):
        out = beating(*args, **kwargs)
        if "form" in signature.bind(*args, **kwargs).arguments:   # the gate (the alternatives pass none)
            calls.append(bool(out))
        return out

    rng = np.random.default_rng(seed)
    asked, fired, none = 0, [], 0
    with mock.patch.object(diagnosis, "_beating_nominal", recording):
        for i in range(cases):
            with threadpool_limits(limits=1, user_api="blas"):    # as run_blind makes its cases
                case = make_case(rng, "none", KINDS[i % len(KINDS)])
            calls.clear()
            none += diagnosis.diagnose(case.rig, case.table).verdict.effect == "none"
            asked += bool(calls)
            fired += [i] if any(calls) else []
    return GateCount(cases, asked, tuple(fired), none)


def line(seed: int, count: GateCount) -> str:
    return (f"seed {seed}: {count.cases} cases without an effect, the gate asked on {count.asked}, fired on "
            f"{len(count.fired)}{' (#' + ', #'.join(map(str, count.fired)) + ')' if count.fired else ''}; "
            f"verdict none {count.none}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=lambda t: tuple(tuple(int(x) for x in r.split(":")) for r in t.split(",")),
                    default=RUNS, help="comma-separated seed:cases (default 880001:120,880002:300)")
    for seed, cases in ap.parse_args().runs:
        print(line(seed, gate_count(seed, cases)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
