"""The parts of a scene's section in the sweep report, each a module with two functions:
``applies(view) -> bool``, whether the scene's data call for it at all, and ``render(view)``, its
Markdown lines (which may still be none once computed: no balance heuristic for Veach's bound, no
spectrum to plot). ``view`` is a ``SceneView``. ``SECTIONS`` lists them once, in the order they
appear on the page."""
from __future__ import annotations

from dataclasses import dataclass

from . import (bias, comparison_viewer, curves, efficiency, equal_time, error_spectra, image_mean, image_strip,
               near_floor, passes, pilots, region_budgets, regions, spp_slopes, veach_bound)

SECTIONS = (near_floor, comparison_viewer, curves, efficiency, equal_time, image_mean, bias, passes, spp_slopes,
            error_spectra, regions, region_budgets, pilots, veach_bound, image_strip)


@dataclass
class SceneView:
    """What a section reads of one scene: the ``Report`` (its tables and loaded state), the scene's
    name, its points (``PointStats``, sorted by strategy, sampler and time), those grouped by
    (strategy, sampler), the label a group is shown by, and the scene's Reference."""
    report: object
    scene: str
    stats: list
    groups: dict
    label: object
    ref: object


def render_scene(view: SceneView) -> list[str]:
    """The Markdown lines of every section that applies, in order."""
    lines = []
    for section in SECTIONS:
        if section.applies(view):
            lines += section.render(view)
    return lines
