"""The reference and each strategy's render at about equal time, with their error and
signed-difference maps (``strip``)."""
from __future__ import annotations

import os

import numpy as np

from ....reporting.figures import save_figure
from ...pipeline.budget import missed_budget
from ..analysis import run_image
from ..strip import strip_figure, strip_points, strip_title


def applies(view) -> bool:
    return bool(view.groups)


def render(view) -> list[str]:
    report, ref = view.report, view.ref
    picks, title = strip_points(view.groups, view.label)
    chosen = []
    for key, pick in picks.items():
        mean = np.mean([run_image(report.folder, path) for path in pick.images], axis=0)
        name = strip_title(view.label(key), pick.spp, pick.time_s) + ("\n(off budget)" if missed_budget(pick) else "")
        chosen.append((name, run_image(report.folder, pick.images[0]), mean))
    height, width = ref.image.shape[:2]
    fig = strip_figure(ref.image, ref.variance, chosen, report._regions(view.scene, width, height))
    strip = save_figure(fig, os.path.join(report.out, f"{view.scene}_images.png"))
    return ["", f"![{title}]({os.path.basename(strip)})",
            "", "Under each render: its relative error |x - ref| / (|ref| + 0.01) (one seed), then the signed "
                "difference of its mean over the seeds from the reference (red above, blue below, one "
                "symmetric range for all): noise averages out of the mean, bias stays."]
