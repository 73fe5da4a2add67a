"""The sweep report, built from stored results only (it never renders).

Writes ``OUTDIR/results.csv`` (one row per render), ``OUTDIR/report/index.html``
(self-contained: plots and images embedded as data URIs, opens offline; per scene a
comparison viewer, ``viewer``, with the renders as half-float HDR data),
``OUTDIR/report/summary.md`` and the plot / image PNGs beside them. The tables of each
scene's section are in ``report_sections``; page, table, number and figure helpers are
the shared ones of ``mitsuba_lab.reporting``.
"""
from __future__ import annotations

import json
import math
import os
from collections import defaultdict

import numpy as np

from ... import images
from ...reporting import block_marker, dict_rows, fmt, markdown_table, write_csv, write_markdown_page
from ...reporting.figures import loglog_axes, pyplot, save_figure, series_styles
from . import viewer
from .analysis import (FLOOR_WARNING_FACTOR, PointStats, curve, equal_time_budgets, pilot_light_paths, point_stats,
                       run_image)
from ..pipeline.budget import measured_range, missed_budget
from ..pipeline.reference import Reference
from .tables import OTHER_RAY_KINDS, SectionTables
from .spectrum import plot_error_spectra, slope_table
from ..pipeline.store import ResultStore
from ..execution.strategy_grid import grid_section

#: The rule every verdict of the report follows, stated once at its top.
VERDICT_RULE = (
    "Verdicts: a verdict (best or most efficient, biased, resolved, a slope) is given only where its "
    "uncertainty separates it: more than two standard errors for an error taken over pixels, Student's t at "
    "97.5% for one taken over the seeds (12.7 standard errors with 2 seeds, 4.3 with 3); otherwise it reads "
    "\"not resolved with N seeds (needs about M)\", M from the standard error's 1/sqrt(N) scaling. Numbers "
    "carry the digits that tell apart values differing by more than their errors. A bias^2 more than two "
    "standard errors below zero is flagged as an unreliable variance estimate (heavy tails). Efficiency ranks "
    "consistent estimators: a strategy whose bias is resolved (over the image, or in a region) or that ignores "
    "part of the scene is left out of a \"most efficient\" verdict there, and the verdict names it.")

CSV_COLUMNS = ("point", "scene", "strategy", "sampler", "spp", "budget_s", "seed", "wall_s", "kernel_s",
               "compile_s", "mse", "rel_mse", "flip", "ciede2000", "finite", "negative", "peak_rss_mib", "host",
               "image")
RAY_KINDS = ("camera", "extension", "shadow")


