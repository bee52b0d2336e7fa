"""Regenerate the numbers docs/diagnosis.md quotes (tests re-run these functions and compare).

    python benchmarks/diagnosis_doc.py                   # print the seed 003 block
    python benchmarks/diagnosis_doc.py --coverage --blind --write   # every block, into docs/diagnosis.md

Blocks sit between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->`` (NAME = seed003, coverage,
sparse, and per draw set of ``DRAW_SETS`` its name and ideal block, per ``ADVICE_SETS`` key an advice
block).  The last draw set is the acceptance measurement: 36 cases of each of five draws of
fixtures/blind.py's generator never used before (seeds ``FINAL_SEEDS``), their summaries and the mean
and worst over draws (tests/test_blind.py re-runs every draw set under ``-m slow``); the coverage block
the Monte-Carlo coverage of the identification's intervals (tests/test_modal_uncertainty.py re-runs it
under ``-m slow``).
"""

from __future__ import annotations

import argparse
import sys
from functools import partial
from pathlib import Path
from typing import NamedTuple

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "diagnosis.md"
BLIND_CASES = 36
class DrawSet(NamedTuple):
    """Five draws of fixtures/blind.py's generator quoted in docs/diagnosis.md: the block ``name``, its
    ideal-fit block ``ideal``, the ``seeds`` and the header ``note`` saying what the draws were used for."""

    name: str
    ideal: str
    seeds: tuple[int, ...]
    note: str


USED_SEEDS = (106, 107, 108, 109, 110, 211, 212, 213, 214, 215, 316, 317, 318, 319, 320,
              421, 422, 423, 424, 425, 526, 527, 528, 529, 530, 631, 632, 633, 634, 635,
              736, 737, 738, 739, 740, 841, 842, 843, 844, 845, 946, 947, 948, 949, 950,
              1051, 1052, 1053, 1054, 1055, 1156, 1157, 1158, 1159, 1160, 1261, 1262, 1263, 1264, 1265,
              1366, 1367, 1368, 1369, 1370, 1471, 1472, 1473, 1474, 1475,
              1576, 1577, 1578, 1579, 1580, 1681, 1682, 1683, 1684, 1685,
              1786, 1787, 1788, 1789, 1790, 1891, 1892, 1893, 1894, 1895,
              1996, 1997, 1998, 1999, 2000)
"""Every draw of the generator used to develop the method so far (each first run once as the blind
figure of a change, then analysed for a later one): a blind figure needs seeds outside these.  The
figures of the versions that were measured on them are in docs/diagnosis.md's history table."""

DRAW_SETS = (
    DrawSet("s2101", "ideal_s2101", (2101, 2102, 2103, 2104, 2105),
            "run once, after the last change to the method; never used to develop it"),
)
"""The draw sets docs/diagnosis.md quotes, run with the current method: the blind figure of the current
method (five draws never used before its measurement)."""
DRAWS = {d.name: d for d in DRAW_SETS}
FINAL_SEEDS = DRAW_SETS[-1].seeds
SPARSE_CASES = 60
SPARSE_SEED = 5
ADVICE_SETS = {"advice_s2101": FINAL_SEEDS}
"""Blocks of the next-measurement advice measured on the ambiguous verdicts of the draw sets: the blind
set (the advice measured once on it, never used for the advice)."""

from flexmodal.compare.diagnosis import diagnose  # noqa: E402
from flexmodal.contract.table import ModalTable  # noqa: E402
from flexmodal.models.rig import load_rig  # noqa: E402


