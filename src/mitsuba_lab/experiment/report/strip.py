"""The image strip of a scene's section: the reference and each strategy's render at about equal
time, under each its relative error map and the signed difference of its mean over the seeds."""
from __future__ import annotations

import math

import numpy as np

from ... import images
from ..pipeline.budget import measured_range, missed_budget
from ...reporting.figures import pyplot
from .analysis import curve, equal_time_budgets


def strip_points(groups, label) -> tuple[dict, str]:
    """({group: the point the image strip shows}, the strip's title). With time budgets every
    strategy at one budget, the largest that all of them have (an off-budget point marked);
    otherwise each strategy's point nearest in log time to the middle of the time range all
    curves cover (the longest where there is none), the title naming each one's time."""
    common = set.intersection(*({p.budget_s for p in points if p.budget_s is not None}
                                for points in groups.values())) if groups else set()
    if common:
        budget = max(common)
        picks = {key: next(p for p in points if p.budget_s == budget) for key, points in groups.items()}
        times = [p.time_s for p in picks.values()]
        off = [f"{label(key)} {p.time_s:.2g} s" for key, p in picks.items() if missed_budget(p)]
        title = (f"reference, each strategy at the {budget:g} s budget ({measured_range(min(times), max(times))}"
                 + (f"; off budget: {', '.join(off)}" if off else "") + "), error maps")
        return picks, title
    curves = {key: curve(points) for key, points in groups.items()}
    budgets = equal_time_budgets(curves)
    target = budgets[len(budgets) // 2] if budgets else None
    picks = {key: min(points, key=lambda p: abs(math.log(p.time_s / target)) if target else -p.time_s)
             for key, points in groups.items()}
    at = ", ".join(f"{label(key)} {p.time_s:.2g} s" for key, p in picks.items())
    return picks, f"reference, each strategy at about equal time ({at}), error maps"


#: The thumbnail grid's columns at most: six 2.2-inch cells fill a 1400 px page at 100 dpi.
STRIP_COLUMNS = 6
#: log10 relative error range of every error map (one colour bar for all).
ERROR_RANGE = (-3.0, 0.5)
#: The signed maps' range: the largest of the renders' 99th percentiles of |difference|, at least this.
SIGNED_FLOOR = 1e-3
#: The signed maps' colour map: diverging, blue below the reference, red above, white at zero.
SIGNED_CMAP = "RdBu_r"


def signed_difference(mean: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per pixel (mean - ref) / (|ref| + 0.01), channels averaged: where a strategy's mean over
    its seeds over- (positive) or under-estimates (negative) the reference."""
    ref = reference.astype(np.float64)
    return (mean.astype(np.float64) - ref).mean(-1) / (np.abs(ref).mean(-1) + 1e-2)


def signed_range(differences) -> float:
    """One symmetric limit for every signed map: the largest 99th percentile of |difference|."""
    return max([SIGNED_FLOOR] + [float(np.percentile(np.abs(d), 99)) for d in differences])


def strip_title(name: str, spp: int, time_s: float, width: int = 24) -> str:
    """A thumbnail's title: the label (broken after "/" when long), then spp and time."""
    if len(name) > width and " / " in name:
        name = name.replace(" / ", " /\n", 1)
    return f"{name}\n{spp} spp, {time_s:.2g} s"


def strip_figure(reference, variance, chosen, regions=None, columns: int = STRIP_COLUMNS):
    """The reference and each (title, image, mean over seeds) of ``chosen`` as thumbnails in a
    grid of at most ``columns`` cells a row, each image above its maps: log10 reference variance
    under the reference; under each render log10 relative error |x - ref| / (|ref| + 0.01) and
    below that the signed difference of its mean over the seeds (the image itself
    when ``chosen`` gives no mean), (mean - ref) / (|ref| + 0.01), in a diverging colour map
    with one symmetric range for all; below the grid one colour bar for each kind of map."""
    from matplotlib.patches import Rectangle

    plt = pyplot()
    cells = 1 + len(chosen)
    rows = math.ceil(cells / columns)
    cols = math.ceil(cells / rows)             # rows as full as each other: 8 cells are 4 + 4, not 6 + 2
    height, width = reference.shape[:2]
    aspect = height / width
    cell_w = 2.2
    fig = plt.figure(figsize=(max(cell_w * cols, 6.6), rows * (3 * cell_w * aspect + 0.5) + 0.7), dpi=100)
    # outer rows: one per row of cells (room for the titles between them), then the colour bars
    outer = fig.add_gridspec(rows + 1, cols, height_ratios=[3 * aspect] * rows + [0.09], hspace=0.22,
                             wspace=0.06)
    entries = [(c[0], c[1], c[2] if len(c) > 2 else c[1]) for c in chosen]
    signed = [signed_difference(mean, reference) for _, _, mean in entries]
    limit = signed_range(signed)

    def cell(i):
        inner = outer[divmod(i, cols)].subgridspec(3, 1, hspace=0.03)
        return fig.add_subplot(inner[0]), fig.add_subplot(inner[1]), inner[2]

    top, bottom, _ = cell(0)
    top.imshow(images.srgb_preview(reference))
    top.set_title("reference", fontsize=8)
    for name, (x0, y0, x1, y1) in (regions or {}).items():
        top.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False, color="cyan", lw=0.8))
    var_map = bottom.imshow(np.log10(np.maximum(variance.mean(-1), 1e-12)), cmap="viridis")
    axes, err_map, signed_map = [top, bottom], None, None
    for i, ((title, image, _), difference) in enumerate(zip(entries, signed), 1):
        top, bottom, third = cell(i)
        top.imshow(images.srgb_preview(image))
        top.set_title(title, fontsize=8)
        rel_err = np.abs(image - reference).mean(-1) / (np.abs(reference).mean(-1) + 1e-2)
        err_map = bottom.imshow(np.log10(np.maximum(rel_err, 1e-4)), cmap="magma", vmin=ERROR_RANGE[0],
                                vmax=ERROR_RANGE[1])
        signed_axis = fig.add_subplot(third)
        signed_map = signed_axis.imshow(difference, cmap=SIGNED_CMAP, vmin=-limit, vmax=limit)
        axes += [top, bottom, signed_axis]
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    bars = outer[-1, :].subgridspec(1, 3, wspace=0.1)
    _colour_bar(fig, var_map, bars[0, 0], "log10 reference variance\n(map under the reference)")
    if err_map is not None:
        _colour_bar(fig, err_map, bars[0, 1], "log10 relative error (one seed)\n|x - ref| / (|ref| + 0.01)")
        _colour_bar(fig, signed_map, bars[0, 2], "signed difference (seeds' mean)\n(mean - ref) / (|ref| + 0.01)",
                    symmetric=True)
    return fig


def _colour_bar(fig, mappable, spec, label: str, symmetric: bool = False) -> None:
    """A horizontal colour bar in ``spec``, inset from its ends so that the end labels of two
    bars side by side do not touch; a ``symmetric`` one is ticked at its ends and zero."""
    from matplotlib.ticker import FixedLocator, MaxNLocator

    bar = fig.colorbar(mappable, cax=fig.add_subplot(spec.subgridspec(1, 12, wspace=0)[0, 1:11]),
                       orientation="horizontal")
    if symmetric:
        limit = mappable.get_clim()[1]
        bar.locator = FixedLocator([-limit, 0.0, limit])
        bar.formatter = _SignedFormatter()
    else:
        bar.locator = MaxNLocator(6, steps=[1, 2, 5, 10])       # whole and half decades
    bar.update_ticks()
    bar.set_label(label, fontsize=7)
    bar.ax.tick_params(labelsize=7)


def _SignedFormatter():
    from matplotlib.ticker import FuncFormatter

    return FuncFormatter(lambda x, _: "0" if x == 0 else f"{x:+.2g}")
