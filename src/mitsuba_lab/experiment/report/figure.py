"""Publication figures of a sweep (``mitsuba-lab report OUTDIR --figure``), one per scene.

Left: the equal-time image grid, the reference and each strategy's render of one comparison
set (``comparisons``), the scene's regions outlined, and under each image the crops of the
regions enlarged, with the relMSE of each crop under it. Right: relMSE (reference floor
subtracted) against wall time for every strategy, the shown renders circled. Written as PDF
(vector text, fonts embedded as TrueType) and PNG, from stored results only.
"""
from __future__ import annotations

import math
import os

import numpy as np

from ... import images
from ...errors import LabError
from ...images import atomic_path
from ...reporting import fmt, pyplot
from ...reporting.figures import legend_outside, series_styles
from ..pipeline.budget import missed_budget
from .comparisons import comparison_sets, default_set, group_points, region_rel_mse, relative_error, shown_image
from .viewer import crop_exposure

#: A column of the image grid, and the plot's width, in inches.
COLUMN_IN = 1.15
PLOT_IN = 2.9
REGION_COLOURS = ("#00e5ff", "#ffd400", "#ff4fd8", "#7dff4f", "#ff8a00", "#4f8dff")
STYLE = {"font.size": 6.5, "axes.titlesize": 6.5, "axes.labelsize": 6.5, "legend.fontsize": 5.5,
         "xtick.labelsize": 5.5, "ytick.labelsize": 5.5, "pdf.fonttype": 42, "ps.fonttype": 42}


def pick_set(sets, budget: float | None):
    """The comparison set shown: the equal-time set nearest ``budget`` (log scale; a budget's set
    by its budget, not by the times its points took), or the default one
    (``comparisons.default_set``)."""
    if budget is None:
        return sets[default_set(sets)]
    timed = [s for s in sets if s.kind == "time"]
    if not timed:
        return sets[default_set(sets)]
    times = lambda s: s.budget_s or float(np.median([p.time_s for _, p in s.entries]))   # noqa: E731
    return min(timed, key=lambda s: abs(math.log(times(s) / budget)))


def _image_axis(ax, pixels, title=None, colour="black"):
    ax.imshow(pixels, interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    for side in ax.spines.values():
        side.set_linewidth(0.4)
    if title:
        ax.set_title(title, color=colour, pad=2)


def build_figure(report, scene: str, budget: float | None = None):
    """The figure of one scene (a matplotlib Figure; None when the scene has no comparison
    set); ``scene_figure`` writes it."""
    plt = pyplot()
    from matplotlib.patches import Rectangle

    groups, label = group_points(report.stats[scene])
    sets = comparison_sets(groups, label)
    if not sets:
        return None
    chosen = pick_set(sets, budget)
    ref = report.references[scene]
    height, width = ref.image.shape[:2]
    regions = report._regions(scene, width, height)
    styles, how = series_styles(groups, ("strategy", "sampler"))     # as in the report's plots
    colours = {label(k): style.colour for k, style in styles.items()}
    columns = [("reference", None)] + chosen.entries
    n, rows = len(columns), 1 + len(regions)
    crop_ratio = [max(0.25, min(1.0, (r[3] - r[1]) / (r[2] - r[0]))) for r in regions.values()]
    image_h = COLUMN_IN * height / width
    heights = [image_h] + [COLUMN_IN * 0.62 * c for c in crop_ratio]
    with plt.rc_context(STYLE):
        fig = plt.figure(figsize=(n * COLUMN_IN + PLOT_IN + 0.6, max(sum(heights) + 0.3 * rows + 0.4, 2.4)))
        outer = fig.add_gridspec(1, 2, width_ratios=[n * COLUMN_IN, PLOT_IN], wspace=0.12 + 0.6 / n)
        grid = outer[0].subgridspec(rows, n, height_ratios=heights, wspace=0.08, hspace=0.3)
        for col, (name, point) in enumerate(columns):
            image = ref.image if point is None else shown_image(report.folder, point)
            ax = fig.add_subplot(grid[0, col])
            _image_axis(ax, images.srgb_preview(image), name, "black" if point is None else colours[name])
            for (rname, (x0, y0, x1, y1)), c in zip(regions.items(), REGION_COLOURS * 4):
                ax.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False, color=c, lw=0.6))
            if point is None:
                ax.set_xlabel(f"{ref.meta.get('spp')} spp", labelpad=2)
            else:
                own = float(np.mean(relative_error(image, ref.image) ** 2))
                off = f"\noff its {point.budget_s:g} s budget" if missed_budget(point) else ""
                ax.set_xlabel(f"{point.spp} spp, {point.time_s:.2g} s{off}\nrelMSE {fmt(own, 2)}", labelpad=2)
            for row, ((rname, rect), c) in enumerate(zip(regions.items(), REGION_COLOURS * 4), 1):
                x0, y0, x1, y1 = rect
                offset = crop_exposure(ref.image, rect)
                cax = fig.add_subplot(grid[row, col])
                _image_axis(cax, images.srgb_preview(image[y0:y1, x0:x1], offset))
                for side in cax.spines.values():
                    side.set_edgecolor(c)
                    side.set_linewidth(1.0)
                text = "floor " + fmt(report_floor(ref, rect), 2) if point is None else \
                    fmt(region_rel_mse(image, ref.image, rect), 2)
                cax.set_xlabel(text, labelpad=1.5)
                if col == 0:       # horizontal, left of the row: thin regions leave no room above
                    cax.text(-0.06, 0.5, f"{rname}\n{offset:+g} EV" if offset else rname, ha="right",
                             va="center", transform=cax.transAxes)
        plot_errors(fig.add_subplot(outer[1]), groups, label, styles, how, chosen)
        fig.suptitle(f"{scene}: {chosen.name} (relMSE under each image and crop: that render alone)",
                     fontsize=7, y=0.995)
    return fig


