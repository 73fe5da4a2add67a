"""The bias tables of a scene's section in the sweep report: bias and variance per point, each
strategy's image mean over the reference's, and a region's variance / bias^2 at each budget.

``BiasTables`` is mixed into ``tables.SectionTables`` (the state it reads is described
there); the cells' verdicts are ``verdicts.bias_verdict``'s.
"""
from __future__ import annotations

import math

from ...reporting import fmt, fmt_pm, markdown_table
from ...reporting.numbers import digits_for_error
from .analysis import region_bias_variance
from ..pipeline.budget import missed_budget, off_budget_text
from .verdicts import BIAS_SEPARATION, UNRELIABLE, bias_verdict, not_resolved, seeds_needed, separation_factor

#: A "biased" image mean is a two-sided test at 1% (Student's t's and the normal's 99.5% quantiles): it
#: takes a strategy out of the image's "most efficient" verdict, and three seeds of an unbiased but
#: heavy-tailed estimator (a small light seen in a rough-plastic sphere by lab_nee) lie below its mean
#: more often than a 5% test allows for.
MEAN_QUANTILE = 0.995
#: the normal distribution's MEAN_QUANTILE quantile (the pixel blocks' error has many degrees of freedom)
MEAN_SEPARATION = 2.576


class BiasTables:
    def bias_table(self, stats) -> list[str]:
        header = ["point", "seeds", "variance", "bias^2 (+- se)", "relative variance", "relative bias^2 (+- se)",
                  "relMSE floor-corrected"]
        body = [[self.shown(s.scene, s.strategy, s.point) + off_budget_mark(s), s.seeds, fmt(s.variance),
                 bias_cell(s.bias2, s.bias2_se, s.seeds), fmt(s.rel_variance),
                 bias_cell(s.rel_bias2, s.rel_bias2_se, s.seeds), fmt(s.rel_mse_corrected)] for s in stats]
        return ["", "### Bias and variance per point", "",
                "Relative: the same in relMSE's units (pixels weighted by 1 / (ref^2 + 0.01)). bias^2 is an "
                "estimate (the seed mean's squared error minus its expected noise), so for an unbiased "
                "estimator it scatters around zero and is negative about as often as positive. Its standard "
                "error is taken over blocks of pixels (neighbouring pixels of a blurring estimator are not "
                "independent). Marked \"biased\" more than three standard errors above zero (a table of many "
                "points: at two, unbiased estimators would show one now and then); more than three below "
                f"zero, where no bias^2 can be, \"{UNRELIABLE}\": the seeds' variance estimate is off, not "
                "the bias absent; otherwise \"not resolved with N seeds (needs about M)\", M the seeds at "
                "which an estimate of this size would be three standard errors from zero (an unbiased "
                "estimator's keeps shrinking, so no number of seeds resolves it); a negative estimate names "
                "no M (more seeds would flag it, never resolve a bias). Estimate and error carry the digits "
                "that show on which side of three standard errors it lies.", "",
                *markdown_table(header, body)]

    def mean_table(self, groups, label) -> list[str]:
        """Per strategy (its longest point) the image mean over the reference's, with its 99%
        interval over the seeds: the quickest bias check, 1 within the interval for an unbiased
        strategy."""
        body = []
        for key, points in groups.items():
            p = max(points, key=lambda q: q.time_s)
            half = separation_factor(p.seeds, MEAN_QUANTILE) * p.mean_ratio_se
            gap = abs(p.mean_ratio - 1.0)
            if mean_biased(p):
                verdict = f"biased: {100 * (p.mean_ratio - 1):+.2g}%"
            else:
                verdict = not_resolved(p.seeds, seeds_needed(p.seeds, gap, p.mean_ratio_se, quantile=MEAN_QUANTILE))
            body.append([label(key), p.spp, fmt(p.time_s), p.seeds, _interval(p.mean_ratio, half), verdict])
        if not body:
            return []
        return ["", "### Image mean over the reference's", "",
                "Each strategy's longest point: the mean over its seeds of the image's mean over the "
                "reference's image mean, with its 99% interval (Student's t over the seeds, the reference's "
                "own noise included). Off 1 by more than the interval, and by more than 2.58 standard errors "
                "taken from the spread of pixel-block means (up to 8x8 pixels) over the seeds (a few seeds "
                "whose means lie close by chance make the interval too narrow): biased (a bias that cancels over the image "
                "does not show here; the bias table does).", "",
                *markdown_table(["strategy", "spp", "time s", "seeds", "mean / reference mean (99% interval)",
                                 "verdict"], body)]

    def _region_bias_table(self, name, rect, ref, stats, label) -> list[str]:
        """Per budget, each strategy's relative variance and bias^2 inside one region: whether
        its error there is noise (more time removes it) or bias (a consistent estimator's blur,
        which its schedule removes more slowly)."""
        cells = {}
        for p in stats:
            if p.budget_s is not None and len(p.images) >= 2:
                cells.setdefault(p.budget_s, {})[label((p.strategy, p.sampler))] = \
                    (*self.region_bias(p, ref, rect), p.seeds, off_budget_mark(p))
        if not cells:
            return []
        names = sorted({n for row in cells.values() for n in row})
        body = [[f"{budget:g} s", *(f"{fmt(c[0])} / {bias_cell(c[1], c[2], c[3])}{c[4]}" if (c := row.get(n))
                                    else "n/a" for n in names)] for budget, row in sorted(cells.items())]
        return ["", f"Region `{name}`: relative variance / bias^2 +- its standard error (relMSE's units; "
                    f"with the floor they add up to the region's relMSE; bias^2 is an estimate, near zero "
                    f"or below for an unbiased strategy; its verdict as in the bias table; a point off its "
                    f"budget is marked).", "", *markdown_table(["budget", *names], body)]

    def region_bias(self, p, ref, rect) -> tuple[float, float, float]:
        """``analysis.region_bias_variance`` of a point in a region, computed once per report."""
        cache = self.__dict__.setdefault("_region_bias_cache", {})
        key = (p.point, tuple(rect))
        if key not in cache:
            cache[key] = region_bias_variance(p, self.folder, ref, rect)
        return cache[key]


