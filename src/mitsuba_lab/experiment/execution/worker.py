"""One point of a sweep, as a self-contained task: runs in this process or on a Dask worker.

A task carries everything its renders need (scene and plugin specs, the seeds
still missing, the reference image, the regions, the variant), and returns rows
and images instead of writing them: only the sweep's own process writes the
store, so a task retried after a worker died can never duplicate a row. A progressive
point (``execute_progressive``) returns one row per seed with its checkpoints and their images.
"""
from __future__ import annotations

import functools
import json
import os
import resource
import socket
import time
from dataclasses import dataclass, field

import numpy as np

from ... import metrics
from ..pipeline.budget import (BUDGET_RETRIES, measured_time, once_cost, pass_times, rescaled_count, rescaled_passes,
                               too_many_passes, within_budget)
from ..pipeline.config import PluginSpec, SceneSpec, sample_count_plugin
from ..pipeline.plan import Point, point_id, warmup_sizes
from .progressive import Checkpoint, run_passes

#: Pilot sample counts for time budgets (spp, or passes: config.PASS_PARAMETER): timed renders
#: fit time = fixed + per_sample x count. The first pilots are PILOT_SPP; while their times differ
#: by less than PILOT_BUDGET_FRACTION of the budget, both grow PILOT_GROWTH-fold, so that the
#: per-sample cost is measured above the timing noise (at 2 and 8 spp a small image renders in
#: milliseconds, and a noisy difference extrapolated to seconds gave absurd sample counts).
PILOT_SPP = (2, 8)
PILOT_GROWTH = 4
PILOT_BUDGET_FRACTION = 0.05
#: At most this many growth steps (each compiles a kernel for a new spp).
PILOT_MAX_GROWTH = 6
#: After calibrating, the untimed compile render at the fitted count is checked too: when its time
#: less compilation is off the budget by more than budget.BUDGET_TOLERANCE either way, the count is
#: scaled by (budget - fixed) / (that time - fixed) and rendered again, at most SETTLE_TRIES times. An
#: integrator whose cost per sample depends on the count (lab_vcm's ``pilot`` chooses path tracing
#: alone at some counts and every technique at others) is not linear in it, and a fit from small
#: pilots rendered its 16 s point of the Cornell box in 3.3 s. The timed renders are checked
#: again afterwards (``keep_to_budget``).
SETTLE_TRIES = 3
#: A progressive run whose passes compiled a kernel after the warm-up is rendered again, at most
#: this often (the run that compiled served as a warm-up).
RECOMPILE_RETRIES = 2


@dataclass(frozen=True)
class PointTask:
    point: Point
    scene: SceneSpec
    sampler: PluginSpec
    strategy: PluginSpec            # with the experiment's max_depth applied
    seeds: tuple[int, ...]          # the seeds still missing from the store
    spp: int | None                 # None: calibrate to point.budget_s
    reference_image: np.ndarray
    regions: dict                   # name -> pixel rectangle
    metrics: tuple[str, ...]
    variant: str
    identity: dict = field(default_factory=dict)    # what determines the runs (experiment.identity)
    identity_hash: str = ""
    passes: tuple[int, ...] = ()    # progressive: pass sizes (the point's, or a budget's fitted ones)
    # a resumed budget point: the wall times of its seeds already stored at ``spp`` (they count
    # in its measured time) and the calibration row that chose ``spp`` (its fixed cost rescales)
    stored_times: tuple[float, ...] = ()
    calibration: dict | None = None


@dataclass
class PointResult:
    task: PointTask
    spp: int
    calibration: dict | None = None
    runs: list = field(default_factory=list)     # (row without the image path, image), or for a
                                                 # progressive run (row, [image of each checkpoint])


@functools.lru_cache(maxsize=1)
def _flip_openmp() -> tuple:
    """The OpenMP runtimes FLIP may use (its wheel's own libgomp, the system's), as ctypes handles."""
    import ctypes
    import ctypes.util
    import glob

    import flip_evaluator

    site = os.path.dirname(os.path.dirname(os.path.abspath(flip_evaluator.__file__)))
    paths = glob.glob(os.path.join(site, "flip_evaluator.libs", "libgomp*.so*"))
    paths += [p for p in [ctypes.util.find_library("gomp")] if p]
    handles = []
    for path in paths:
        try:
            handles.append(ctypes.CDLL(path))
        except OSError:
            pass
    return tuple(h for h in handles if hasattr(h, "omp_set_num_threads"))


