"""Regenerate the numbers docs/diagnosis.md quotes (tests re-run these functions and compare).

    python benchmarks/diagnosis_doc.py                   # print the seed 003 block
    python benchmarks/diagnosis_doc.py --blind --write   # both blocks, written into docs/diagnosis.md

Blocks sit between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->`` (NAME = seed003, blind).  The
blind block is the 36-case run of fixtures/blind.py (seed 0): its per-case table and summary without
the timing line (a measurement that varies; tests/test_blind.py re-runs it under ``-m slow``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "diagnosis.md"
BLIND_CASES = 36

from flexmodal.compare.diagnosis import diagnose  # noqa: E402
from flexmodal.modal.table import ModalTable  # noqa: E402
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
    b, v = split.baseline, split.verdict
    best = next(e for e in split.ranking if (e.effect, e.location) == (v.effect, v.location))
    top = split.ranking[0]
    params = ", ".join(f"{k} = {x:.4g}" for k, x in v.params.items())
    alts = "; ".join(f"{a.effect} at {a.location} ({_pct(a.heldout_rms_rel_error)})"
                     for a in v.alternatives) or "none"
    lv = loo.verdict
    return "\n".join([
        f"Rigid-joint baseline: RMS {_pct(b.rms_rel_error)}, max {_pct(b.max_rel_error)} (f2 at 0°, "
        f"the "
        f"paper's 72 %); `where`: modes {list(split.where.modes)}, region `{split.where.region}`.",
        f"Fitted on 0/60/120° and predicting 30/90/150° (`--holdout theta30,theta90,theta150`), every "
        f"fit refitted without the held-out poses: verdict **{v.effect} at {v.location}** "
        f"({params}; unidentified: {', '.join(v.unidentified_params) or 'none'}), held-out RMS "
        f"{_pct(v.heldout_rms_rel_error_before)} → **{_pct(v.heldout_rms_rel_error_after)}** "
        f"(fit {_pct(best.fit_rms_rel_error)}); explained: {str(v.explained).lower()}.",
        f"Best-scored candidate {top.effect} at {top.location}: {_pct(top.heldout_rms_rel_error)} "
        f"held out, pruned to the verdict because with 6 held-out residuals the difference is within noise; "
        f"alternatives within noise: {alts}.",
        f"Leave one configuration out: {lv.effect} at {lv.location}, "
        f"{_pct(lv.heldout_rms_rel_error_before)} → {_pct(lv.heldout_rms_rel_error_after)}.",
    ])


def blind_block(results: list | None = None, seed: int = 0) -> str:
    """The blind run's per-case table and summary as a fenced block, without the timing line;
    ``results``: those of ``run_blind(BLIND_CASES, seed)`` when already computed."""
    from flexmodal.fixtures.blind import format_summary, format_table, run_blind, summarise

    results = run_blind(BLIND_CASES, seed=seed) if results is None else results
    lines = format_summary(summarise(results)).splitlines()
    body = "\n".join([format_table(results)] + [x for x in lines if not x.startswith("time per case")])
    return f"`fixtures/blind.py`, {len(results)} cases, seed {seed}:\n\n```\n{body}\n```"


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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="replace the blocks in docs/diagnosis.md")
    ap.add_argument("--blind", action="store_true", help="also the 36-case blind run (minutes)")
    args = ap.parse_args()
    blocks = {"seed003": seed003_block()}
    if args.blind:
        blocks["blind"] = blind_block()
    for name, block in blocks.items():
        if args.write:
            write_block(name, block)
        print(block)
    return 0


if __name__ == "__main__":
    sys.exit(main())