def seed003_table(data: Path) -> ModalTable:
    """Seed 003 Table 3 (f1, f2 at six elbow angles, from ``data``/seeds) as a modal table."""
    t3 = pd.read_csv(data / "seeds" / "seed003_table3_experimental.csv")
    recs = [{"config": f"theta{int(r.theta_deg)}", "mode": m, "freq_hz": r[f"f{m}_hz"],
             "source": "experiment", "pose.theta_deg": r.theta_deg} for _, r in t3.iterrows() for m in (1, 2)]
    return ModalTable.from_records(recs, "seed003 Table 3")


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def seed003_block(data: Path = REPO / "tests" / "data") -> str:
    """The markdown paragraph of seed 003's diagnosis, every number computed now."""
    rig = load_rig(REPO / "examples" / "rigs" / "seed003_two_link.toml")
    table = seed003_table(data)
    split = diagnose(rig, table, holdout="theta30,theta90,theta150")
    loo = diagnose(rig, table)
    b = split.baseline

    def verdict(res) -> str:
        v = res.verdict
        entry = res.verdict_score()
        params = ", ".join(f"{k} = {x:.4g} [{v.param_intervals[k][0]:.4g}, {v.param_intervals[k][1]:.4g}]"
                           for k, x in v.params.items())
        alts = "; ".join(f"{a.effect} at {a.location} ({_pct(a.heldout_rms_rel_error)})"
                         for a in v.alternatives) or "none"
        why = f" ({v.why_not_top})" if v.why_not_top else ""
        return (f"verdict **{v.effect} at {v.location}** (ranked {v.ranked}{why}; {params}; unidentified: "
                f"{', '.join(v.unidentified_params) or 'none'}), held-out RMS "
                f"{_pct(v.heldout_rms_rel_error_before)} → **{_pct(v.heldout_rms_rel_error_after)}** (fit "
                f"{_pct(entry.fit_rms_rel_error)}; {v.grade}, {100 * v.gap_removed:.0f} % of the gap "
                f"removed; "
                f"ranking scatter {_pct(res.scatter)}, its model-form floor); alternatives within noise: "
                f"{alts}; remaining feature: {v.residual_feature or 'none'}")

    return "\n".join([
        f"Rigid-joint baseline: RMS {_pct(b.rms_rel_error)}, max {_pct(b.max_rel_error)} (f2 at 0°, "
        f"the paper's 72 %); `where`: modes {list(split.where.modes)}, region `{split.where.region}`.",
        f"Fitted on 0/60/120° and predicting 30/90/150° (`--holdout theta30,theta90,theta150`), every "
        f"fit refitted without the held-out poses: {verdict(split)}.",
        f"Leave one pose out: {verdict(loo)}.",
        "Parameters with their 95 % intervals in brackets (`verdict.param_intervals`).",
    ])


def blind_block(seeds: tuple[int, ...] = FINAL_SEEDS, cases: int = BLIND_CASES,
                results: dict | None = None,
                note: str = DRAW_SETS[-1].note) -> str:
    """The acceptance measurement: ``cases`` blind cases of each of the draws ``seeds`` (one draw of
    fixtures/blind.py's generator each: new rigs, poses, magnitudes, scatter), each draw's summary and
    misses, then the mean and worst over draws, as a fenced block (no timing); ``results`` {seed:
    run_blind's results} when already computed."""
    from flexmodal.fixtures.blind import format_draws, format_summary, run_blind, summarise

    parts, draws = [], []
    for seed in seeds:
        s = summarise(results[seed] if results else run_blind(cases, seed=seed))
        draws.append(s)
        lines = [x for x in format_summary(s).splitlines() if not x.startswith("time per case")]
        parts.append(f"draw seed {seed}:\n" + "\n".join("  " + x for x in lines))
    body = "\n".join(parts + [format_draws(draws)])
    return (f"`fixtures/blind.py`, {cases} cases in each of {len(seeds)} draws (seeds "
            f"{', '.join(map(str, seeds))}; {note}):\n\n"
            f"```\n{body}\n```")


def ideal_block(results: dict | None = None, seeds: tuple[int, ...] = FINAL_SEEDS,
                cases: int = BLIND_CASES) -> str:
    """The blind count with issue 26's ideal-fit rule (fixtures/blind.py ``with_ideal_fit``): a wrong
    top-1 flagged ambiguous with the truth among its alternatives is right only where an ideal fit
    cannot decide; per draw of ``seeds`` and every case checked, as a fenced block; ``results`` {seed:
    run_blind's results} when already computed."""
    from flexmodal.fixtures.blind import format_ideal_fit, run_blind, with_ideal_fit

    results = results or {seed: run_blind(cases, seed=seed) for seed in seeds}
    return f"```\n{format_ideal_fit({s: with_ideal_fit(results[s]) for s in seeds})}\n```"