def flip_one_thread(image: np.ndarray, ref_image: np.ndarray) -> float:
    """HDR-FLIP (``metrics.flip_hdr``) on one OpenMP thread. Its OpenMP threads spin at barriers:
    just after a render, while Dr.Jit's worker threads still spin before sleeping, a 64x64 FLIP
    took 0.9 s instead of 0.05 s on 2 cores, and FLIP's idle threads then slowed the next timed
    render by about 30%. One thread does neither."""
    for runtime in _flip_openmp():
        runtime.omp_set_num_threads(1)
    return metrics.flip_hdr(image, ref_image)


def measure(image: np.ndarray, ref_image: np.ndarray, regions: dict, optional: tuple[str, ...]) -> dict:
    """Error metrics of one render against the reference (raw: the floor is not subtracted)."""
    row = {"mse": metrics.mse(image, ref_image), "rel_mse": metrics.rel_mse(image, ref_image),
           "finite": bool(np.isfinite(image).all()), "negative": int((image < 0).sum())}
    if "flip" in optional:
        row["flip"] = flip_one_thread(image, ref_image)
    if "ciede2000" in optional:
        row["ciede2000"] = metrics.ciede2000_mean(image, ref_image)
    row["regions"] = {}
    for name, rect in regions.items():
        crop, ref_crop = metrics.region(image, rect), metrics.region(ref_image, rect)
        row["regions"][name] = {"mse": metrics.mse(crop, ref_crop), "rel_mse": metrics.rel_mse(crop, ref_crop)}
    return row


# One scene and one integrator stay loaded between tasks of the same group (tasks arrive
# grouped by scene, sampler and strategy), in this process or in each worker process.
_loaded: dict[str, tuple[str, object]] = {}


def _cached(slot: str, key: str, make):
    held = _loaded.get(slot)
    if held is None or held[0] != key:
        _loaded[slot] = (key, make())
    return _loaded[slot][1]


def _integrator(spec: PluginSpec):
    """The strategy's integrator. A lab integrator is told that the sweep has said what it cannot
    render on the scene (a strategy runs there only when experiment.allow_unsupported names it,
    and the report marks it), so it does not log that again at every render."""
    from ...scene import make_integrator

    integrator = make_integrator(spec.type, spec.params)
    if hasattr(integrator, "ESTIMATOR"):
        integrator.unsupported_acknowledged = True
    return integrator


def execute(task: PointTask) -> PointResult:
    from ...runtime import activate
    from ...render import render
    from ...scene_xml import load_scene_variant

    activate(task.variant)                   # a fresh worker process selects the sweep's variant
    scene_key = json.dumps([task.variant, task.scene.path, task.scene.resolution, task.scene.defaults,
                            task.sampler.as_dict()], sort_keys=True, default=str)
    scene = _cached("scene", scene_key, lambda: load_scene_variant(
        task.scene.path, task.scene.resolution, task.sampler.as_dict(), task.scene.defaults))

    def render_at(count: int, seed: int, continues: bool = False):
        """Render with ``count`` camera samples per pixel (spp, or passes: sample_count_plugin);
        ``continues``: a chain estimator continues its last render's chains (progressive.run_passes)."""
        spec, spp = sample_count_plugin(task.strategy, count)
        integrator = _cached("integrator", scene_key + json.dumps(spec.as_dict(), sort_keys=True),
                             lambda: _integrator(spec))
        if hasattr(integrator, "continue_chains"):
            integrator.continue_chains = continues
        return render(scene, integrator, spp=spp, seed=seed)

    if task.point.progressive:
        return execute_progressive(task, render_at)
    return execute_counted(task, render_at)


def execute_counted(task: PointTask, render_at) -> PointResult:
    """A point of one render per seed at one sample count: the point's, or one calibrated to its
    time budget and kept there (``keep_to_budget``). ``render_at(count, seed)`` -> (image, stats)."""
    result = PointResult(task, task.spp or 0)
    if not task.spp:
        result.spp, result.calibration = calibrate(task.point, render_at)
        result.calibration["identity_hash"] = task.identity_hash
    _, stats = render_at(result.spp, task.point.warmup_seed)                 # compile, untimed
    if result.calibration:
        result.spp = settle(task.point, render_at, result.spp, stats, result.calibration)
    result.runs = render_seeds(task, render_at, result.spp, task.seeds)
    if task.point.budget_s is not None:
        keep_to_budget(task, render_at, result)
    return result


