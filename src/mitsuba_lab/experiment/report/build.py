"""The sweep report, built from stored results only (it never renders).

Writes ``OUTDIR/results.csv`` (one row per render), ``OUTDIR/report/index.html``
(self-contained: plots and images embedded as data URIs, opens offline; per scene a
comparison viewer, ``viewer``, with the renders as half-float HDR data),
``OUTDIR/report/summary.md`` and the plot / image PNGs beside them. The tables of each
scene's section are the modules of ``sections``, in their order there (their tables in
``tables``, ``bias`` and ``veach``); page, table, number and figure helpers are
the shared ones of ``mitsuba_lab.reporting``.
"""
from __future__ import annotations

import json
import math
import os
from collections import defaultdict

from ... import images
from ...reporting import block_marker, dict_rows, fmt, markdown_table, write_csv, write_markdown_page
from ...reporting.figures import loglog_axes, pyplot, save_figure, series_styles
from ..execution.strategy_grid import grid_section
from ..pipeline.reference import Reference
from ..pipeline.store import ResultStore
from . import viewer
from .analysis import PointStats, pilot_light_paths, point_stats
from .sections import SceneView, render_scene
from .tables import OTHER_RAY_KINDS, SectionTables

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
        md += render_scene(SceneView(self, scene, stats, groups, label, ref))
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