class Report(SectionTables):
    def __init__(self, folder: str):
        self.folder = folder
        check_sweep_folder(folder)                  # before ResultStore, which would create it
        self.store = ResultStore(folder)
        metas = self.store.of_kind("meta")
        self.meta = metas[-1] if metas else {}
        if not self.store.current_runs():
            from ...errors import LabError

            config = self.meta.get("config") or "CONFIG"
            raise LabError(f"{folder} holds no finished renders yet ({self.store.path} has no run rows): "
                           f"run or resume the sweep with `mitsuba-lab sweep {config} -o {folder}` first")
        self.out = os.path.join(folder, "report")
        os.makedirs(self.out, exist_ok=True)
        #: {(scene, strategy): mark} of strategies run though they ignore part of the scene
        #: (experiment.allow_unsupported): every table names them with it, "path (ignores media)"
        self.marks = {(u["scene"], u["strategy"]): u["mark"] for u in self.meta.get("unsupported", [])}
        self.references = self._references()
        self.stats = self._stats()
        self.blocks: dict[str, str] = {}             # HTML blocks of the page (the viewers)

    # -- loading -------------------------------------------------------------------
    def _references(self) -> dict[str, Reference]:
        refs = {}
        for row in self.store.of_kind("reference"):
            stem = os.path.join(self.folder, "references", row["key"])
            refs[row["scene"]] = Reference(row["key"], images.read_exr(stem + ".exr")[0],
                                           images.read_exr(stem + ".var.exr")[0], row)
        return refs

    def _stats(self) -> dict[str, list[PointStats]]:
        by_point = defaultdict(list)
        for row in self.store.current_runs():
            by_point[row["point"]].append(row)
        stats = defaultdict(list)
        for rows in by_point.values():
            if len(rows) >= 2:                       # variance needs two seeds
                scene = rows[0]["scene"]
                stats[scene].append(point_stats(rows, self.folder, self.references[scene]))
        return stats

    # -- output --------------------------------------------------------------------
    def write(self) -> dict[str, str]:
        self.write_csv()
        md = "\n\n".join([self.header()] + [self.scene_section(scene) for scene in self.stats])
        grid = grid_section(self.store, self.out)
        if grid:
            md += "\n" + "\n".join(grid)             # the section starts with an empty line
        script = viewer.script() if self.blocks else ""
        paths = write_markdown_page(self.out, self.meta.get("name", "sweep"), md, blocks=self.blocks,
                                    style=viewer.STYLE if self.blocks else "", script=script)
        return {"csv": os.path.join(self.folder, "results.csv"), **paths}

    def write_csv(self) -> None:
        runs = self.store.current_runs()
        region_names = sorted({n for r in runs for n in r.get("regions", {})})
        # (the other kinds only when some run counted them: lab_bdpt's, lab_vcm's, lab_photon's)
        kinds = RAY_KINDS + tuple(k for k in OTHER_RAY_KINDS if any(k in r.get("rays", {}) for r in runs))
        columns = list(CSV_COLUMNS) + [f"rays_{k}" for k in kinds] + \
            [f"region_{n}_{m}" for n in region_names for m in ("mse", "rel_mse")] + ["pilot_light_paths"]
        rows = [values + [row.get("rays", {}).get(k) for k in kinds] +
                [row.get("regions", {}).get(n, {}).get(m) for n in region_names for m in ("mse", "rel_mse")] +
                [pilot_light_paths(row.get("integrator_stats") or {})]
                for row, values in zip(runs, dict_rows(runs, CSV_COLUMNS))]
        write_csv(os.path.join(self.folder, "results.csv"), columns, rows)

    def header(self) -> str:
        machine = self.meta.get("machine", {})
        info = ", ".join(f"{k} {v}" for k, v in machine.items())
        lines_md = [f"# Sweep report: {self.meta.get('name')}", "", f"Config: `{self.meta.get('config')}`",
                    "", f"Machine and versions: {info}", "",
                    "Metrics: relMSE = mean (x - ref)^2 / (ref^2 + 0.01); `corrected` values subtract the "
                    "reference's noise floor; efficiency = 1 / (mean over seeds of corrected MSE x that "
                    "seed's wall time); variance = mean per-pixel variance across seeds; bias^2 = squared error of "
                    "the seed mean minus its variance and the reference floor (+- one standard error).",
                    "", VERDICT_RULE]
        left = self.meta.get("left_out", []) + [
            {**a, "reason": f"same estimator as {a['same_as']}: {a['reason']}"} for a in self.meta.get("aliases", [])]
        if left:
            lines_md += ["", "## Left out and aliased strategies", "",
                         *markdown_table(["scene", "strategy", "reason"],
                                         [[x["scene"], x["strategy"], x["reason"]] for x in left])]
        marked = self.meta.get("unsupported", [])
        if marked:
            lines_md += ["", "## Strategies run on scenes they cannot render correctly", "",
                         "Named in experiment.allow_unsupported: they ran, and every table marks them; their "
                         "errors include what they leave out, so their ranking says nothing about their noise.", "",
                         *markdown_table(["scene", "strategy", "mark", "reason"],
                                         [[x["scene"], x["strategy"], x["mark"], x["reason"]] for x in marked])]
        lines_md += self.settings_table()
        return "\n".join(lines_md)

    def scene_section(self, scene: str) -> str:
        stats = sorted(self.stats[scene], key=lambda s: (s.strategy, s.sampler, s.time_s))
        ref = self.references[scene]
        groups = defaultdict(list)
        for s in stats:
            groups[(s.strategy, s.sampler)].append(s)
        plain = lambda key: key[0] if len({k[1] for k in groups}) == 1 else f"{key[0]} / {key[1]}"
        label = lambda key: self.shown(scene, key[0], plain(key))
        md = [f"## Scene `{scene}`", "",
              f"Reference: {ref.meta.get('integrator')} {json.dumps(ref.meta.get('params', {}))}, "
              f"{ref.meta.get('spp')} spp in {ref.meta.get('chunks')} chunks; noise floor: MSE "
              f"{fmt(ref.mse_floor)}, relMSE {fmt(ref.rel_mse_floor())}."]
        near = [s.point for s in stats if s.near_floor]
        if near:
            md += ["", f"**Warning:** {len(near)} point(s) measured an MSE within {FLOOR_WARNING_FACTOR:g}x of "
                       f"the reference floor (their errors are mostly the reference's): {', '.join(near)}."]
        md += self.viewer_marker(scene, stats)
        plot = self.plot_curves(scene, groups, label)
        md += ["", f"![relMSE against time]({os.path.basename(plot)})"]
        md += self.efficiency_table(groups, label)
        md += self.equal_time_table(groups, label)
        md += self.mean_table(groups, label)
        md += self.bias_table(stats)
        md += self.passes_section(scene, groups, label)
        md += slope_table(groups, label)
        spectra = plot_error_spectra(groups, label, ref.image, self.folder,
                                     os.path.join(self.out, f"{scene}_spectra.png"),
                                     read_image=lambda p: run_image(self.folder, os.path.relpath(p, self.folder)))
        if spectra:
            md += ["", f"![radially averaged power spectrum of the error]({os.path.basename(spectra)})"]
        md += self.region_tables(scene, groups, label)
        md += self.region_budget_tables(scene, stats, label)
        md += self.pilot_table(groups, label)
        md += self.veach_table(scene, groups)
        strip = self.image_strip(scene, groups, label)
        if strip:
            md += ["", f"![{strip_points(groups, label)[1]}]({os.path.basename(strip)})",
                   "", "Under each render: its relative error |x - ref| / (|ref| + 0.01) (one seed), then the signed "
                       "difference of its mean over the seeds from the reference (red above, blue below, one "
                       "symmetric range for all): noise averages out of the mean, bias stays."]
        return "\n".join(md)

    def viewer_marker(self, scene, stats) -> list[str]:
        """The scene's comparison viewer (HTML only: summary.md gets an invisible marker)."""
        ref = self.references[scene]
        data = viewer.scene_data(self.folder, scene, stats, ref,
                                 self._regions(scene, ref.image.shape[1], ref.image.shape[0]))
        if data is None:
            return []
        self.blocks[f"viewer-{scene}"] = viewer.viewer_block(data)
        return ["", block_marker(f"viewer-{scene}")]

    # -- figures -------------------------------------------------------------------------
    def plot_curves(self, scene, groups, label) -> str:
        fig, _ = curves_figure(groups, label)
        return save_figure(fig, os.path.join(self.out, f"{scene}_curves.png"))

    def plot_passes(self, scene, curves: dict, styles: dict | None = None) -> str:
        """bias^2 (solid, filled) and variance (dashed, open) against passes per curve;
        ``styles`` {curve name: Style} gives each the colour and marker of its curve elsewhere."""
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
        styles = styles or series_styles(curves)[0]
        for name, result in curves.items():
            rows, style = result["rows"], styles[name]
            ax.plot([r["passes"] for r in rows], [r["variance"] for r in rows], color=style.colour,
                    marker=style.marker, linestyle="--", mfc="none", label=f"{name}: variance")
            shown = [r for r in rows if r["bias2"] > 0]        # a log axis has no room for <= 0
            ax.errorbar([r["passes"] for r in shown], [r["bias2"] for r in shown],
                        yerr=[min(r["bias2_se"], 0.999 * r["bias2"]) for r in shown], color=style.colour,
                        marker=style.marker, linestyle="-", capsize=3, label=f"{name}: bias^2 (+- se)")
        loglog_axes(ax, "passes or iterations (one light-vertex map and one camera sample per pixel each)",
                    "part of relMSE", f"{scene}: bias^2 (solid) and variance (dashed) against passes", legend_size=7)
        from matplotlib.ticker import NullFormatter, ScalarFormatter

        # plain numbers at powers of two (log minor labels such as 3x10^1 collide)
        passes = [r["passes"] for result in curves.values() for r in result["rows"]] or [1]
        ax.set_xticks([2 ** k for k in range(int(math.log2(max(passes))) + 1) if min(passes) <= 2 ** k]
                      or sorted(set(passes)))
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
        return save_figure(fig, os.path.join(self.out, f"{scene}_passes.png"))

    def image_strip(self, scene, groups, label) -> str | None:
        ref = self.references[scene]
        chosen = []
        for key, pick in strip_points(groups, label)[0].items():
            mean = np.mean([run_image(self.folder, path) for path in pick.images], axis=0)
            title = strip_title(label(key), pick.spp, pick.time_s) + ("\n(off budget)" if missed_budget(pick) else "")
            chosen.append((title, run_image(self.folder, pick.images[0]),
                           mean))
        height, width = ref.image.shape[:2]
        fig = strip_figure(ref.image, ref.variance, chosen, self._regions(scene, width, height))
        return save_figure(fig, os.path.join(self.out, f"{scene}_images.png"))


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


