"""Veach's bound: lab_mis's balance heuristic against its other weightings (``veach``); nothing
where no balance heuristic ran."""
from __future__ import annotations


def applies(view) -> bool:
    return any(view.report._integrator(points[0]) == "lab_mis" for points in view.groups.values() if points)


def render(view) -> list[str]:
    return view.report.veach_table(view.scene, view.groups)
