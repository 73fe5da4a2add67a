"""The sweep report, built from stored results only (it never renders).

Writes ``OUTDIR/results.csv`` (one row per render), ``OUTDIR/report/index.html``
(self-contained: plots and images embedded as data URIs, opens offline),
``OUTDIR/report/summary.md`` and the plot / image PNGs beside them.
"""
from __future__ import annotations

import base64
import csv
import html
import json
import math
import os
from collections import defaultdict

import numpy as np

from .. import images, metrics
from .analysis import (FLOOR_WARNING_FACTOR, PointStats, bias_by_passes, curve, equal_time_budgets,
                       point_stats, region_at_budgets, region_floor, region_stack_stats, run_image, slope,
                       veach_bound)
from ..plugins.params import resolve as resolve_params
from .config import PASS_PARAMETER
from .reference import Reference
from .spectrum import plot_error_spectra, slope_table
from .store import ResultStore

CSV_COLUMNS = ("point", "scene", "strategy", "sampler", "spp", "budget_s", "seed", "wall_s", "kernel_s",
               "compile_s", "mse", "rel_mse", "flip", "ciede2000", "finite", "negative", "peak_rss_mib", "host",
               "image")


def fmt(value, digits=3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if isinstance(value, float):
        if value == math.inf:
            return "inf"
        return f"{value:.{digits}g}"
    return str(value)


class Report:
    def __init__(self, folder: str):
        self.folder = folder
        check_sweep_folder(folder)                  # before ResultStore, which would create it
        self.store = ResultStore(folder)
        metas = self.store.of_kind("meta")
        self.meta = metas[-1] if metas else {}
        if not self.store.current_runs():
            from ..errors import LabError

            config = self.meta.get("config") or "CONFIG"
            raise LabError(f"{folder} holds no finished renders yet ({self.store.path} has no run rows): "
                           f"run or resume the sweep with `mitsuba-lab sweep {config} -o {folder}` first")
        self.out = os.path.join(folder, "report")
        os.makedirs(self.out, exist_ok=True)
        self.references = self._references()
        self.stats = self._stats()

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
        sections = [self.header()] + [self.scene_section(scene) for scene in self.stats]
        md = "\n\n".join(s["md"] for s in sections)
        body = "\n".join(s["html"] for s in sections)
        paths = {"csv": os.path.join(self.folder, "results.csv"),
                 "html": os.path.join(self.out, "index.html"), "md": os.path.join(self.out, "summary.md")}
        with images.atomic_path(paths["md"]) as tmp, open(tmp, "w") as f:
            f.write(md + "\n")
        with images.atomic_path(paths["html"]) as tmp, open(tmp, "w") as f:
            f.write(HTML_PAGE.format(title=html.escape(self.meta.get("name", "sweep")), body=body))
        return paths

    def write_csv(self) -> None:
        region_names = sorted({n for r in self.store.current_runs() for n in r.get("regions", {})})
        columns = list(CSV_COLUMNS) + [f"rays_{k}" for k in ("camera", "extension", "shadow")] + \
            [f"region_{n}_{m}" for n in region_names for m in ("mse", "rel_mse")]
        with images.atomic_path(os.path.join(self.folder, "results.csv")) as tmp, open(tmp, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(columns)
            for row in self.store.current_runs():
                values = [row.get(c) for c in CSV_COLUMNS]
                values += [row.get("rays", {}).get(k) for k in ("camera", "extension", "shadow")]
                values += [row.get("regions", {}).get(n, {}).get(m) for n in region_names
                           for m in ("mse", "rel_mse")]
                writer.writerow(values)

    def header(self) -> dict:
        machine = self.meta.get("machine", {})
        info = ", ".join(f"{k} {v}" for k, v in machine.items())
        lines_md = [f"# Sweep report: {self.meta.get('name')}", "", f"Config: `{self.meta.get('config')}`",
                    "", f"Machine and versions: {info}", "",
                    "Metrics: relMSE = mean (x - ref)^2 / (ref^2 + 0.01); `corrected` values subtract the "
                    "reference's noise floor; efficiency = 1 / (corrected MSE x median wall time of one "
                    "render); variance = mean per-pixel variance across seeds; bias^2 = squared error of "
                    "the seed mean minus its variance and the reference floor (+- one standard error)."]
        left = self.meta.get("left_out", []) + [
            {**a, "reason": f"same estimator as {a['same_as']}: {a['reason']}"} for a in self.meta.get("aliases", [])]
        if left:
            lines_md += ["", "## Left out and aliased strategies", "", "| scene | strategy | reason |", "|---|---|---|"]
            lines_md += [f"| {x['scene']} | {x['strategy']} | {x['reason']} |" for x in left]
        return {"md": "\n".join(lines_md), "html": md_to_html("\n".join(lines_md))}

    def scene_section(self, scene: str) -> dict:
        stats = sorted(self.stats[scene], key=lambda s: (s.strategy, s.sampler, s.time_s))
        ref = self.references[scene]
        groups = defaultdict(list)
        for s in stats:
            groups[(s.strategy, s.sampler)].append(s)
        label = lambda key: key[0] if len({k[1] for k in groups}) == 1 else f"{key[0]} / {key[1]}"
        md = [f"## Scene `{scene}`", "",
              f"Reference: {ref.meta.get('integrator')} {json.dumps(ref.meta.get('params', {}))}, "
              f"{ref.meta.get('spp')} spp in {ref.meta.get('chunks')} chunks; noise floor: MSE "
              f"{fmt(ref.mse_floor)}, relMSE {fmt(ref.rel_mse_floor())}."]
        near = [s.point for s in stats if s.near_floor]
        if near:
            md += ["", f"**Warning:** {len(near)} point(s) measured an MSE within {FLOOR_WARNING_FACTOR:g}x of "
                       f"the reference floor (their errors are mostly the reference's): {', '.join(near)}."]
        plot = self.plot_curves(scene, groups, label)
        md += ["", f"![relMSE against time]({os.path.basename(plot)})"]
        md += self.efficiency_table(groups, label)
        md += self.equal_time_table(groups, label)
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
        md += self.veach_table(scene, groups)
        strip = self.image_strip(scene, groups, label)
        if strip:
            md += ["", f"![reference, each strategy at about equal time, error maps]({os.path.basename(strip)})"]
        text = "\n".join(md)
        return {"md": text, "html": md_to_html(text, embed_from=self.out)}

    # -- tables ------------------------------------------------------------------------
    def efficiency_table(self, groups, label) -> list[str]:
        rows = []
        for key, points in groups.items():
            top = max(points, key=lambda p: p.time_s)
            times, errors = curve(points, "mse_corrected")
            rows.append((top.efficiency if not math.isnan(top.efficiency) else -1, key, top, slope(times, errors)))
        rows.sort(key=lambda r: r[0], reverse=True)
        md = ["", "### Efficiency (largest sample count), ranked", "",
              "| rank | strategy | spp | time s | MSE | corrected MSE | relMSE (+- seed std) | efficiency | "
              "slope log MSE / log t | FLIP | CIEDE2000 | rays / sample (ext, shadow) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for rank, (_, key, p, s) in enumerate(rows, 1):
            rays = f"{fmt(p.rays_per_sample.get('extension'))}, {fmt(p.rays_per_sample.get('shadow'))}"
            md.append(f"| {rank} | {label(key)} | {p.spp} | {fmt(p.time_s)} | {fmt(p.mse)} | {fmt(p.mse_corrected)} | "
                      f"{fmt(p.rel_mse)} +- {fmt(p.rel_mse_std, 2)} | {fmt(p.efficiency)} | {fmt(s)} | "
                      f"{fmt(p.flip)} | {fmt(p.ciede2000)} | {rays} |")
        return md

    def equal_time_table(self, groups, label) -> list[str]:
        curves = {key: curve(points) for key, points in groups.items()}
        budgets = equal_time_budgets(curves)
        if not budgets:
            return ["", "### Equal time", "", "The strategies' time ranges do not overlap: no equal-time "
                    "comparison (add spp levels or time budgets)."]
        md = ["", "### Corrected relMSE at equal time (log-log interpolation)", "",
              "| strategy | " + " | ".join(f"{b:.3g} s" for b in budgets) + " |",
              "|---|" + "---|" * len(budgets)]
        for key, (times, errors) in curves.items():
            values = [metrics.interpolate_at_time(times, errors, b) if len(times) >= 2 else math.nan
                      for b in budgets]
            md.append(f"| {label(key)} | " + " | ".join(fmt(v) for v in values) + " |")
        return md

    def bias_table(self, stats) -> list[str]:
        md = ["", "### Bias and variance per point", "",
              "Relative: the same in relMSE's units (pixels weighted by 1 / (ref^2 + 0.01)).", "",
              "| point | seeds | variance | bias^2 (+- se) | relative variance | relative bias^2 (+- se) | "
              "relMSE floor-corrected |", "|---|---|---|---|---|---|---|"]
        md += [f"| {s.point} | {s.seeds} | {fmt(s.variance)} | {fmt(s.bias2)} +- {fmt(s.bias2_se, 2)} | "
               f"{fmt(s.rel_variance)} | {fmt(s.rel_bias2)} +- {fmt(s.rel_bias2_se, 2)} | "
               f"{fmt(s.rel_mse_corrected)} |" for s in stats]
        return md

    def region_tables(self, scene, groups, label) -> list[str]:
        names = sorted({n for points in groups.values() for p in points for n in p.regions})
        if not names:
            return []
        ref = self.references[scene]
        rects = self._regions(scene, ref.image.shape[1], ref.image.shape[0])
        floors = {n: float(metrics.region(ref.variance, rects[n]).mean()) if n in rects else 0.0 for n in names}
        md = ["", "### Regions of interest (largest sample count): relMSE and efficiency "
                  "(efficiency from the region MSE minus the region's reference floor; the relative "
                  "version weighs dim and bright pixels alike)", "",
              "| strategy | " + " | ".join(f"{n} relMSE | {n} efficiency | {n} 1/(relMSE x t)" for n in names) + " |",
              "|---|" + "---|---|---|" * len(names)]
        best = {}
        for key, points in groups.items():
            top = max(points, key=lambda p: p.time_s)
            cells = []
            for n in names:
                r = top.regions[n]
                corrected = r["mse"] - floors[n]
                eff = 1.0 / (corrected * top.time_s) if corrected > 0 else math.nan
                best.setdefault(n, []).append((eff, label(key)))
                rel_eff = 1.0 / (r["rel_mse"] * top.time_s) if r["rel_mse"] > 0 else math.inf
                cells += [fmt(r["rel_mse"]), fmt(eff), fmt(rel_eff)]
            md.append(f"| {label(key)} | " + " | ".join(cells) + " |")
        md += ["", "Reference noise floor per region (what a perfect render would measure there): " + "; ".join(
            f"{n}: relMSE {fmt(f['rel_mse'])}, MSE {fmt(f['mse'])}, relative standard error of the region "
            f"mean {fmt(100 * f['mean_rel_se'], 2)}%" for n, f in
            ((n, region_floor(ref, rects[n])) for n in names if n in rects)) + "."]
        md += ["", "Most efficient per region: " + "; ".join(
            f"{n}: {max((e, k) for e, k in v if not math.isnan(e))[1]}" for n, v in best.items()
            if any(not math.isnan(e) for e, _ in v)) + "."]
        return md

    def region_budget_tables(self, scene, stats, label) -> list[str]:
        """Per region, every strategy at each time budget: the equal-time comparison where it
        matters (a caustic, a light), with the region's own reference floor subtracted."""
        ref = self.references[scene]
        rects = self._regions(scene, ref.image.shape[1], ref.image.shape[0])
        md = []
        for name, rect in rects.items():
            floor = region_floor(ref, rect)
            table = region_at_budgets(stats, lambda p: label((p.strategy, p.sampler)), name, floor["rel_mse"])
            if not table:
                continue
            names = sorted({n for cells in table.values() for n in cells})
            md += ["", f"### Region `{name}` at each time budget", "",
                   f"Cells: relMSE minus the region's reference floor ({fmt(floor['rel_mse'])}), median time "
                   f"of one render, and (corrected relMSE x time) / the best strategy's at that budget: "
                   f"the equal-time relMSE ratio to the best.", "",
                   "| budget | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
            for budget, cells in table.items():
                md.append(f"| {budget:g} s | " + " | ".join(
                    f"{fmt(c['rel_mse_corrected'])} ({fmt(c['time_s'], 2)} s, {fmt(c['x_best'], 3)}x)"
                    if (c := cells.get(n)) else "n/a" for n in names) + " |")
        return md

    def passes_section(self, scene, groups, label) -> list[str]:
        """Bias^2 and variance against passes for pass-scaled strategies (lab_photon): a biased,
        consistent estimator should show bias^2 falling as passes grow."""
        md, curves = [], {}
        rel_floor = self.references[scene].rel_mse_floor()
        for key, points in groups.items():
            unit = PASS_PARAMETER.get(self._integrator(points[0]))
            if unit is None or len(points) < 2:
                continue
            result = bias_by_passes(points, lambda p: int(self._param(p, unit, p.spp)))
            curves[label(key)] = result
            md += ["", f"### {label(key)}: bias^2 and variance against {unit}", "",
                   f"In relMSE's units (pixels weighted by 1 / (ref^2 + 0.01), so the light's edge pixels do "
                   f"not swamp the rest): relMSE = bias^2 + variance + reference floor ({fmt(rel_floor)}); "
                   f"bias^2 +- one standard error, resolved when more than two above zero. Log-log slope "
                   f"of the resolved bias^2 against {unit}: {fmt(result['slope'])}.", "",
                   f"| {unit} | seeds | time s | relMSE | variance | bias^2 (+- se) | resolved | bias^2 / relMSE |",
                   "|---|---|---|---|---|---|---|---|"]
            md += [f"| {r['passes']} | {r['seeds']} | {fmt(r['time_s'])} | {fmt(r['rel_mse'])} | "
                   f"{fmt(r['variance'])} | {fmt(r['bias2'])} +- {fmt(r['bias2_se'], 2)} | "
                   f"{'yes' if r['resolved'] else 'no'} | "
                   f"{fmt(r['bias2'] / r['rel_mse'] if r['rel_mse'] > 0 else math.nan, 2)} |"
                   for r in result["rows"]]
        if curves:
            md += ["", f"![bias^2 and variance against passes]({os.path.basename(self.plot_passes(scene, curves))})"]
        return md

    def _mis_setting(self, stats: PointStats) -> tuple[str, int, tuple]:
        """(weighting, emitter_samples, the rest of the estimator's parameters) of a lab_mis point,
        with lab_mis's defaults filled in, so a stored row that spells a default out and one that
        leaves it implicit mean the same. Weighting: 'balance' (also power with beta 1, the same
        weights), 'power (beta B)', 'max' or 'average'."""
        stored = self._run_row(stats).get("params", {})
        try:
            params = resolve_params("lab_mis", stored)
        except ValueError:                  # a value resolve rejects (an older row): read as stored
            params = dict(stored)
        params.pop("count_rays", None)      # changes only what is counted
        heuristic, beta = str(params.pop("heuristic", "power")), float(params.pop("beta", 2.0))
        n_l = int(params.pop("emitter_samples", 1))
        if heuristic == "power" and beta == 1.0:
            heuristic = "balance"
        weighting = f"power (beta {beta:g})" if heuristic == "power" else heuristic
        rest = tuple(sorted((k, repr(v)) for k, v in params.items()))
        return weighting, n_l, rest

    def veach_table(self, scene, groups) -> list[str]:
        """Veach's bound: the balance heuristic against each other lab_mis weighting (power, max,
        average) run with the same sampler, the same emitter_samples and otherwise the same
        parameters (max_depth, rr_depth, ...), at equal spp; one group of rows per (sampler,
        emitter_samples). Never across samplers or emitter counts: the bound compares
        weightings of one set of samples."""
        blocks = defaultdict(dict)          # (sampler, n_L, other parameters) -> {strategy: (weighting, points)}
        for (strategy, sampler), points in groups.items():
            if points and self._integrator(points[0]) == "lab_mis":
                weighting, n_l, rest = self._mis_setting(points[0])
                blocks[(sampler, n_l, rest)][strategy] = (weighting, points)
        if not any(w == "balance" for block in blocks.values() for w, _ in block.values()):
            return []
        ref = self.references[scene]
        height, width = ref.image.shape[:2]
        regions = self._regions(scene, width, height) or {"image": (0, 0, width, height)}
        rows, unmatched = [], []
        for (sampler, n_l, _), block in sorted(blocks.items(), key=lambda item: (item[0][0], item[0][1])):
            balance = [s for s, (w, _) in block.items() if w == "balance"]
            others = [s for s, (w, _) in block.items() if w != "balance"]
            where = f"sampler {sampler}, emitter_samples {n_l}"
            if not balance:
                unmatched += [f"{s} ({where}): no balance weighting with this sampler, emitter_samples "
                              f"and other parameters" for s in others]
            for bname in balance:
                bpoints = block[bname][1]
                for oname in others:
                    weighting, opoints = block[oname]
                    pairs = [(bp, op) for bp in sorted(bpoints, key=lambda p: p.spp)
                             for op in [next((p for p in opoints if p.spp == bp.spp), None)] if op is not None]
                    if not pairs:
                        unmatched.append(f"{oname} ({where}): no spp in common with {bname}")
                    for bp, op in pairs:
                        for name, rect in regions.items():
                            b = region_stack_stats(bp, self.folder, ref, rect)
                            o = region_stack_stats(op, self.folder, ref, rect)
                            v = veach_bound(b, o, n_l, bp.spp)
                            rows.append(f"| {sampler} | {n_l} | {bname} | {oname} | {weighting} | {bp.spp} | "
                                        f"{name} | {fmt(v['lhs'])} | {fmt(v['rhs'])} | {fmt(v['se'], 2)} | "
                                        f"{v['verdict']} |")
        md = ["", "### Veach's bound: Var[balance] <= Var[other] + (1/min n_i - 1/sum n_i) I^2", "",
              "Each weighting against the balance heuristic on the same sampler with the same emitter_samples "
              "(n_L shadow rays and 1 BSDF sample per vertex, so min n_i = 1 and sum n_i = n_L + 1) and "
              "otherwise the same parameters, at equal spp."]
        if rows:
            md += ["", "| sampler | emitter_samples | balance | other | weighting | spp | region | Var balance | "
                       "Var other + slack | standard error | verdict |",
                   "|---|---|---|---|---|---|---|---|---|---|---|", *rows]
        for line in unmatched:
            md += ["", f"Not compared: {line}."]
        if not rows and not unmatched:
            md += ["", "Nothing to compare: no other lab_mis weighting shares a sampler and emitter_samples "
                       "with a balance one."]
        md.append("")
        md.append("Variances are sample variances over the seeds (jackknife standard errors); "
                  "'within noise' means the excess is under two standard errors. The bound is exact for "
                  "direct lighting (max_depth 2); with longer paths it is indicative only.")
        return md

    def _run_row(self, stats: PointStats) -> dict:
        """A run row of the point (rows in force only; the store does not change while the
        report is built, so the point -> row map is made once)."""
        if not hasattr(self, "_row_of_point"):
            self._row_of_point = {}
            for row in self.store.current_runs():
                self._row_of_point.setdefault(row["point"], row)
        return self._row_of_point[stats.point]

    def _integrator(self, stats: PointStats) -> str:
        return self._run_row(stats).get("integrator", "")

    def _param(self, stats: PointStats, name: str, default):
        return self._run_row(stats).get("params", {}).get(name, default)

    def _regions(self, scene, width, height) -> dict:
        return {n: tuple(r) for n, r in self.references[scene].meta.get("regions", {}).items()}

    # -- figures -------------------------------------------------------------------------
    def plot_curves(self, scene, groups, label) -> str:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
        for key, points in groups.items():
            points = sorted(points, key=lambda p: p.time_s)
            t = [p.time_s for p in points]
            e = [max(p.rel_mse_corrected, 1e-12) for p in points]
            err = [p.rel_mse_std if not math.isnan(p.rel_mse_std) else 0 for p in points]
            ax.errorbar(t, e, yerr=err, marker="o", capsize=3, label=label(key))
        return self._save_loglog(fig, ax, os.path.join(self.out, f"{scene}_curves.png"),
                                 "wall time of one render (s)", "relMSE, reference floor subtracted",
                                 f"{scene}: error against time (bars: std over seeds)", legend_size=8)

    def plot_passes(self, scene, curves: dict) -> str:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
        for i, (name, result) in enumerate(curves.items()):
            rows, colour = result["rows"], f"C{i}"
            ax.plot([r["passes"] for r in rows], [r["variance"] for r in rows], "s--", color=colour,
                    label=f"{name}: variance")
            shown = [r for r in rows if r["bias2"] > 0]        # a log axis has no room for <= 0
            ax.errorbar([r["passes"] for r in shown], [r["bias2"] for r in shown],
                        yerr=[min(r["bias2_se"], 0.999 * r["bias2"]) for r in shown], fmt="o-", color=colour,
                        capsize=3, label=f"{name}: bias^2 (+- se)")
        return self._save_loglog(fig, ax, os.path.join(self.out, f"{scene}_passes.png"),
                                 "passes (one photon map and one camera sample per pixel each)",
                                 "part of relMSE", f"{scene}: bias^2 and variance against passes", legend_size=7)

    @staticmethod
    def _save_loglog(fig, ax, path, xlabel, ylabel, title, legend_size) -> str:
        """Log-log axes, labels, grid and legend; the PNG written atomically; the figure closed."""
        import matplotlib.pyplot as plt

        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=legend_size)
        with images.atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", bbox_inches="tight")
        plt.close(fig)
        return path

    def image_strip(self, scene, groups, label) -> str | None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.patches import Rectangle

        ref = self.references[scene]
        curves = {key: curve(points) for key, points in groups.items()}
        budgets = equal_time_budgets(curves)
        target = budgets[len(budgets) // 2] if budgets else None
        chosen = []
        for key, points in groups.items():
            pick = min(points, key=lambda p: abs(math.log(p.time_s / target)) if target else -p.time_s)
            chosen.append((key, pick))
        height, width = ref.image.shape[:2]
        regions = self._regions(scene, width, height)
        cols = 1 + len(chosen)
        fig, axes = plt.subplots(2, cols, figsize=(2.2 * cols, 4.6), dpi=100, squeeze=False)
        axes[0][0].imshow(images.srgb_preview(ref.image))
        axes[0][0].set_title("reference", fontsize=8)
        for name, (x0, y0, x1, y1) in regions.items():
            axes[0][0].add_patch(Rectangle((x0 - 0.5, y0 - 0.5), x1 - x0, y1 - y0, fill=False, color="cyan", lw=0.8))
        axes[1][0].imshow(np.log10(np.maximum(ref.variance.mean(-1), 1e-12)), cmap="viridis")
        axes[1][0].set_title("log10 reference variance", fontsize=7)
        for col, (key, p) in enumerate(chosen, 1):
            image = run_image(self.folder, p.images[0])
            axes[0][col].imshow(images.srgb_preview(image))
            axes[0][col].set_title(f"{label(key)}\n{p.spp} spp, {p.time_s:.2g} s", fontsize=7)
            rel_err = np.abs(image - ref.image).mean(-1) / (np.abs(ref.image).mean(-1) + 1e-2)
            axes[1][col].imshow(np.log10(np.maximum(rel_err, 1e-4)), cmap="magma", vmin=-3, vmax=0.5)
            axes[1][col].set_title("log10 relative error", fontsize=7)
        for ax in axes.flat:
            ax.set_xticks([])
            ax.set_yticks([])
        path = os.path.join(self.out, f"{scene}_images.png")
        with images.atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", bbox_inches="tight")
        plt.close(fig)
        return path


def md_to_html(text: str, embed_from: str | None = None) -> str:
    """The small Markdown subset the report uses (headings, tables, paragraphs, images) as HTML;
    images are embedded as data URIs so the page is self-contained."""
    out, table = [], []

    def flush_table():
        if table:
            rows = [r.strip().strip("|").split("|") for r in table if not set(r.strip()) <= set("|-")]
            head, body = rows[0], rows[1:]
            out.append("<table><tr>" + "".join(f"<th>{html.escape(c.strip())}</th>" for c in head) + "</tr>" +
                       "".join("<tr>" + "".join(f"<td>{html.escape(c.strip())}</td>" for c in r) + "</tr>"
                               for r in body) + "</table>")
            table.clear()

    for line in text.splitlines():
        if line.startswith("|"):
            table.append(line)
            continue
        flush_table()
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{html.escape(line.lstrip('#').strip())}</h{level}>")
        elif line.startswith("![") and embed_from:
            alt, src = line[2:].split("](", 1)
            with open(os.path.join(embed_from, src.rstrip(")")), "rb") as f:
                data = base64.b64encode(f.read()).decode()
            out.append(f'<p><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}"></p>')
        elif line.strip():
            out.append(f"<p>{html.escape(line).replace('`', '')}</p>")
    flush_table()
    return "\n".join(out)


HTML_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1400px; }}
table {{ border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.85em; }}
th, td {{ border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: right; }}
th {{ background: #eee; }} td:first-child, th:first-child {{ text-align: left; }}
img {{ max-width: 100%; }}
</style></head><body>
{body}
</body></html>
"""


def check_sweep_folder(folder: str) -> None:
    """LabError unless ``folder`` is an existing folder with a results.jsonl; it only looks
    (ResultStore would create a missing folder)."""
    from ..errors import LabError

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
