"""Bias^2 and variance of every point (``bias.bias_table``)."""
from __future__ import annotations


def applies(view) -> bool:
    return True             # (a header row even without points, as the report always had)


def render(view) -> list[str]:
    return view.report.bias_table(view.stats)
