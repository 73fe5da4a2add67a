"""What lab_vcm's pilots chose, seed by seed (``tables.pilot_table``)."""
from __future__ import annotations


def applies(view) -> bool:
    return any(any(p.pilots) for points in view.groups.values() for p in points)


def render(view) -> list[str]:
    return view.report.pilot_table(view.groups, view.label)
