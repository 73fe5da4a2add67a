"""``mitsuba-lab report OUTDIR``: rebuild a sweep's report from its stored results (no variant)."""
from __future__ import annotations


def add_arguments(parser) -> None:
    parser.description = ("Rebuild OUTDIR/results.csv and OUTDIR/report/ from OUTDIR/results.jsonl and "
                          "the stored images; renders nothing.")
    parser.add_argument("folder", help="a sweep's output folder")


def run(args, out) -> int:
    from ..experiment.report import build_report

    paths = build_report(args.folder)
    print(f"wrote {paths['html']}, {paths['md']} and {paths['csv']}", file=out)
    return 0
