"""Progressive runs: one render per seed whose passes accumulate, with the accumulated image's
error and the synchronised elapsed time recorded after every pass (a *checkpoint*).

Over an spp ladder the passes double the accumulated count (``plan.ladder_passes``: 4, 4, 8,
16, 32 spp for [4, 16, 64]), so one render of the largest count gives the image at 4, 8, 16, 32
and 64 spp, each a point of the error-against-time curve. Pass 0 renders with the run's seed,
pass j with TEA(seed, j) (``pass_seed``), and the image after a pass is the spp-weighted mean
of the passes so far: for an estimator with independent samples that is the same estimator as
one render of the total count (exactly so with a box pixel filter, as every shipped scene has:
each sample then counts in its own pixel only; a wider filter normalises each pass's weights
apart). A scene where some strategy or sampler cannot accumulate (``plan.separate_reason``)
keeps every point on one render per spp, so that all its curves share one time base.

Time: a checkpoint's ``wall_s`` is the sum of its passes' synchronised wall times
(``render.render``: dr.eval + dr.sync_thread before each clock stops); metrics, image copies and
the accumulation are outside the clock. Compile time is kept out by a warm-up of the two
smallest pass sizes (``plan.warmup_sizes``; neither the sample count nor the seed is compiled
into the kernels of the lab integrators or Mitsuba's ``path``); a run that still compiled a
kernel (``cache_misses`` > 0) is rendered again, and ``compile_s`` is reported apart.

Every pass pays a render's fixed cost (Python tracing of the integrator, kernel launches, small
wavefronts that fill fewer cores: 7-14 ms per pass on the quick and veach_mis scenes), so the
elapsed time at N spp exceeds one N-spp render's. Doubling keeps it to one per curve point
(1-spp passes paid it per sample: 4.7x the time of one 64-spp render of a 64x64 Cornell box);
``experiment.checkpoints = "ladder"`` ends passes at the ladder's values only (4, 12, 48 spp:
the same points as separate renders, fewest passes).

Time budgets: passes start at 1 spp and double while the next one is predicted to fit (time =
fixed + per-sample x spp, fitted to the passes so far), then one pass takes what is left; a
pass that overran is dropped, so the run stops at the last pass that fits. The first seed's
passes are then the point's (a calibration row; ``worker.fewer_passes`` renders it again with
fewer where their fixed parts took more than ``budget.FIXED_SHARE`` of the budget), and its
other seeds render the same passes.

Chain estimators (``Estimator.CONTINUES_PASSES``: lab_pssmlt) do not render independent passes:
pass 0 bootstraps and starts the Markov chains, every later pass continues them and returns the
image of its own mutations normalised by their count, so the spp-weighted mean above is the
chains' image after all their mutations (one render's, to float rounding), each checkpoint
unbiased at its own mutation count, and every seed its own bootstrap and chains. The bootstrap
is a cost of pass 0 alone: a budget's fit leaves pass 0 out, and a rescaled budget point takes
its excess off the budget once (``budget.once_cost``; ``worker.rescaled_single_pass`` where a
run kept one pass).

This module renders the passes (``run_passes``); ``worker.execute_progressive`` runs a point's
seeds and makes their rows.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np



@dataclass
class Checkpoint:
    """The accumulated image after ``passes`` passes and what they cost, summed."""
    spp: int
    passes: int
    wall_s: float
    kernel_s: float
    compile_s: float
    cache_misses: int
    rays: dict = field(default_factory=dict)
    image: np.ndarray | None = None
    integrator: dict = field(default_factory=dict)   # the last pass's integrator statistics


def pass_seed(seed: int, index: int) -> int:
    """Seed of pass ``index`` of a run: pass 0 keeps the run's seed (so a progressive run's first
    checkpoint is the separate render of that seed), later ones TEA(seed, index), as lab_bdpt
    seeds its own passes."""
    if index == 0:
        return seed & 0xFFFFFFFF
    import mitsuba as mi

    return int(mi.sample_tea_32(mi.UInt32(seed & 0xFFFFFFFF), mi.UInt32(index))[0][0])


def fit_pass_time(times: list[tuple[int, float]]) -> tuple[float, float]:
    """(fixed seconds, seconds per spp) of one pass, from (spp, wall) of the passes so far; with
    fewer than two distinct sizes, or a fit that is not increasing (timing noise over a fixed
    cost), all the time of the largest passes counts as per-sample cost (an upper bound, so a
    predicted pass is not too large)."""
    sizes = {n for n, _ in times}
    if len(sizes) >= 2:
        per, fixed = np.polyfit([n for n, _ in times], [t for _, t in times], 1)
        if per > 0:
            return max(float(fixed), 0.0), float(per)
    largest = max(sizes)
    return 0.0, max(t for n, t in times if n == largest) / largest


def next_budget_pass(spp: int, times: list[tuple[int, float]], remaining: float) -> tuple[int, bool]:
    """(spp of the next pass, whether it is the last) within a time budget: the first pass 1 spp,
    then the accumulated count while it is predicted to fit, then the most that fits (last);
    0 when not even one sample is predicted to fit."""
    if not times:
        return 1, False
    fixed, per = fit_pass_time(times)
    if fixed + per * spp <= remaining:
        return spp, False
    fits = int((remaining - fixed) / per)
    return (fits, True) if fits >= 1 else (0, True)


def run_passes(render_at, seed: int, sizes=None, budget_s: float | None = None,
               continues: bool = False) -> list[Checkpoint]:
    """Render one progressive run: passes of ``sizes`` spp, or fitted to ``budget_s`` when
    ``sizes`` is None. ``render_at(spp, seed)`` is a timed render -> (image, RenderStats).
    Returns the checkpoint after each pass (spp and times summed, accumulated image).

    ``continues`` (chain estimators, ``Estimator.CONTINUES_PASSES``): passes after the first
    continue the first one's Markov chains (``render_at(spp, seed, True)``) and return the image of
    their own mutations, normalised by their count, so the spp-weighted mean after a pass is the
    chains' image after all their mutations so far. The first pass alone pays the chains' fixed
    cost (the bootstrap), so the budget fit leaves it out: a later pass is predicted from the
    later passes (time = fixed + per spp x spp over them; the first continued pass is 1 spp)."""
    checkpoints: list[Checkpoint] = []
    times: list[tuple[int, float]] = []
    weighted_sum = None
    last = Checkpoint(0, 0, 0.0, 0.0, 0.0, 0)
    while True:
        index = last.passes
        if sizes is not None:
            if index == len(sizes):
                break
            size, final = sizes[index], False
        else:
            size, final = next_budget_pass(last.spp, times, budget_s - last.wall_s)
            if size == 0:
                break
        if continues and index > 0:
            image, stats = render_at(size, pass_seed(seed, index), True)
        else:
            image, stats = render_at(size, pass_seed(seed, index))
        if sizes is None and index > 0 and last.wall_s + stats.wall_s > budget_s:
            break                                   # it overran: the run ends at the pass before
        if not (continues and index == 0):
            times.append((size, stats.wall_s))
        pass_image = image.astype(np.float64) * size
        weighted_sum = pass_image if weighted_sum is None else weighted_sum + pass_image
        rays = {k: last.rays.get(k, 0) + stats.rays.get(k, 0) for k in set(last.rays) | set(stats.rays)}
        last = Checkpoint(last.spp + size, index + 1, last.wall_s + stats.wall_s, last.kernel_s + stats.kernel_s,
                          last.compile_s + stats.compile_s, last.cache_misses + stats.cache_misses, rays,
                          integrator=stats.integrator)
        last.image = (weighted_sum / last.spp).astype(np.float32)
        checkpoints.append(last)
        if final:
            break
    return checkpoints
