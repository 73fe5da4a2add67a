"""``mitsuba-lab invert CONFIG``: prb inverse-rendering demos and gradient variance against
time. Arguments and command live in ``mitsuba_lab.inverse``."""
from __future__ import annotations


def add_arguments(parser) -> None:
    from .. import inverse

    parser.description = (
        "Run an inverse-rendering config (experiments/inverse_*.toml): optimise the chosen scene "
        "parameters with Mitsuba's prb and Adam from a target rendered with known values, and measure "
        "the gradient's variance against time per sampler and spp. Writes CSV files, plots, images "
        "and a report to OUTDIR.")
    inverse.add_arguments(parser)            # may replace the description with its own


def run(args, out) -> int:
    from .. import inverse

    return inverse.run(args, out)
