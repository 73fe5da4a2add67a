"""The scene's comparison viewer (``report.viewer``): HTML only, summary.md gets an invisible
marker. Nothing where no comparison set exists."""
from __future__ import annotations


def applies(view) -> bool:
    return bool(view.stats)


def render(view) -> list[str]:
    return view.report.viewer_marker(view.scene, view.stats)