def sparse_block(results: list | None = None, n: int = SPARSE_CASES, seed: int = SPARSE_SEED) -> str:
    """Next-measurement advice where it is needed: ``n`` cases of one library effect measured at three
    poses only (fixtures/blind.py ``sparse_case``), every ambiguous verdict measured once more at its
    advised pose and at two random untested poses, as a fenced block; ``results`` run_sparse's."""
    from flexmodal.fixtures.blind import advice_trials, format_advice, run_sparse

    results = run_sparse(n, seed) if results is None else results
    amb = sum(bool(r.verdict.ambiguous) for r in results)
    return (f"```\n{n} cases (seed {seed}), 3 poses x 2 modes: {amb} ambiguous verdicts\n"
            f"{format_advice(advice_trials(results, seed=seed))}\n```")


def advice_block(results: dict | None = None, seeds: tuple[int, ...] = FINAL_SEEDS,
                 cases: int = BLIND_CASES) -> str:
    """Next-measurement advice on the blind draws ``seeds`` (``cases`` each): every ambiguous library
    verdict measured once more at its advised pose and at three random untested poses (fixtures/blind.py
    ``advice_trials``), pooled over the draws, as a fenced block; ``results`` {seed: run_blind's
    results} when already computed."""
    from flexmodal.fixtures.blind import advice_trials, format_advice, run_blind

    trials = [t for s in seeds
              for t in advice_trials(results[s] if results else run_blind(cases, seed=s), seed=s)]
    return (f"```\n{cases} cases in each of {len(seeds)} draws (seeds {', '.join(map(str, seeds))}): "
            f"{len(trials)} ambiguous library verdicts\n{format_advice(trials)}\n```")


def coverage_block() -> str:
    """Monte-Carlo coverage of the identification's 95 % intervals, EMA and output-only
    (fixtures/modal_coverage.py ``coverage_block``), as a fenced block."""
    from flexmodal.fixtures.modal_coverage import coverage_block as block

    return block()


def doc_block(name: str) -> str:
    """The block ``name`` as it stands in docs/diagnosis.md."""
    text = DOC.read_text()
    return text.partition(f"<!-- {name}:begin -->\n")[2].partition(f"\n<!-- {name}:end -->")[0]


def write_block(name: str, block: str) -> None:
    text = DOC.read_text()
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    head, _, rest = text.partition(begin)
    _, _, tail = rest.partition(end)
    DOC.write_text(f"{head}{begin}\n{block}\n{end}{tail}")


BLOCKS = {"seed003": seed003_block, "coverage": coverage_block, "sparse": sparse_block}
for _draws in DRAW_SETS:
    BLOCKS[_draws.name] = partial(blind_block, _draws.seeds, note=_draws.note)
    BLOCKS[_draws.ideal] = partial(ideal_block, seeds=_draws.seeds)
for _name, _seeds in ADVICE_SETS.items():
    BLOCKS[_name] = partial(advice_block, seeds=_seeds)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="replace the blocks in docs/diagnosis.md")
    ap.add_argument("--blind", action="store_true", help="also the 5-draw blind measurement (long)")
    ap.add_argument("--coverage", action="store_true", help="also the identification's Monte-Carlo coverage")
    ap.add_argument("--only", choices=sorted(BLOCKS), help="this block alone (e.g. one per process)")
    args = ap.parse_args()
    if args.only:
        blocks = {args.only: BLOCKS[args.only]()}
    else:
        blocks = {"seed003": seed003_block()}
        if args.coverage:
            blocks["coverage"] = coverage_block()
        if args.blind:
            blocks.update((name, BLOCKS[name]())
                          for name in [d.name for d in DRAW_SETS] + ["sparse", *ADVICE_SETS])
    for name, block in blocks.items():
        if args.write:
            write_block(name, block)
        print(block)
    return 0


if __name__ == "__main__":
    sys.exit(main())
