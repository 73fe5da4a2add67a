"""The report's section on Veach's bound: the balance heuristic against each other lab_mis
weighting of the same samples (Veach 1997)."""
from __future__ import annotations

from collections import defaultdict

from ...plugins.params import resolve as resolve_params
from ...reporting import fmt, markdown_table
from .analysis import PointStats, region_stack_stats, veach_bound


class VeachSection:
    """A mixin of the report (``tables.SectionTables``): it reads the report's
    ``folder``, ``references``, ``shown``, ``_run_row``, ``_integrator`` and ``_regions``."""

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
        from ...plugins.integrators.mis import MIS

        heuristic, beta = MIS.weighting(str(params.pop("heuristic", "power")), float(params.pop("beta", 2.0)))
        n_l = int(params.pop("emitter_samples", 1))
        weighting = heuristic if beta is None else f"power (beta {beta:g})"
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
                            rows.append([sampler, n_l, self.shown(scene, bname), self.shown(scene, oname),
                                         weighting, bp.spp, name, fmt(v["lhs"]),
                                         fmt(v["rhs"]), fmt(v["se"], 2), v["verdict"]])
        md = ["", "### Veach's bound: Var[balance] <= Var[other] + (1/min n_i - 1/sum n_i) I^2", "",
              "Each weighting against the balance heuristic on the same sampler with the same emitter_samples "
              "(n_L shadow rays and 1 BSDF sample per vertex, so min n_i = 1 and sum n_i = n_L + 1) and "
              "otherwise the same parameters, at equal spp."]
        if rows:
            md += ["", *markdown_table(["sampler", "emitter_samples", "balance", "other", "weighting", "spp", "region",
                                        "Var balance", "Var other + slack", "standard error", "verdict"], rows)]
        for line in unmatched:
            md += ["", f"Not compared: {line}."]
        if not rows and not unmatched:      # (one lab_mis weighting alone: nothing to say)
            return []
        md.append("")
        md.append("Variances are sample variances over the seeds (jackknife standard errors); "
                  "'within noise' means the excess is under two standard errors. The bound is exact for "
                  "direct lighting (max_depth 2); with longer paths it is indicative only.")
        return md