def scene_figure(report, scene: str, out_dir: str, budget: float | None = None) -> list[str]:
    """Write ``out_dir/<scene>_equal_time.pdf`` and ``.png``; returns their paths ([] when the
    scene has no comparison set)."""
    fig = build_figure(report, scene, budget)
    if fig is None:
        return []
    paths = []
    os.makedirs(out_dir, exist_ok=True)
    with pyplot().rc_context(STYLE):
        for ext, dpi in (("pdf", None), ("png", 220)):
            path = os.path.join(out_dir, f"{scene}_equal_time.{ext}")
            with atomic_path(path) as tmp:
                fig.savefig(tmp, format=ext, dpi=dpi, bbox_inches="tight", pad_inches=0.03)
            paths.append(path)
    pyplot().close(fig)
    return paths


def report_floor(ref, rect) -> float:
    """The reference's relMSE floor inside a region (what a perfect render would measure)."""
    x0, y0, x1, y1 = rect
    var = ref.variance[y0:y1, x0:x1].astype(np.float64)
    return float(np.mean(var / (ref.image[y0:y1, x0:x1].astype(np.float64) ** 2 + 1e-2)))


def plot_errors(ax, groups, label, styles, how, chosen) -> None:
    shown = {p.point for _, p in chosen.entries}
    for key, points in groups.items():
        points = sorted(points, key=lambda p: p.time_s)
        t = [p.time_s for p in points]
        e = [max(p.rel_mse_corrected, 1e-12) for p in points]
        err = [0 if math.isnan(p.rel_mse_std) else min(p.rel_mse_std, 0.999 * v) for p, v in zip(points, e)]
        ax.errorbar(t, e, yerr=err, ms=2.5, lw=0.9, capsize=1.5, **styles[key].kwargs(), label=label(key))
        picked = [(p.time_s, v) for p, v in zip(points, e) if p.point in shown]
        if picked:
            ax.plot(*zip(*picked), "o", ms=6, mfc="none", mec=styles[key].colour, mew=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time of one render (s)")
    ax.set_ylabel("relMSE, reference floor subtracted")
    ax.set_title("error against time (bars: std over seeds; circled: shown)", pad=2)
    ax.grid(True, which="both", alpha=0.25, lw=0.4)
    legend_outside(ax, STYLE["legend.fontsize"], how)


def write_figures(report, out_dir: str, budget: float | None = None) -> list[str]:
    """Every scene's figure (``scene_figure``); LabError when no scene has a comparison."""
    if budget is not None and not budget > 0:
        raise LabError(f"--budget must be a positive number of seconds, got {budget:g}")
    paths = [p for scene in report.stats for p in scene_figure(report, scene, out_dir, budget)]
    if not paths:
        raise LabError(f"{report.folder} has no points with two or more seeds: no figure to draw")
    return paths
