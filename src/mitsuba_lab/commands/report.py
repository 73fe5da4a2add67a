"""``mitsuba-lab report OUTDIR [--figure]``: rebuild a sweep's report from its stored results,
and with ``--figure`` a publication figure per scene (no variant: nothing renders)."""
from __future__ import annotations

import argparse


def positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def add_arguments(parser) -> None:
    parser.description = ("Rebuild OUTDIR/results.csv and OUTDIR/report/ from OUTDIR/results.jsonl and "
                          "the stored images; renders nothing.")
    parser.add_argument("folder", help="a sweep's output folder")
    parser.add_argument("--figure", action="store_true",
                        help="also write a publication figure per scene (PDF and PNG): the equal-time image "
                             "grid with region crops and their relMSE, and relMSE against time")
    parser.add_argument("--figure-dir", metavar="DIR",
                        help="where the figures go (default OUTDIR/report/figures; implies --figure)")
    parser.add_argument("--budget", type=positive_seconds, metavar="SECONDS",
                        help="the figure's equal-time comparison: the one nearest this time (default: the "
                             "middle one)")


def run(args, out) -> int:
    import os

    from ..experiment.report.build import Report, check_sweep_folder

    check_sweep_folder(args.folder)
    report = Report(args.folder)
    paths = report.write()
    print(f"wrote {paths['html']}, {paths['md']} and {paths['csv']}", file=out)
    if args.figure or args.figure_dir or args.budget is not None:
        from ..experiment.report.figure import write_figures

        figures = write_figures(report, args.figure_dir or os.path.join(report.out, "figures"), args.budget)
        print("wrote " + ", ".join(figures), file=out)
    return 0
