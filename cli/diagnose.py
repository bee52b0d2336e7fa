"""`flexmodal diagnose`: sim-to-real gap diagnosis (docs/formats.md) and its blind self-check."""

from __future__ import annotations

import argparse
import sys

from flexmodal.checked_io import options as opt

DIAGNOSIS_FILES = ("diagnosis.json", "diagnosis.html")  # what `diagnose` writes into its --out folder


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``diagnose`` to the flexmodal parser."""
    p = sub.add_parser(
        "diagnose", help="sim-to-real gap diagnosis: where, which unmodelled effect, held-out improvement",
        description="Compare a nominal rig's FE modes with measured modes over several poses, rank every "
                    "unmodelled effect (docs/formats.md) at every location and pairs of them by their error "
                    "on held-out configurations, and write DIR/diagnosis.json and DIR/diagnosis.html.")
    p.add_argument("--rig", help="nominal rig description (TOML, docs/formats.md)")
    p.add_argument("--measured",
                   help="measured modes (modal table CSV, docs/formats.md) with pose.<var> columns")
    p.add_argument("--out", help="output directory for diagnosis.json and diagnosis.html")
    p.add_argument("--effects", default="all", help="'all' or comma-separated effect names (default all)")
    p.add_argument("--holdout", default="auto",
                   help="'auto' (leave one configuration out; 5-fold above 10 configurations) or a "
                        "comma-separated list of configurations to hold out")
    p.add_argument("--scatter", type=opt.real(0.0, 1.0, lo_open=True, hi_open=True, name="fraction"),
                   default=None,
                   help="fallback relative measurement scatter of the frequencies (fraction; default 0.005 = "
                        "0.5 %%), used only when the table has no repeated configurations and no "
                        "freq_std_hz column")
    p.add_argument("--selftest", type=opt.integer(1, 100000), metavar="N",
                   help="blind self-check instead: N random rigs simulated by an independent truth model "
                        "(Timoshenko frame) with withheld effects; prints accuracy")
    p.add_argument("--seed", type=opt.seed, default=0, help="random seed of --selftest (default 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from flexmodal.api import CompareError

    if args.selftest is not None:
        from flexmodal.api import selftest

        def show(r) -> None:
            c, v = r.case, r.verdict
            print(f"{c.kind}/{c.category}: hidden {c.effect}@{c.location or '-'} -> {v.effect}@"
                  f"{v.location or '-'} ({r.seconds:.1f} s)", file=sys.stderr)

        check = selftest(args.selftest, seed=args.seed, progress=None if getattr(args, "quiet", False)
                         else show)
        print(check.text)
        return 0
    missing = [o for o in ("rig", "measured", "out") if getattr(args, o) is None]
    if missing:
        raise CompareError(f"diagnose: missing --{missing[0]} "
                           "(needs --rig, --measured and --out, or --selftest N)")
    from flexmodal.checked_io.output import output_dir

    output_dir(args.out, CompareError, "diagnosis folder (--out)", files=DIAGNOSIS_FILES,
               inputs=(args.rig, args.measured))  # before the heavy imports
    from flexmodal.api import diagnose, load_rig, read_table, write_diagnosis
    from flexmodal.compare.candidates import parse_effects
    from flexmodal.compare.diagnosis import folds_for
    from flexmodal.compare.verdict_text import scatter_line, verdict_words

    rig = load_rig(args.rig)
    table = read_table(args.measured)
    parse_effects(args.effects)  # bad --effects / --holdout fail before the progress line
    folds_for(table.configs, args.holdout)
    if not getattr(args, "quiet", False):
        print(f"diagnosing {table.source} against {rig.source} ...", file=sys.stderr)
    result = diagnose(rig, table, effects=args.effects, holdout=args.holdout, scatter=args.scatter)
    pj, ph = write_diagnosis(result, args.out, inputs=[rig.source, table.source])
    v = result.verdict
    print(f"verdict: {v.effect} at {v.location or '-'}; held-out RMS "
          f"{v.heldout_rms_rel_error_before:.2%} -> {v.heldout_rms_rel_error_after:.2%}")
    if verdict_words(result):
        print(verdict_words(result))
    print(scatter_line(result))
    for name, (lo, hi) in (v.param_intervals or {}).items():
        print(f"  {name} = {v.params[name]:.4g}  (95 % interval {lo:.4g} .. {hi:.4g})")
    if v.residual_feature or v.flags:
        print(f"remaining: {v.residual_feature or '-'}" + "".join(f"; flagged: {f}" for f in v.flags or ()))
    if v.ranked and v.ranked > 1:
        print(f"not the top of the ranking ({v.ranked}): {v.why_not_top}")
    if v.next_measurements:
        print("next measurement: " + "; ".join(f"{x.pose} (mode {x.mode}, {x.information_nats:.1f} nats)"
                                               for x in v.next_measurements))
    print(pj)
    print(ph)
    return 0
