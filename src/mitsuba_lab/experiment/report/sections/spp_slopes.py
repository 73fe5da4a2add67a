"""The slope of MSE against spp per strategy and sampler (``spectrum.slope_table``)."""
from __future__ import annotations

from ..spectrum import slope_table


def applies(view) -> bool:
    return any(len({p.spp for p in points}) >= 2 for points in view.groups.values())


def render(view) -> list[str]:
    return slope_table(view.groups, view.label)
