"""Per region of interest, each strategy's relMSE and efficiency (``tables.region_tables``)."""
from __future__ import annotations


def applies(view) -> bool:
    return any(p.regions for points in view.groups.values() for p in points)


def render(view) -> list[str]:
    return view.report.region_tables(view.scene, view.groups, view.label)
