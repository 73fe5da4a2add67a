"""The strategies at equal time: at each time budget, or their curves interpolated at times all
of them cover (``tables.equal_time_table``). One strategy has nothing to compare."""
from __future__ import annotations


def applies(view) -> bool:
    return len(view.groups) >= 2


def render(view) -> list[str]:
    return view.report.equal_time_table(view.groups, view.label)