def render_seeds(task: PointTask, render_at, spp: int, seeds) -> list:
    """The timed render of each seed at ``spp``: [(row without the image path, image)]."""
    runs = []
    for seed in seeds:
        image, stats = render_at(spp, seed)
        row = {**run_row(task, seed, spp), "wall_s": stats.wall_s, "kernel_s": stats.kernel_s,
               "compile_s": stats.compile_s, "rays": stats.rays, "integrator_stats": stats.integrator,
               **measure(image, task.reference_image, task.regions, task.metrics)}
        runs.append((row, image))
    return runs


def keep_to_budget(task: PointTask, render_at, result: PointResult) -> None:
    """Check a budget point's measured time (the median over its seeds, those already stored
    included) against its budget; while it is off by more than budget.BUDGET_TOLERANCE, rescale
    the count by the measured time and render every seed of the point again (BUDGET_RETRIES at
    most). Only the last renders stay in ``result``; the calibration row records each try
    (``budget_tries``: count, measured seconds) and the count kept. Deterministic given the
    render times: the clock is read only by ``render_at``."""
    point = task.point
    base = result.calibration or dict(task.calibration or {})
    fixed = base.get("fixed_s", 0.0)
    stored = list(task.stored_times)
    tries = []
    for retry in range(BUDGET_RETRIES + 1):
        times = stored + [row["wall_s"] for row, _ in result.runs]
        tries.append({"spp": result.spp, "measured_s": measured_time(times), "times": times})
        if within_budget(tries[-1]["measured_s"], point.budget_s) or retry == BUDGET_RETRIES:
            break
        result.spp = rescaled_count(result.spp, tries[-1]["measured_s"], point.budget_s, fixed)
        render_at(result.spp, point.warmup_seed)                            # compile, untimed
        # all the point's seeds, the stored ones too: one point, one count
        result.runs = render_seeds(task, render_at, result.spp, point.seeds if stored else task.seeds)
        stored = []
    if result.calibration is None and len(tries) == 1:
        return                               # a resumed point at its budget: its calibration stands
    result.calibration = {**base, "kind": "calibration", "point": point.id, "budget_s": point.budget_s,
                          "identity_hash": task.identity_hash, "spp": result.spp, "budget_tries": tries,
                          "within_budget": within_budget(tries[-1]["measured_s"], point.budget_s)}


