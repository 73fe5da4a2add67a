"""``mitsuba-lab sweep CONFIG``: a strategy sweep against cached references, and its report."""
from __future__ import annotations


def add_arguments(parser) -> None:
    parser.description = ("Run every point of an experiment config (scenes x strategies x samplers x "
                          "spp / time budgets, R seeds each) against cached references, store one row "
                          "per render, and write the report. A killed sweep resumes where it stopped. "
                          "Config schema: experiments/README.md.")
    parser.add_argument("config", help="experiment TOML file")
    parser.add_argument("-o", "--output", help="output folder (default: the config's experiment.output)")
    parser.add_argument("--cluster", metavar="ADDRESS",
                        help="run the points on a Dask distributed cluster, e.g. tcp://host:8786 "
                             "(needs the 'distributed' extra; overrides the config's [executor] cluster)")
    parser.add_argument("--dry-run", action="store_true",
                        help="print the plan, left-out strategies and why, and an estimated cost (from a "
                             "short pilot render per scene), and render nothing else; exit status 2 when "
                             "nothing would run")


def run(args, out) -> int:
    from ..experiment import sweep

    return sweep.sweep_command(args.config, args.output, args.dry_run, out, args.cluster)