def curves_figure(groups, label, styles=None):
    """(figure, axes): corrected relMSE against time per group, bars the std over seeds;
    one colour per strategy and one marker and line style per sampler (``styles``: what
    ``series_styles`` returns, by default for these groups), the legend outside the axes."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
    styles, how = styles or series_styles(groups, ("strategy", "sampler"))
    for key, points in groups.items():
        points = sorted(points, key=lambda p: p.time_s)
        t = [p.time_s for p in points]
        e = [max(p.rel_mse_corrected, 1e-12) for p in points]
        err = [0 if math.isnan(p.rel_mse_std) else min(p.rel_mse_std, 0.999 * v) for p, v in zip(points, e)]
        ax.errorbar(t, e, yerr=err, capsize=2, ms=4, lw=1.0, label=label(key), **styles[key].kwargs())
    scene = next((getattr(p, "scene", "") for points in groups.values() for p in points), "")
    loglog_axes(ax, "wall time of one render (s)", "relMSE, reference floor subtracted",
                f"{scene}: error against time (bars: std over seeds)", legend_size=7, legend_title=how)
    return fig, ax


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


def check_sweep_folder(folder: str) -> None:
    """LabError unless ``folder`` is an existing folder with a results.jsonl; it only looks
    (ResultStore would create a missing folder)."""
    from ...errors import LabError

    if os.path.isfile(folder):
        message = f"report expects a sweep's output folder, got the file {folder}"
        if folder.lower().endswith(".toml"):
            message += f"; to run the sweep: mitsuba-lab sweep {folder}"
        raise LabError(message)
    if not os.path.exists(folder):
        raise LabError(f"no such folder: {folder}")
    if not os.path.isdir(folder):
        raise LabError(f"report expects a sweep's output folder, got {folder}, which is not a folder")
    if not os.path.isfile(os.path.join(folder, "results.jsonl")):
        raise LabError(f"{folder} holds no sweep results (no results.jsonl): run "
                       f"`mitsuba-lab sweep CONFIG -o {folder}` first")


def build_report(folder: str) -> dict[str, str]:
    """Rebuild the report of the sweep stored in ``folder`` (LabError when it holds none)."""
    check_sweep_folder(folder)
    return Report(folder).write()
