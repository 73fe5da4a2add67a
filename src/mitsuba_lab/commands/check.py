"""``mitsuba-lab check [SCENES...]``: the stiff scenes with every applicable lab strategy
against path. Arguments and command live in ``mitsuba_lab.check``."""
from __future__ import annotations


def add_arguments(parser) -> None:
    from .. import check

    parser.description = (
        "Render every scene (default: scenes/stiff/*.xml) with every lab strategy that applies and "
        "with Mitsuba's path as the reference; report NaN/Inf/negative pixels, fireflies and z-scores "
        "of the means; write CSV + HTML. Exit status 1 when a strategy produces NaN, Inf or negative "
        "values or a mean off the reference where it claims to be unbiased.")
    check.add_arguments(parser)              # may replace the description with its own


def run(args, out) -> int:
    from .. import check

    return check.run(args, out)
