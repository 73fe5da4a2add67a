"""The tables of a scene's section in the sweep report, as Markdown lines (the modules of
``sections`` call them, in the page's order).

``SectionTables`` is mixed into ``build.Report``, whose loaded state the tables read:
``folder`` (the sweep's output folder), ``out`` (its report folder, for plots),
``store`` (the ``ResultStore``), ``references`` ({scene: Reference}) and ``plot_passes``.
Every table takes the scene's groups {(strategy, sampler): [PointStats]} and ``label``,
the name a group is shown by.
"""
from __future__ import annotations

import math
import os
import statistics
from collections import defaultdict

from ... import metrics
from ...reporting import fmt, fmt_pm, fmt_pm_column, markdown_table
from ...reporting.figures import series_styles
from .analysis import (MIN_TRUSTED_TIME_S, PointStats, bias_by_passes, budget_columns, curve, equal_time_budgets,
                       region_at_budgets, region_floor, seed_cost,
                       timing_trusted)
from ..pipeline.budget import BUDGET_RETRIES, budget_label, missed_budget, off_budget_text, tolerance_text
from ..pipeline.config import PASS_PARAMETER
from .bias import BiasTables, mean_biased
from .veach import VeachSection
from .verdicts import BIAS_SEPARATION, SEPARATION, UNRELIABLE, best_of, bias_verdict
from .spectrum import fit_slope, slope_cell, slope_note


#: A point whose slowest seed took more than this many times its fastest's says so in its cell
#: (a pilot that chose differently per seed: its relMSE then mixes renders of different lengths).
TIME_SPREAD_NOTED = 1.5


#: Ray kinds the rays/sample column names after extension and shadow rays (the bidirectional
#: integrators' own, and lab_photon's photon segments; camera rays are one per sample everywhere).
OTHER_RAY_KINDS = ("connection", "light", "sensor", "merge", "photon")


def rays_cell(rays_per_sample: dict) -> str:
    """Extension and shadow rays per sample, then the other kinds an integrator counts (lab_bdpt's
    connection, light subpath and sensor rays, the light vertices lab_vcm's merges read, lab_photon's photon segments) by name; n/a when the
    integrator counts none."""
    if not rays_per_sample:
        return fmt(None)
    cell = f"{fmt(rays_per_sample.get('extension'))}, {fmt(rays_per_sample.get('shadow'))}"
    others = [f"{kind} {fmt(rays_per_sample[kind])}" for kind in OTHER_RAY_KINDS if kind in rays_per_sample]
    return cell + (f"; {', '.join(others)}" if others else "")


def budget_cell(c: dict) -> str:
    """One cell of a region's table at a budget (``region_at_budgets``); a single seed has no
    standard error, so none is printed."""
    lo, hi = c["x_best_range"]
    ratio = f"{fmt(c['x_best'], 3)}x" if lo == hi or math.isnan(lo) else \
        f"{fmt(c['x_best'], 3)}x, {fmt(lo, 3)} to {fmt(hi, 3)}"
    spread = f", times {fmt(c['time_spread'], 2)}x apart" if c["time_spread"] > TIME_SPREAD_NOTED else ""
    if c.get("off_budget"):
        ratio = f"**off the {c['budget_s']:g} s budget**: not compared"
    return f"{fmt_pm(c['rel_mse_corrected'], c['rel_mse_se'])} ({fmt(c['time_s'], 2)} s{spread}, {ratio})"


def budget_rule() -> str:
    """The report's statement of when a budget point counts as rendered at its budget."""
    return (f"A point counts as rendered at its time budget when its median render time is within "
            f"{tolerance_text()} of it (budget.BUDGET_TOLERANCE); the runner renders a point outside it again "
            f"at a rescaled sample count (at most {BUDGET_RETRIES} times), and a point that still misses is "
            f"marked **off budget** wherever it is shown and is left out of every comparison at its budget "
            f"(the efficiency ranking uses its measured time, as for every point).")


