"""Per region, every strategy at each time budget (``tables.region_budget_tables``)."""
from __future__ import annotations


def applies(view) -> bool:
    return bool(view.ref.meta.get("regions")) and any(s.budget_s is not None for s in view.stats)


def render(view) -> list[str]:
    return view.report.region_budget_tables(view.scene, view.stats, view.label)
