"""``mitsuba-lab theory``: eight worked Monte Carlo problems (P1-P8), predicted against measured (no variant)."""
from __future__ import annotations


def add_arguments(parser) -> None:
    parser.description = ("Run eight toy estimators (uniform MC, importance sampling, cosine "
                          "sampling, MIS weights and MIS, Russian roulette, delta and ratio "
                          "tracking, equi-angular and distance sampling, a Metropolis-Hastings "
                          "chain) and print predicted "
                          "against measured values. Exit status 1 when a measurement misses its "
                          "stated tolerance.")
    parser.add_argument("--json", action="store_true",
                        help='print a JSON list of {"problem", "quantity", "predicted", "measured", '
                             '"tolerance", "note"} rows instead of a table')
    parser.add_argument("--quick", action="store_true", help="about 10x fewer trials (seconds)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")


def run(args, out) -> int:
    import json

    from .. import theory

    rows = theory.run_all(seed=args.seed, quick=args.quick)
    print(json.dumps(rows, indent=1) if args.json else theory.format_table(rows), file=out)
    return 1 if theory.check(rows) else 0
