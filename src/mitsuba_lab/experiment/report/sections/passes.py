"""Bias^2 and variance against passes for the consistent strategies (lab_photon's passes,
lab_vcm's iterations; ``tables.passes_section``); nothing for the unbiased ones."""
from __future__ import annotations


def applies(view) -> bool:
    return any(len(points) >= 2 for points in view.groups.values())


def render(view) -> list[str]:
    return view.report.passes_section(view.scene, view.groups, view.label)
