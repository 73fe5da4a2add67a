"""Each strategy's longest point, ranked by efficiency (``tables.efficiency_table``)."""
from __future__ import annotations


def applies(view) -> bool:
    return bool(view.groups)


def render(view) -> list[str]:
    return view.report.efficiency_table(view.groups, view.label)