def mean_biased(p) -> bool:
    """Whether a point's image mean over the reference's is off 1 by more than its 99% interval over
    the seeds (``mean_table``'s "biased": a light an estimator cannot sample, missing over the image),
    and by more than MEAN_SEPARATION standard errors taken from the pixel blocks
    (``analysis.mean_ratio``): a few seeds whose means lie close by chance make the first interval
    too narrow."""
    ratio, se = getattr(p, "mean_ratio", math.nan), getattr(p, "mean_ratio_se", math.nan)
    gap = abs(ratio - 1.0)
    block_se = getattr(p, "mean_ratio_block_se", math.nan)
    by_seeds = math.isfinite(gap) and math.isfinite(se) and gap > separation_factor(p.seeds, MEAN_QUANTILE) * se
    return by_seeds and (not math.isfinite(block_se) or gap > MEAN_SEPARATION * block_se)


def off_budget_mark(p) -> str:
    """" (**off its 2 s budget: 1.4 s**)" after a point off its time budget (``budget.missed_budget``),
    "" for any other."""
    return f" (**{off_budget_text(p)}**)" if missed_budget(p) else ""


def bias_cell(bias2: float, se: float, seeds: int) -> str:
    """A bias^2 estimate with its standard error and its verdict (``verdicts.bias_verdict``)."""
    if math.isnan(bias2):
        return fmt(bias2)
    return f"{fmt_pm(bias2, se, separation=BIAS_SEPARATION)} ({bias_verdict(bias2, se, seeds)[0]})"


def _interval(value: float, half: float) -> str:
    """"value (low to high)", all three with the digits ``value``'s error needs (the bare value
    where there is no interval)."""
    if not math.isfinite(half):
        return fmt(value)
    digits = digits_for_error(value, half / 2)
    return f"{fmt(value, digits)} ({fmt(value - half, digits)} to {fmt(value + half, digits)})"
