"""A warning: points whose MSE is within a few times the reference's noise floor (their errors
are mostly the reference's)."""
from __future__ import annotations

from ..analysis import FLOOR_WARNING_FACTOR


def applies(view) -> bool:
    return any(s.near_floor for s in view.stats)


def render(view) -> list[str]:
    near = [s.point for s in view.stats if s.near_floor]
    return ["", f"**Warning:** {len(near)} point(s) measured an MSE within {FLOOR_WARNING_FACTOR:g}x of "
                f"the reference floor (their errors are mostly the reference's): {', '.join(near)}."]
