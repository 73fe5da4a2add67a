"""From stored rows and images to per-point statistics and comparisons (no rendering).

Definitions used throughout the report:

* MSE and relMSE of a render are measured against the reference; the
  reference's own noise (its "floor", the mean per-pixel variance of its
  mean) is part of every such number. ``mse_corrected = mean MSE - floor``.
* variance = mean over pixels of the per-pixel sample variance across the R
  seeds (the part of one render's error that more samples remove);
* bias^2 = mean_p (mean_r img - ref)^2 - s^2/R - ref variance, with a
  standard error (``metrics.bias_squared``);
* efficiency = 1 / cost, cost = the mean over seeds of (MSE - floor) x that seed's wall time
  (Veach 1997; higher is better; ``seed_cost``); NaN when the cost is not positive (at the
  floor). Per seed, because a strategy that chooses per render (lab_vcm's pilot) takes a
  different time on each seed: mean MSE x median time would charge the slow seeds' small errors
  at the fast seeds' times.
* rel_variance, rel_bias2: the same two on images weighted by 1 / sqrt(ref^2 + 0.01),
  i.e. in relMSE's units (relMSE = rel_bias2 + rel_variance + relative floor), where a bright
  light's pixels do not swamp the rest of the image.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import os
import statistics
from dataclasses import dataclass, field

import numpy as np

from ... import images, metrics
from ..pipeline.budget import missed_budget
from .verdicts import bias_verdict

#: A measured MSE closer than this factor to the reference floor is flagged.
FLOOR_WARNING_FACTOR = 10.0
#: Renders whose median wall time is shorter than this (seconds) are not timed well enough
#: to rank: launch overhead and scheduler jitter of a few milliseconds are then a sizeable
#: part of the time (a user's 10 ms, 4 spp point once topped an efficiency ranking).
MIN_TRUSTED_TIME_S = 0.05


def timing_trusted(point) -> bool:
    """Whether ``point``'s median render time is long enough to enter an efficiency ranking
    or a fit against time (``MIN_TRUSTED_TIME_S``)."""
    return point.time_s >= MIN_TRUSTED_TIME_S


@dataclass
class PointStats:
    point: str
    scene: str
    strategy: str
    sampler: str
    spp: int
    budget_s: float | None
    seeds: int
    time_s: float                   # median wall time of one render
    kernel_s: float
    mse: float                      # mean over seeds (raw)
    mse_std: float
    rel_mse: float
    rel_mse_std: float
    mse_corrected: float
    rel_mse_corrected: float
    variance: float
    bias2: float
    bias2_se: float
    efficiency: float
    near_floor: bool
    rel_variance: float = math.nan
    rel_bias2: float = math.nan
    rel_bias2_se: float = math.nan
    flip: float = math.nan
    ciede2000: float = math.nan
    rays_per_sample: dict = field(default_factory=dict)
    regions: dict = field(default_factory=dict)       # name -> {mse, rel_mse, rel_mse_se, mse_seeds, rel_mse_seeds}
    times: list = field(default_factory=list)         # each seed's wall time (the rows' order)
    images: list = field(default_factory=list)        # stored image paths (relative to the sweep folder)
    pilots: list = field(default_factory=list)        # each seed's pilot_choice (None: no pilot)
    efficiency_se: float = math.nan                   # over the seeds (``seed_cost``'s error)
    mean_ratio: float = math.nan                      # image mean over the reference's, mean over seeds
    mean_ratio_se: float = math.nan                   # its standard error (seeds and reference)
    mean_ratio_block_se: float = math.nan             # the same from the pixel blocks' spread (``mean_ratio``)


@functools.lru_cache(maxsize=512)
def run_image(folder: str, relative_path: str) -> np.ndarray:
    """A stored run image, read once: the bias table, Veach's bound per region and the
    image strip all come back to the same files."""
    image = images.read_exr(os.path.join(folder, relative_path))[0]
    image.setflags(write=False)
    return image


def _mean(values):
    values = [v for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]
    return float(np.mean(values)) if values else math.nan


def _std(values):
    return float(np.std(values, ddof=1)) if len(values) > 1 else math.nan


def seed_cost(errors, times, floor: float = 0.0) -> tuple[float, float]:
    """(cost, its standard error): the mean over seeds of (error - floor) x that seed's render
    time, an error x time product that is the same at every time for an estimator whose error
    falls as 1 / time, so it compares renders that missed their budget by a little, or (a pilot
    that chooses per render) by a lot. NaN cost when not positive (at the floor); NaN error with
    one seed."""
    products = (np.asarray(errors, dtype=np.float64) - floor) * np.asarray(times, dtype=np.float64)
    cost = float(products.mean()) if products.size else math.nan
    error = float(products.std(ddof=1) / math.sqrt(products.size)) if products.size > 1 else math.nan
    return (cost if cost > 0 else math.nan), error


def pilot_choice(stats: dict) -> tuple[str, float] | None:
    """(what a render's pilot chose, its seconds) from the integrator's statistics of that
    render (a run row's ``integrator_stats``): lab_vcm with ``pilot`` chooses path tracing alone
    ("path tracing") or every technique with a number of light subpaths per camera subpath
    (that number); None for a render without a pilot."""
    if not stats.get("pilot_s"):
        return None
    chosen = "path tracing" if stats.get("chose_path_tracing") else f"{stats.get('light_paths_chosen', 0.0):g}"
    return chosen, float(stats["pilot_s"])


def pilot_light_paths(stats: dict) -> float | None:
    """The light subpaths per camera subpath a render's pilot chose, 0 for path tracing alone;
    None for a render without a pilot (results.csv's ``pilot_light_paths``)."""
    return None if pilot_choice(stats) is None else float(stats.get("light_paths_chosen", 0.0))


def efficiency_of(errors, times, floor: float = 0.0) -> float:
    """1 / ``seed_cost`` (NaN at the floor)."""
    return 1.0 / seed_cost(errors, times, floor)[0]          # (NaN at the floor)


def bias_tile(shape) -> int:
    """The block side (pixels) of bias^2's standard error (``metrics.bias_squared``'s ``tile``):
    8, or less on a small image so that at least 64 blocks remain. A photon map's kernel or a
    wide filter correlates neighbouring pixels, and a standard error that treats them as
    independent resolved a bias^2 from 2 seeds of an unbiased estimator."""
    height, width = shape[:2]
    return max(1, min(8, int(math.sqrt(height * width / 64))))


def relative_bias_variance(stack: np.ndarray, reference) -> tuple[float, float, float]:
    """(variance, bias^2, its standard error) in relMSE's units: every image and the reference
    multiplied by 1 / sqrt(ref^2 + 0.01), the reference's variance by its square."""
    weight = 1.0 / np.sqrt(reference.image.astype(np.float64) ** 2 + 1e-2)
    weighted = stack * weight
    bias2, se = metrics.bias_squared(weighted, reference.image * weight, reference.variance * weight ** 2,
                                     tile=bias_tile(reference.image.shape))
    return metrics.mean_variance(weighted), bias2, se


def point_stats(rows: list[dict], folder: str, reference) -> PointStats:
    """Aggregate the R run rows of one point (and their stored images)."""
    first = rows[0]
    stack = np.stack([run_image(folder, r["image"]) for r in rows])
    mse = [r["mse"] for r in rows]
    rel = [r["rel_mse"] for r in rows]
    times = [r["wall_s"] for r in rows]
    time_s = statistics.median(times)
    floor, rel_floor = reference.mse_floor, reference.rel_mse_floor()
    bias2, bias2_se = metrics.bias_squared(stack, reference.image, reference.variance,
                                           tile=bias_tile(reference.image.shape))
    cost, cost_se = seed_cost(mse, times, floor)
    ratio, ratio_se, ratio_block_se = mean_ratio(stack, reference)
    samples = first["spp"] * stack.shape[1] * stack.shape[2]
    rays = {k: _mean([r["rays"].get(k, 0) for r in rows]) / samples for k in first.get("rays", {})}
    regions = {}
    for name in first.get("regions", {}):
        region_mse = _mean([r["regions"][name]["mse"] for r in rows])
        region_rel = [r["regions"][name]["rel_mse"] for r in rows]
        regions[name] = {"mse": region_mse, "rel_mse": _mean(region_rel),
                         "rel_mse_se": _std(region_rel) / math.sqrt(len(region_rel)),
                         "mse_seeds": [r["regions"][name]["mse"] for r in rows], "rel_mse_seeds": region_rel}
    corrected = _mean(mse) - floor
    rel_variance, rel_bias2, rel_bias2_se = relative_bias_variance(stack, reference)
    return PointStats(
        point=first["point"], scene=first["scene"], strategy=first["strategy"], sampler=first["sampler"],
        spp=first["spp"], budget_s=first.get("budget_s"), seeds=len(rows), time_s=time_s,
        kernel_s=statistics.median(r["kernel_s"] for r in rows), mse=_mean(mse), mse_std=_std(mse),
        rel_mse=_mean(rel), rel_mse_std=_std(rel), mse_corrected=corrected,
        rel_mse_corrected=_mean(rel) - rel_floor, variance=metrics.mean_variance(stack), bias2=bias2,
        bias2_se=bias2_se, efficiency=1.0 / cost, efficiency_se=cost_se / cost ** 2,
        mean_ratio=ratio, mean_ratio_se=ratio_se, mean_ratio_block_se=ratio_block_se,
        near_floor=_mean(mse) < FLOOR_WARNING_FACTOR * floor, rel_variance=rel_variance,
        rel_bias2=rel_bias2, rel_bias2_se=rel_bias2_se,
        flip=_mean([r.get("flip") for r in rows]), ciede2000=_mean([r.get("ciede2000") for r in rows]),
        rays_per_sample=rays, regions=regions, times=times, images=[r["image"] for r in rows],
        pilots=[pilot_choice(r.get("integrator_stats") or {}) for r in rows])


def mean_ratio(stack: np.ndarray, reference) -> tuple[float, float, float]:
    """(the image mean over the reference's, averaged over the seeds; its standard error from the
    seeds' spread; its standard error from the pixel blocks' spread): the quickest bias check, 1
    within its interval for an unbiased strategy. Both errors include the reference's own noise
    (its mean's relative standard error). The first holds for any estimator but comes from a few
    numbers: three seeds whose image means happen to lie close understate it, and an unbiased
    estimator reads "biased". The second pools each ``bias_tile`` block's variance over the seeds
    (many degrees of freedom), and holds while blocks are uncorrelated; a verdict needs both
    (``bias.mean_biased``)."""
    ref = reference.image.astype(np.float64)
    ref_mean = float(ref.mean())
    if not ref_mean > 0:
        return math.nan, math.nan, math.nan
    seeds = stack.shape[0]
    ratios = stack.reshape(seeds, -1).astype(np.float64).mean(axis=1) / ref_mean
    ratio = float(ratios.mean())
    ref_rel_se = math.sqrt(float(np.mean(reference.variance)) / ref[..., 0].size) / ref_mean
    if seeds < 2:
        return ratio, math.nan, math.nan
    seeds_se = float(ratios.std(ddof=1) / math.sqrt(seeds))
    blocks = _block_means(stack.astype(np.float64), bias_tile(stack.shape[1:3]))
    # the image mean is the blocks' mean (equal blocks): its variance is their variances' sum over B^2
    blocks_se = math.sqrt(float(blocks.var(axis=0, ddof=1).sum()) / seeds) / blocks.shape[1] / ref_mean
    return ratio, math.hypot(seeds_se, ratio * ref_rel_se), math.hypot(blocks_se, ratio * ref_rel_se)


def _block_means(stack: np.ndarray, tile: int) -> np.ndarray:
    """(seeds, blocks) means of ``tile`` x ``tile`` pixel blocks, channels averaged; the film's
    last rows and columns that do not fill a block are left out."""
    seeds, height, width = stack.shape[:3]
    rows, cols = height // tile, width // tile
    cut = stack[:, :rows * tile, :cols * tile].reshape(seeds, rows * tile, cols * tile, -1).mean(axis=3)
    return cut.reshape(seeds, rows, tile, cols, tile).mean(axis=(2, 4)).reshape(seeds, rows * cols)


def region_stack(stats: PointStats, folder: str, rect) -> np.ndarray:
    """The point's stored images (one per seed) cropped to a region, stacked."""
    return np.stack([metrics.region(run_image(folder, p), rect) for p in stats.images])


def region_stack_stats(stats: PointStats, folder: str, reference, rect) -> dict:
    """Inside a region: variance (mean per-pixel, across seeds) with its jackknife standard
    error over the seeds, and the mean square of the reference."""
    stack = region_stack(stats, folder, rect)
    ref = metrics.region(reference.image, rect).astype(np.float64)
    r = stack.shape[0]
    leave_one_out = np.array([metrics.mean_variance(np.delete(stack, k, axis=0)) for k in range(r)]) \
        if r >= 3 else np.array([math.nan])
    jackknife_se = float(np.sqrt((r - 1) / r * np.sum((leave_one_out - leave_one_out.mean()) ** 2)))
    return {"variance": metrics.mean_variance(stack), "variance_se": jackknife_se,
            "ref_mean_square": float(np.mean(ref ** 2))}


def region_bias_variance(stats: PointStats, folder: str, reference, rect) -> tuple[float, float, float]:
    """Inside a region, in relMSE's units: (variance across the seeds, bias^2, its standard
    error), as ``relative_bias_variance`` on the region's pixels (NaN with fewer than two
    seeds). Their sum plus the region's floor is the region's relMSE, so this tells which of
    the two a longer render or a smaller merging radius would remove."""
    if len(stats.images) < 2:
        return math.nan, math.nan, math.nan
    stack = region_stack(stats, folder, rect)
    cropped = dataclasses.replace(reference, image=metrics.region(reference.image, rect),
                                  variance=metrics.region(reference.variance, rect))
    return relative_bias_variance(stack, cropped)


def curve(points: list[PointStats], key: str = "rel_mse_corrected"):
    """(times, errors) of one strategy's points, sorted by time, positive errors only."""
    pairs = sorted((p.time_s, getattr(p, key)) for p in points if getattr(p, key) > 0 and p.time_s > 0)
    return [t for t, _ in pairs], [e for _, e in pairs]


def equal_time_budgets(curves: dict[str, tuple[list, list]], count: int = 3) -> list[float]:
    """Time budgets every strategy's curve covers (geometric between the common bounds)."""
    usable = [c for c in curves.values() if len(c[0]) >= 2]
    if not usable:
        return []
    lo = max(min(t) for t, _ in usable)
    hi = min(max(t) for t, _ in usable)
    if not hi > lo:
        return []
    return [float(v) for v in np.geomspace(lo, hi, count)]


def slope(times, errors) -> float:
    return metrics.loglog_slope(times, errors) if len(times) >= 2 and len(set(times)) >= 2 else math.nan


def veach_bound(balance: dict, other: dict, n_emitter: int, spp: int) -> dict:
    """Veach's bound on the balance heuristic (Veach 1997, Theorem 9.2):

        Var[F_balance] <= Var[F_other] + (1/min n_i - 1/sum n_i) I^2

    for one pixel sample (n_L emitter samples and 1 BSDF sample); the pixel
    estimate averages ``spp`` such samples, which divides both variances and the
    slack by spp. Averaged over a region's pixels with I^2 = ref^2 per pixel.
    The variances are estimates over R seeds; the verdict is "holds" when the
    measured lhs <= rhs, "within noise" when the excess is below two standard
    errors of the difference (jackknife, the two treated as independent), else
    "violated"; an excess with no standard error (fewer than three seeds) is not resolved.
    """
    slack = (1.0 / min(n_emitter, 1) - 1.0 / (n_emitter + 1)) * balance["ref_mean_square"] / spp
    rhs = other["variance"] + slack
    excess = balance["variance"] - rhs
    se = math.hypot(balance["variance_se"], other["variance_se"])
    if excess <= 0:
        verdict = "holds"
    elif not math.isfinite(se):             # (jackknife errors need three seeds)
        verdict = "not resolved with 2 seeds (needs at least 3)"
    else:
        verdict = "within noise" if excess <= 2 * se else "violated"
    return {"lhs": balance["variance"], "rhs": rhs, "slack": slack, "se": se, "verdict": verdict}


def region_floor(reference, rect) -> dict:
    """The reference's own noise inside a region: the MSE and relMSE floors (what a perfect
    render would measure there) and the relative standard error of the region's mean."""
    ref = metrics.region(reference.image, rect).astype(np.float64)
    var = metrics.region(reference.variance, rect).astype(np.float64)
    mean = float(ref.mean())
    return {"mse": float(var.mean()), "rel_mse": float(np.mean(var / (ref ** 2 + 1e-2))),
            "mean": mean, "mean_rel_se": math.sqrt(var.mean() / ref[..., 0].size) / mean if mean > 0 else math.nan}


def region_at_budgets(points: list[PointStats], label, region: str, rel_floor: float) -> dict:
    """Per time budget, each strategy's region relMSE (raw and minus the region's floor), its
    standard error over the seeds, median time, and its cost ratio to the best: its cost (the
    mean over seeds of corrected relMSE x that seed's time, ``seed_cost``) over the smallest at
    that budget. The product, not the relMSE alone, because calibrated renders miss their budget
    by a little, and a pilot that chooses per render (lab_vcm's) by a lot; for an estimator whose
    error falls as 1/time it is the equal-time ratio. ``time_spread`` is the slowest seed's time
    over the fastest's.

    ``x_best_range`` is that ratio one standard error either way: both costs' relative standard
    errors combined on the log of the ratio (independent seeds; (1, 1) for the best itself, NaN
    without the errors). A few seeds of a heavy-tailed region swing the ratio far, so a target
    read from one sweep needs it.

    A point whose median time is off its budget (``budget.missed_budget``) is not an equal-time
    render: its cell is kept, marked (``off_budget``), and left out of the ratios (NaN), neither
    best nor compared.

    Returns {budget: {label: {rel_mse, rel_mse_corrected, rel_mse_se, time_s, time_spread, cost,
    cost_se, seeds, x_best, x_best_range, budget_s, off_budget}}}."""
    table = {}
    for p in points:
        if p.budget_s is None or region not in p.regions:
            continue
        raw = p.regions[region]["rel_mse"]
        cost, cost_se = seed_cost(p.regions[region]["rel_mse_seeds"], p.times, rel_floor)
        cell = {"rel_mse": raw, "rel_mse_corrected": raw - rel_floor, "time_s": p.time_s,
                "time_spread": max(p.times) / min(p.times) if min(p.times) > 0 else math.nan,
                "rel_mse_se": p.regions[region].get("rel_mse_se", math.nan), "cost": cost, "cost_se": cost_se,
                "seeds": len(p.times), "budget_s": p.budget_s, "off_budget": missed_budget(p)}
        table.setdefault(p.budget_s, {})[label(p)] = cell
    for cells in table.values():
        # (NaN cost: at the floor; off budget: not an equal-time render)
        measured = [c for c in cells.values() if not math.isnan(c["cost"]) and not c["off_budget"]]
        best = min(measured, key=lambda c: c["cost"], default=None)
        for c in cells.values():
            compared = best is not None and not c["off_budget"]
            c["x_best"] = c["cost"] / best["cost"] if compared else math.nan
            c["x_best_range"] = ratio_range(c, best) if compared else (math.nan, math.nan)
    return dict(sorted(table.items()))


def budget_columns(points: list[PointStats]) -> dict[float, dict]:
    """Per time budget (ascending), the measured times of its points: {budget: {"low", "high":
    the smallest and largest median time of a point at it, "off": how many of them are off
    the budget (``budget.missed_budget``)}}: what an equal-time column's header states."""
    columns: dict[float, list] = {}
    for p in points:
        if p.budget_s is not None:
            columns.setdefault(p.budget_s, []).append(p)
    return {b: {"low": min(p.time_s for p in ps), "high": max(p.time_s for p in ps),
                "off": sum(missed_budget(p) for p in ps)} for b, ps in sorted(columns.items())}


def ratio_range(cell: dict, best: dict) -> tuple[float, float]:
    """``cell``'s cost over ``best``'s, one standard error down and up (``region_at_budgets``)."""
    if cell is best:
        return 1.0, 1.0
    if math.isnan(cell["cost"]):                 # (at or below the floor: no ratio)
        return math.nan, math.nan
    log_se = math.hypot(cell["cost_se"] / cell["cost"], best["cost_se"] / best["cost"])
    if math.isnan(log_se):
        return math.nan, math.nan
    ratio = cell["cost"] / best["cost"]
    return ratio * math.exp(-log_se), ratio * math.exp(log_se)


def bias_by_passes(points: list[PointStats], passes_of) -> dict:
    """Relative bias^2 and variance (relMSE's units) of one progressive strategy against its
    pass count.

    ``passes_of(point)`` gives a point's passes. Rows sorted by passes, each with relMSE, the
    relative variance, the relative bias^2 estimate, its standard error, whether it is
    resolved (more than ``verdicts.BIAS_SEPARATION`` standard errors above zero), ``verdict``
    (``bias_verdict``) and ``needed`` (the seeds that would resolve it); ``slope`` is the
    log-log slope of bias^2 against passes over the resolved rows (NaN with fewer than two):
    negative when the bias shrinks as passes grow.
    """
    rows = []
    for p in sorted(points, key=passes_of):
        verdict, needed = bias_verdict(p.rel_bias2, p.rel_bias2_se, p.seeds)
        rows.append({"passes": passes_of(p), "time_s": p.time_s, "rel_mse": p.rel_mse,
                     "variance": p.rel_variance, "bias2": p.rel_bias2, "bias2_se": p.rel_bias2_se,
                     "resolved": verdict == "biased", "verdict": verdict, "needed": needed, "seeds": p.seeds})
    resolved = [r for r in rows if r["resolved"]]
    fit = slope([r["passes"] for r in resolved], [r["bias2"] for r in resolved]) if len(resolved) >= 2 else math.nan
    return {"rows": rows, "slope": fit}