class SectionTables(VeachSection, BiasTables):
    #: {(scene, strategy): mark}: ``Report`` sets its own (``shown``); none by default.
    marks: dict = {}

    def shown(self, scene: str, strategy: str, text: str | None = None) -> str:
        """How the tables name a strategy (or ``text``, a label or point id of it) on a scene:
        with its mark where it ran though it ignores part of the scene, "path (ignores media)"."""
        mark = self.marks.get((scene, strategy))
        text = strategy if text is None else text
        return f"{text} ({mark})" if mark else text

    def efficiency_table(self, groups, label) -> list[str]:
        """Each group's longest point, ranked by efficiency; a group whose longest render is
        shorter than MIN_TRUSTED_TIME_S is not ranked (listed last, marked) and the MSE-time
        slope is fitted over the points at least that long, +- its standard error, marked
        when it cannot be trusted (``spectrum.fit_slope``)."""
        rows = []
        for key, points in groups.items():
            top = max(points, key=lambda p: p.time_s)
            trusted = timing_trusted(top)
            timed = [p for p in points if timing_trusted(p)]
            fit = fit_slope([p.time_s for p in timed], [p.mse_corrected for p in timed],
                            [p.mse_std / math.sqrt(p.seeds) for p in timed], axis="time")
            floor = math.isnan(top.efficiency)       # corrected MSE <= 0: at the reference's floor
            score = top.efficiency if trusted and not floor else -1.0
            rows.append(((trusted and not floor, score), key, top, fit))
        rows.sort(key=lambda r: r[0], reverse=True)
        short = f"{MIN_TRUSTED_TIME_S * 1000:g} ms"
        header = ["rank", "strategy", "spp", "time s", "MSE", "corrected MSE", "relMSE (+- seed std)", "efficiency",
                  "slope log MSE / log t", "FLIP", "CIEDE2000", "rays / sample (ext, shadow; others)"]
        errors = [getattr(p, "efficiency_se", math.nan) for _, _, p, _ in rows]     # (NaN: not measured)
        efficiencies = fmt_pm_column([p.efficiency for _, _, p, _ in rows], errors)
        body = [[rank if ranked else "not ranked", label(key), p.spp,
                 fmt(p.time_s) + ("" if timing_trusted(p) else f" (< {short})") +
                 (f" (**{off_budget_text(p)}**)" if missed_budget(p) else ""), fmt(p.mse), fmt(p.mse_corrected),
                 f"{fmt(p.rel_mse)} +- {fmt(p.rel_mse_std, 2)}", efficiency, slope_cell(s), fmt(p.flip),
                 fmt(p.ciede2000),
                 rays_cell(p.rays_per_sample)]
                for rank, (((ranked, _), key, p, s), efficiency) in enumerate(zip(rows, efficiencies), 1)]
        ranked = [(key, p) for (ok, _), key, p, _ in rows if ok]
        left = {label(key): why for key, p in ranked if (why := self.left_out_why(p))}
        kept = [(key, p) for key, p in ranked if label(key) not in left]
        best = best_of({label(key): (1.0 / p.efficiency, getattr(p, "efficiency_se", math.nan) / p.efficiency ** 2)
                        for key, p in kept},
                       min((p.seeds for _, p in kept), default=0))
        caption = (f"Each strategy's longest point (median wall time of one render). Renders shorter than "
                   f"{short} are timing noise (launch overhead and scheduler jitter): such a point is not "
                   f"ranked and is listed last, and the slope is fitted only over points of at least {short}.")
        untimed = [label(key) for _, key, p, _ in rows if not timing_trusted(p)]
        if untimed:
            caption += (f" **Not ranked:** {', '.join(untimed)} (no render of {short} or more: add spp or a "
                        f"time budget).")
        floored = [label(key) for _, key, p, _ in rows if timing_trusted(p) and math.isnan(p.efficiency)]
        if floored:
            caption += (f" **Not ranked, at the reference's noise floor:** {', '.join(floored)} (the MSE minus the "
                        f"reference's floor is not above zero, so no efficiency can be told: render the "
                        f"reference with more spp).")
        off = [label(key) for _, key, p, _ in rows if missed_budget(p)]
        if off:
            caption += (f" **Off budget:** {', '.join(off)} (median time outside {tolerance_text()} of its time "
                        f"budget): ranked by the time it took, not as a render at its budget.")
        verdict = [] if len(ranked) < 2 else [
            "", f"**Most efficient:** {best.text()}{left_out_note(left)} (efficiency +- its standard error over "
                f"the seeds; the cost "
                f"ratio's interval at Student's t over the seeds)."]
        return ["", "### Efficiency (largest sample count), ranked", "", caption, "", *markdown_table(header, body),
                *verdict,
                *slope_note([(label(key), fit) for _, key, _, fit in rows], "slope column"),
                *self.progressive_note(groups, label)]

    def progressive_note(self, groups, label) -> list[str]:
        """Whether the scene's curves come from progressive runs (experiment/execution/progressive.py) and
        how their times are measured, or why a progressive sweep rendered the scene separately."""
        points = [p for group in groups.values() for p in group]
        if not points:
            return []
        if any(self._run_row(p).get("progressive_run") for p in points):
            return ["", "Progressive runs: one render per seed whose passes accumulate; each point is the image "
                        "after a pass, its time the synchronised elapsed time of the passes so far (compile time "
                        "excluded: a warm-up, and a run that compiled is rendered again). Points of one seed "
                        "share its earlier passes, so they are not independent."]
        blocking = [f"{s['strategy']} / {s['sampler']}: {s['reason']}" for s in self.meta.get("separate", [])
                    if s.get("scene") == points[0].scene]
        if not blocking:
            return []
        return ["", "One render per spp on this scene (not progressive, so that every curve has the same time "
                    "base) because " + "; ".join(blocking) + "."]

    def equal_time_table(self, groups, label) -> list[str]:
        """With time budgets, each strategy's point at each budget (``budget_table``); else each
        curve interpolated (log-log) at times every curve covers. One strategy: nothing to compare."""
        if len(groups) < 2:
            return []
        columns = budget_columns([p for points in groups.values() for p in points])
        if columns:
            return self.budget_table(groups, label, columns)
        curves = {key: curve(points) for key, points in groups.items()}
        budgets = equal_time_budgets(curves)
        if not budgets:
            return ["", "### Equal time", "", "The strategies' time ranges do not overlap: no equal-time "
                    "comparison (add spp levels or time budgets)."]
        body = []
        for key, (times, errors) in curves.items():
            values = [metrics.interpolate_at_time(times, errors, b) if len(times) >= 2 else math.nan
                      for b in budgets]
            body.append([label(key), *(fmt(v) for v in values)])
        return ["", "### Corrected relMSE at equal time (log-log interpolation)", "",
                *markdown_table(["strategy", *(f"{b:.3g} s" for b in budgets)], body)]

    def budget_table(self, groups, label, columns: dict) -> list[str]:
        """Corrected relMSE of each strategy's point at each time budget and its median time,
        columns headed by the budget and the measured range of its points' times
        (``analysis.budget_columns``), points off their budget marked."""
        body = []
        for key, points in groups.items():
            cells = []
            for budget in columns:
                p = next((p for p in points if p.budget_s == budget), None)
                mark = ", **off budget**" if p is not None and missed_budget(p) else ""
                cells.append("n/a" if p is None else f"{fmt(p.rel_mse_corrected)} ({fmt(p.time_s, 2)} s{mark})")
            body.append([label(key), *cells])
        header = ["strategy", *(budget_label(b, c["low"], c["high"]) for b, c in columns.items())]
        return ["", "### Corrected relMSE at each time budget", "",
                "Cells: relMSE minus the reference floor, mean over the seeds, and the median time of one render. "
                "Column headers: the budget and the range of its points' median times. " + budget_rule(), "",
                *markdown_table(header, body)]

    def region_tables(self, scene, groups, label) -> list[str]:
        """Per region each strategy's relMSE and efficiency at its longest point, and the most
        efficient strategy per region. Efficiency and verdict come from the estimate of the
        region tables at each budget (``region_at_budgets``): the cost, the mean over seeds of
        (relMSE - the region's relMSE floor) x that seed's time; with time budgets the verdict is
        that of the largest budget, otherwise of the longest points."""
        names = sorted({n for points in groups.values() for p in points for n in p.regions})
        if not names:
            return []
        ref = self.references[scene]
        rects = self._regions(scene, ref.image.shape[1], ref.image.shape[0])
        floors = {n: region_floor(ref, rects[n]) for n in names if n in rects}
        rel_floors = {n: floors[n]["rel_mse"] if n in floors else 0.0 for n in names}
        header = ["strategy"] + [f"{n} {what}" for n in names for what in ("relMSE", "efficiency")]
        columns, costs, seeds = defaultdict(list), defaultdict(dict), defaultdict(list)
        for key, points in groups.items():
            top = max(points, key=lambda p: p.time_s)
            for n in names:
                r = top.regions[n]
                cost, cost_se = seed_cost(r["rel_mse_seeds"], top.times, rel_floors[n])
                costs[n][label(key)] = (cost, cost_se)
                seeds[n].append(top.seeds)
                columns[(n, "relMSE")].append((r["rel_mse"], r.get("rel_mse_se", math.nan)))
                columns[(n, "efficiency")].append((1.0 / cost, cost_se / cost ** 2))
        cells = {k: fmt_pm_column([v for v, _ in c], [e for _, e in c]) for k, c in columns.items()}
        body = [[label(key), *(cells[(n, what)][i] for n in names for what in ("relMSE", "efficiency"))]
                for i, key in enumerate(groups)]
        md = ["", "### Regions of interest (largest sample count): relMSE and efficiency", "",
              "Efficiency: 1 / cost, the cost the mean over seeds of (region relMSE - the region's reference "
              "floor) x that seed's time, as in the region tables at each budget; +- one standard error over "
              "the seeds.", "", *markdown_table(header, body)]
        md += ["", "Reference noise floor per region (what a perfect render would measure there): " + "; ".join(
            f"{n}: relMSE {fmt(f['rel_mse'])}, MSE {fmt(f['mse'])}, relative standard error of the region "
            f"mean {fmt(100 * f['mean_rel_se'], 2)}%" for n, f in floors.items()) + "."]
        if len(groups) < 2:
            return md
        points = [p for group in groups.values() for p in group]
        budgets = sorted({p.budget_s for p in points if p.budget_s is not None})
        verdicts = []
        at = {(label((p.strategy, p.sampler)), p.budget_s): p for p in points}
        tops = {label(key): max(group, key=lambda p: p.time_s) for key, group in groups.items()}
        for n in names:
            if budgets:
                table = region_at_budgets(points, lambda p: label((p.strategy, p.sampler)), n, rel_floors[n])
                budget, cells_at = max(table.items()) if table else (None, {})
                left = self.left_out_in(scene, rects.get(n), {k: at[(k, budget)] for k in cells_at})
                best = best_of({k: (c["cost"], c["cost_se"]) for k, c in cells_at.items()
                                if not c["off_budget"] and k not in left},
                               min((c["seeds"] for c in cells_at.values()), default=0))
                where = f"{n} at {budget:g} s" if budget is not None else n
            else:
                left = self.left_out_in(scene, rects.get(n), tops)
                best, where = best_of({k: c for k, c in costs[n].items() if k not in left}, min(seeds[n])), n
            if best.winner is not None or left:
                verdicts.append(f"{where}: {best.text()}{left_out_note(left)}")
        if verdicts:
            md += ["", "Most efficient per region (least cost; " + (
                "at the largest time budget, as in the region's table at each budget" if budgets else
                "each strategy's longest point") + "; the cost ratio's interval at Student's t over the seeds): "
                   + "; ".join(verdicts) + "."]
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
            columns = budget_columns(stats)
            at = {(label((p.strategy, p.sampler)), p.budget_s): p for p in stats}
            left = {b: self.left_out_in(scene, rect, {k: at[(k, b)] for k in cells}) for b, cells in table.items()}
            body = [[budget_label(budget, columns[budget]["low"], columns[budget]["high"]),
                     *(budget_cell(c) if (c := cells.get(n)) else "n/a" for n in names),
                     best_of({k: (c["cost"], c["cost_se"]) for k, c in cells.items()
                              if not c["off_budget"] and k not in left[budget]},
                             min(c["seeds"] for c in cells.values())).text() + left_out_note(left[budget])]
                    for budget, cells in table.items()]
            md += ["", f"### Region `{name}` at each time budget", "",
                   f"Cells: relMSE minus the region's reference floor ({fmt(floor['rel_mse'])}) +- one "
                   f"standard error over the seeds, median time of one render (and the slowest seed's "
                   f"over the fastest's where above {TIME_SPREAD_NOTED:g}x), and the cost, the mean over "
                   f"seeds of corrected relMSE x that seed's time, over the best strategy's at that budget: "
                   f"the equal-time relMSE ratio to the best, with its range at one standard error of both "
                   f"(a ratio whose range includes a target has not shown it either way). Rows: the budget and "
                   f"the range of its points' median times; a point off its budget (median time outside "
                   f"{tolerance_text()} of it) is marked and not compared. Most efficient: the least cost, "
                   f"named only where the next one's cost ratio lies outside Student's t standard errors over the "
                   f"seeds.", "", *markdown_table(["budget", *names, "most efficient"], body)]
            md += self._region_bias_table(name, rect, ref, stats, label)
        return md

    def pilot_table(self, groups, label) -> list[str]:
        """Each point whose renders ran a pilot (lab_vcm's ``pilot``): what it chose seed by
        seed, beside each seed's render time, so a point whose times spread (a region cell's
        "times apart") shows why."""
        body = []
        for key, points in groups.items():
            for p in sorted(points, key=lambda p: (p.budget_s or 0.0, p.spp)):
                if not any(p.pilots):
                    continue
                chosen = ", ".join("-" if c is None else c[0] for c in p.pilots)
                seconds = [c[1] for c in p.pilots if c is not None]
                at = f"{p.budget_s:g} s" if p.budget_s else f"{p.spp} spp"
                at += f" (**{off_budget_text(p)}**)" if missed_budget(p) else ""
                body.append([label(key), at, str(p.spp), chosen, ", ".join(fmt(t, 3) for t in p.times),
                             fmt(statistics.median(seconds), 3)])
        if not body:
            return []
        return ["", "### What the pilots chose", "",
                "Per seed, in the rows' order: path tracing alone, or every technique with that many light "
                "subpaths per camera subpath; each seed's render time (the pilot's included) and the "
                "pilot's median seconds.", "",
                *markdown_table(["strategy", "budget", "spp", "chosen per seed", "render s per seed",
                                 "pilot s (median)"], body)]

    def passes_section(self, scene, groups, label) -> list[str]:
        """Bias^2 and variance against passes for the biased, consistent strategies (lab_photon's
        passes, lab_vcm's iterations when it merges, one per spp): bias^2 should fall as they grow."""
        from ...plugins.integrators.estimator import lookup

        md, curves = [], {}
        rel_floor = self.references[scene].rel_mse_floor()
        for key, points in groups.items():
            integrator = self._integrator(points[0])
            unit = PASS_PARAMETER.get(integrator)
            estimator = lookup(integrator)
            if unit is None and estimator is not None and estimator.separate_reason(self._run_row(points[0])
                                                                                   .get("params", {})):
                unit = "spp"                           # (one iteration per sample: lab_vcm)
            if unit is None or len(points) < 2:
                continue
            result = bias_by_passes(points, lambda p: int(self._param(p, unit, p.spp)))
            resolved = [r for r in result["rows"] if r["resolved"]]
            fit = fit_slope([r["passes"] for r in resolved], [r["bias2"] for r in resolved],
                            [r["bias2_se"] for r in resolved], axis=unit)
            curves[label(key)] = result
            header = [unit, "seeds", "time s", "relMSE", "variance", "bias^2 (+- se)", "resolved", "bias^2 / relMSE"]
            body = [[r["passes"], r["seeds"], fmt(r["time_s"]), fmt(r["rel_mse"]), fmt(r["variance"]),
                     fmt_pm(r["bias2"], r["bias2_se"], separation=BIAS_SEPARATION), "yes" if r["resolved"] else r["verdict"],
                     fmt(r["bias2"] / r["rel_mse"] if r["rel_mse"] > 0 else math.nan, 2)] for r in result["rows"]]
            md += ["", f"### {label(key)}: bias^2 and variance against {unit}", "",
                   f"In relMSE's units (pixels weighted by 1 / (ref^2 + 0.01), so the light's edge pixels do "
                   f"not swamp the rest): relMSE = bias^2 + variance + reference floor ({fmt(rel_floor)}); "
                   f"bias^2 +- one standard error (over blocks of pixels), resolved when more than three above "
                   f"zero, \"{UNRELIABLE}\" when more than three below. Log-log slope "
                   f"of the resolved bias^2 against {unit}: {slope_cell(fit)}.", "",
                   *markdown_table(header, body),
                   *slope_note([(label(key), fit)], "above", "theory for progressive photon mapping (alpha 2/3): "
                               "bias^2 falls as passes^(-2/3) where the radiance is smooth, as passes^(-1/3) "
                               "at edges and corners")]
        if curves:
            styles = series_styles(groups, ("strategy", "sampler"))[0]       # the colours of the other plots
            plot = self.plot_passes(scene, curves, {label(key): styles[key] for key in groups if label(key) in curves})
            md += ["", f"![bias^2 and variance against passes]({os.path.basename(plot)})"]
        return md

    def settings_table(self) -> list[str]:
        """Each scene's film size as rendered (its reference's image), and the strategies' and
        samplers' parameters as the runs used them: from each run's identity (defaults filled in;
        a progressive pass count and ``count_rays``, which change no image, left out), else the
        row's own params (older rows). One row per distinct setting, with the scenes it was used
        on when it differs between scenes."""
        settings = defaultdict(set)         # (kind, name, type, params as JSON) -> scenes
        for row in self.store.current_runs():
            ident = row.get("identity") or {}
            integrator = ident.get("integrator") or {"type": row.get("integrator", ""), "params": row.get("params", {})}
            settings[("strategy", row["strategy"], integrator["type"], _params_text(integrator["params"]))].add(
                row["scene"])
            sampler = ident.get("sampler") or {"type": "n/a", "params": None}      # rows before identities
            settings[("sampler", row["sampler"], sampler["type"], _params_text(sampler["params"]))].add(row["scene"])
        if not settings:
            return []
        scenes = {row["scene"] for row in self.store.current_runs()}
        for scene in scenes & set(self.references):        # the film as rendered: the reference's image
            height, width = self.references[scene].image.shape[:2]
            settings[("film", scene, "", f"{width}x{height} pixels (width x height)")].add(scene)
        marks = lambda name, found: sorted({self.marks[(scene, name)] for scene in found if (scene, name) in self.marks})
        body = [[kind, name + "".join(f" ({m})" for m in marks(name, found)) if kind == "strategy" else name, plugin,
                 params, "all" if found == scenes else ", ".join(sorted(found))]
                for (kind, name, plugin, params), found in sorted(settings.items())]
        return ["", "## Settings", "",
                "Film sizes and parameters as rendered, defaults filled in (the sample count is each point's "
                "own; a progressive pass count and count_rays are left out).", "",
                *markdown_table(["kind", "name", "plugin", "parameters", "scenes"], body)]

    def left_out_why(self, p, rect=None) -> str:
        """Why point ``p`` is left out of a "most efficient" verdict (in region ``rect``, or over
        the image): "biased here" where its bias^2 is resolved there, or over the image where its
        image mean is off the reference's (``bias.mean_biased``: a bias^2 spread thin over the
        pixels can stay unresolved while the mean shows it), else "it ignores part of the scene"
        where it is marked so ("ignores media"); "" for a strategy that may be named."""
        if rect is None:           # (getattr: a point that carries no bias estimate has none resolved)
            bias2, se = getattr(p, "rel_bias2", math.nan), getattr(p, "rel_bias2_se", math.nan)
        else:
            _, bias2, se = self.region_bias(p, self.references[p.scene], rect)
        if math.isfinite(bias2) and bias_verdict(bias2, se, p.seeds)[0] == "biased":
            return "biased here"
        if rect is None and mean_biased(p):
            return "biased here (its image mean)"
        return "it ignores part of the scene" if (p.scene, getattr(p, "strategy", None)) in self.marks else ""

    def left_out_in(self, scene, rect, points: dict) -> dict:
        """{label: why} of ``points`` ({label: PointStats} on ``scene``) left out of a region's verdict."""
        return {name: why for name, p in points.items() if (why := self.left_out_why(p, rect))}

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


def left_out_note(left: dict) -> str:
    """", path (ignores media) left out: biased here" after a verdict, for each strategy
    ``left`` ({name: why}) kept out of it: an efficiency ranks consistent estimators only."""
    return "".join(f", {name} left out: {why}" for name, why in left.items())


def _params_text(params: dict | None) -> str:
    """Parameters as one table cell: ``name = value`` pairs, sorted; "(defaults)" when none,
    "(not stored)" when the rows do not say (None)."""
    if params is None:
        return "(not stored)"
    return ", ".join(f"{k} = {v}" for k, v in sorted(params.items())) or "(defaults)"
