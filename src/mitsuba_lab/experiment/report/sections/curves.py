"""relMSE against time, one curve per strategy (and sampler)."""
from __future__ import annotations

import os


def applies(view) -> bool:
    return bool(view.groups)


def render(view) -> list[str]:
    plot = view.report.plot_curves(view.scene, view.groups, view.label)
    return ["", f"![relMSE against time]({os.path.basename(plot)})"]
