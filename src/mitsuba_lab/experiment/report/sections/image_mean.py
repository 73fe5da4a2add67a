"""Each strategy's image mean over the reference's, with its interval (``bias.mean_table``)."""
from __future__ import annotations


def applies(view) -> bool:
    return bool(view.groups)


def render(view) -> list[str]:
    return view.report.mean_table(view.groups, view.label)