def run_row(task: PointTask, seed: int, spp: int) -> dict:
    """The fields of a run row that are not timings or metrics."""
    return {"kind": "run", "point": task.point.id, "scene": task.point.scene, "strategy": task.point.strategy,
            "sampler": task.point.sampler, "spp": spp, "budget_s": task.point.budget_s, "seed": seed,
            "integrator": task.strategy.type, "params": sample_count_plugin(task.strategy, spp)[0].params,
            "identity": task.identity, "identity_hash": task.identity_hash,
            "host": socket.gethostname(), "pid": os.getpid(),
            # process-wide high-water mark so far (Linux reports KiB): cheap, not per render
            "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "finished": time.time()}


def execute_progressive(task: PointTask, render_at) -> PointResult:
    """A progressive point's runs, one per missing seed, as rows with their checkpoints; a budget
    point's kept to its budget (``keep_passes_to_budget``)."""
    sizes = tuple(task.passes) or None                  # None: fitted to the budget by the first run
    for size in warmup_sizes(sizes):                    # compile, untimed
        render_at(size, task.point.warmup_seed)
    result = PointResult(task, 0)
    sizes = progressive_runs(task, render_at, result, sizes, task.seeds)
    if task.point.budget_s is not None:
        keep_passes_to_budget(task, render_at, result, sizes)
    return result


def progressive_runs(task: PointTask, render_at, result: PointResult, sizes, seeds) -> tuple[int, ...]:
    """Render a progressive run of each seed into ``result.runs`` (replacing what it held), with
    passes of ``sizes`` (None: the first run fits them to the budget and records the calibration);
    returns the pass sizes rendered."""
    result.runs = []
    for seed in seeds:
        checkpoints = warm_run(task, render_at, seed, sizes)
        done = pass_sizes(checkpoints)
        if sizes is None:                               # the first run fits the budget: its passes are the point's
            fewer = fewer_passes(task, done, checkpoints)
            if fewer:                                   # its passes' fixed cost took too much of it: again, fewer
                checkpoints = warm_run(task, render_at, seed, fewer)
                done = pass_sizes(checkpoints)
            sizes = done
            result.calibration = {"kind": "calibration", "point": task.point.id, "spp": checkpoints[-1].spp,
                                  "passes": list(sizes), "budget_s": task.point.budget_s, "fitted_on_seed": seed,
                                  "identity_hash": task.identity_hash}
        result.spp = checkpoints[-1].spp
        result.runs.append(progressive_row(task, seed, done, checkpoints))
    return sizes


def warm_run(task: PointTask, render_at, seed: int, sizes) -> list[Checkpoint]:
    """One progressive run of ``seed`` (``progressive.run_passes``), rendered again while it still
    compiled a kernel (then it was a warm-up)."""
    for _ in range(1 + RECOMPILE_RETRIES):
        checkpoints = run_passes(render_at, seed, sizes, task.point.budget_s, continues_passes(task.strategy))
        if checkpoints[-1].cache_misses == 0:
            break
    return checkpoints


def pass_sizes(checkpoints: list[Checkpoint]) -> tuple[int, ...]:
    """The spp of each pass of a run, from its checkpoints' accumulated counts."""
    totals = [0] + [cp.spp for cp in checkpoints]
    return tuple(b - a for a, b in zip(totals, totals[1:]))


def fewer_passes(task: PointTask, sizes, checkpoints: list[Checkpoint]) -> tuple[int, ...] | None:
    """A budget run's passes refitted (``budget.rescaled_passes``) where their fixed cost took more
    than ``budget.FIXED_SHARE`` of the budget (``budget.too_many_passes``); None where it did not.
    The budget's doubling passes start at 1 spp, so an integrator whose render costs a large
    fixed part (tracing a long kernel) would spend its budget on passes, not samples."""
    row = {"checkpoints": [{"spp": cp.spp, "wall_s": cp.wall_s} for cp in checkpoints]}
    continues = continues_passes(task.strategy)
    times = pass_times([row], first=not continues)
    if not too_many_passes(times, len(sizes) - continues, task.point.budget_s):
        return None
    once = once_cost([row], times) if continues else 0.0
    return rescaled_passes(sizes, checkpoints[-1].wall_s, task.point.budget_s, times, once)


def continues_passes(strategy: PluginSpec) -> bool:
    """Whether the strategy's later passes continue its first pass's Markov chains
    (``Estimator.CONTINUES_PASSES``: lab_pssmlt) rather than render independently."""
    from ...plugins.integrators.estimator import lookup

    estimator = lookup(strategy.type)
    return bool(getattr(estimator, "CONTINUES_PASSES", False))


def rescaled_single_pass(sizes, tries: list[dict], budget_s: float) -> tuple[int, ...]:
    """A continued run of one pass (its second overran: a noisy clock) keeps no time of the chains
    apart from the bootstrap's, so the tries' (spp, measured) are fitted instead: seconds = once +
    per spp x spp, the bootstrap the intercept, once two tries differ in spp (as
    ``calibrate``); before that all the time counts as per spp (``rescaled_passes``: short, and
    tried again)."""
    points = {t["spp"]: t["measured_s"] for t in tries}
    if len(points) >= 2:
        per, once = np.polyfit(list(points), list(points.values()), 1)
        if per > 0:
            return (max(1, int(round((budget_s - max(once, 0.0)) / per))),)
    return rescaled_passes(sizes, tries[-1]["measured_s"], budget_s)


def keep_passes_to_budget(task: PointTask, render_at, result: PointResult, sizes) -> None:
    """``keep_to_budget`` for a progressive budget point: while the median of its runs' elapsed
    times is off the budget, the passes are refitted to it from their measured times (fixed cost
    per pass + cost per spp, ``budget.rescaled_passes``: fewer passes where their fixed cost
    alone would fill the budget) and every seed of the point rendered again."""
    point = task.point
    base = result.calibration or dict(task.calibration or {})
    stored = list(task.stored_times)
    tries = []
    for retry in range(BUDGET_RETRIES + 1):
        times = stored + [row["wall_s"] for row, _ in result.runs]
        tries.append({"spp": result.spp, "passes": list(sizes), "measured_s": measured_time(times), "times": times})
        if within_budget(tries[-1]["measured_s"], point.budget_s) or retry == BUDGET_RETRIES:
            break
        rows = [row for row, _ in result.runs]
        if continues_passes(task.strategy):          # the first pass's bootstrap: a cost once per run
            times = pass_times(rows, first=False)
            if times:
                sizes = rescaled_passes(sizes, tries[-1]["measured_s"], point.budget_s, times, once_cost(rows, times))
            else:
                sizes = rescaled_single_pass(sizes, tries, point.budget_s)
        else:
            sizes = rescaled_passes(sizes, tries[-1]["measured_s"], point.budget_s, pass_times(rows))
        for size in warmup_sizes(sizes):                                    # compile, untimed
            render_at(size, point.warmup_seed)
        progressive_runs(task, render_at, result, sizes, point.seeds if stored else task.seeds)
        stored = []
    if result.calibration is None and len(tries) == 1:
        return                               # a resumed point at its budget: its calibration stands
    result.calibration = {**base, "kind": "calibration", "point": point.id, "budget_s": point.budget_s,
                          "identity_hash": task.identity_hash, "spp": result.spp, "passes": list(sizes),
                          "budget_tries": tries,
                          "within_budget": within_budget(tries[-1]["measured_s"], point.budget_s)}


def progressive_row(task: PointTask, seed: int, sizes, checkpoints: list[Checkpoint]) -> tuple[dict, list]:
    """(row, checkpoint images): the run's row with its checkpoints (the last one's values also
    at the top, as a one-render row has them). Over a ladder every checkpoint is the point of its
    spp, and those at a ladder value and the last get the optional metrics (FLIP, CIEDE2000: the
    slow ones); a budget run's last checkpoint is the budget point."""
    point = task.point
    rows = []
    for cp in checkpoints:
        is_last = cp is checkpoints[-1]
        if point.budget_s is None:
            name = point_id(point.scene, point.strategy, point.sampler, cp.spp)
            budget, optional = None, task.metrics if (cp.spp in point.ladder or is_last) else ()
        else:
            name, budget, optional = (point.id, point.budget_s, task.metrics) if is_last else (None, None, ())
        rows.append({"point": name, "budget_s": budget, "spp": cp.spp, "passes": cp.passes, "wall_s": cp.wall_s,
                     "kernel_s": cp.kernel_s, "compile_s": cp.compile_s, "cache_misses": cp.cache_misses,
                     "rays": cp.rays, **measure(cp.image, task.reference_image, task.regions, optional)})
    final = {k: v for k, v in rows[-1].items() if k not in ("point", "budget_s")}
    # (a chain estimator's last pass reports its chains since the first: b, acceptance, mutations)
    row = {**run_row(task, seed, checkpoints[-1].spp), **final, "progressive": True, "pass_spp": list(sizes),
           "integrator_stats": checkpoints[-1].integrator, "checkpoints": rows}
    return row, [cp.image for cp in checkpoints]


def settle(point: Point, render_at, spp: int, stats, calibration: dict) -> int:
    """The calibrated ``spp`` checked against the budget by the compile render at it (``stats``)
    and rescaled while its time less compilation is off by more than budget.BUDGET_TOLERANCE (SETTLE_TRIES
    at most); ``calibration`` records the count kept and the rescalings."""
    for _ in range(SETTLE_TRIES):
        seconds = max(stats.wall_s - stats.compile_s, 1e-6)
        if within_budget(seconds, point.budget_s):
            break
        spp = rescaled_count(spp, seconds, point.budget_s, calibration["fixed_s"])
        calibration.setdefault("rescaled", []).append({"seconds": seconds, "spp": spp})
        _, stats = render_at(spp, point.warmup_seed)
    calibration["spp"] = spp
    return spp


def calibrate(point: Point, render_at) -> tuple[int, dict]:
    """Sample count (spp, or passes for a pass-scaled integrator) that fills the point's time
    budget, from pilot renders (after a warm-up each, for compilation) that grow until the
    sample-dependent part of their time is a measurable part of the budget (PILOT_*)."""
    def timed(count):
        render_at(count, point.warmup_seed)                                 # compile
        return render_at(count, point.warmup_seed)[1].wall_s

    counts = list(PILOT_SPP)
    times = [timed(c) for c in counts]
    for _ in range(PILOT_MAX_GROWTH):
        if times[1] - times[0] >= PILOT_BUDGET_FRACTION * point.budget_s:
            break
        counts = [counts[1], counts[1] * PILOT_GROWTH]
        times = [times[1], timed(counts[1])]
    # Where the two times are not in order (noise), all of the larger one's time is taken as
    # per-sample cost: an upper bound, so the render stays within its budget.
    per_spp = (times[1] - times[0]) / (counts[1] - counts[0])
    if per_spp <= 0:
        per_spp = times[1] / counts[1]
    fixed = max(times[1] - per_spp * counts[1], 0.0)
    spp = max(1, int(round((point.budget_s - fixed) / per_spp)))
    return spp, {"kind": "calibration", "point": point.id, "spp": spp, "fixed_s": fixed,
                 "per_spp_s": per_spp, "budget_s": point.budget_s, "pilots": counts}
