"""One point of a sweep, as a self-contained task: runs in this process or on a Dask worker.

A task carries everything its renders need (scene and plugin specs, the seeds
still missing, the reference image, the regions, the variant), and returns rows
and images instead of writing them: only the sweep's own process writes the
store, so a task retried after a worker died can never duplicate a row.
"""
from __future__ import annotations

import json
import os
import resource
import socket
import time
from dataclasses import dataclass, field

import numpy as np

from .. import metrics
from .config import PluginSpec, SceneSpec, sample_count_plugin
from .plan import Point

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


@dataclass
class PointResult:
    task: PointTask
    spp: int
    calibration: dict | None = None
    runs: list = field(default_factory=list)     # (row without the image path, image)


def measure(image: np.ndarray, ref_image: np.ndarray, regions: dict, optional: tuple[str, ...]) -> dict:
    """Error metrics of one render against the reference (raw: the floor is not subtracted)."""
    row = {"mse": metrics.mse(image, ref_image), "rel_mse": metrics.rel_mse(image, ref_image),
           "finite": bool(np.isfinite(image).all()), "negative": int((image < 0).sum())}
    if "flip" in optional:
        row["flip"] = metrics.flip_hdr(image, ref_image)
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


def execute(task: PointTask) -> PointResult:
    from .. import activate
    from ..render import render
    from ..scene import make_integrator
    from ..scene_xml import load_scene_variant

    activate(task.variant)                   # a fresh worker process selects the sweep's variant
    scene_key = json.dumps([task.variant, task.scene.path, task.scene.resolution, task.scene.defaults,
                            task.sampler.as_dict()], sort_keys=True, default=str)
    scene = _cached("scene", scene_key, lambda: load_scene_variant(
        task.scene.path, task.scene.resolution, task.sampler.as_dict(), task.scene.defaults))

    def render_at(count: int, seed: int):
        """Render with ``count`` camera samples per pixel (spp, or passes: sample_count_plugin)."""
        spec, spp = sample_count_plugin(task.strategy, count)
        integrator = _cached("integrator", scene_key + json.dumps(spec.as_dict(), sort_keys=True),
                             lambda: make_integrator(spec.type, spec.params))
        return render(scene, integrator, spp=spp, seed=seed)

    result = PointResult(task, task.spp or 0)
    if not task.spp:
        result.spp, result.calibration = calibrate(task.point, render_at)
        result.calibration["identity_hash"] = task.identity_hash
    params = sample_count_plugin(task.strategy, result.spp)[0].params
    render_at(result.spp, task.point.warmup_seed)                            # compile, untimed
    for seed in task.seeds:
        image, stats = render_at(result.spp, seed)
        row = {"kind": "run", "point": task.point.id, "scene": task.point.scene,
               "strategy": task.point.strategy, "sampler": task.point.sampler, "spp": result.spp,
               "budget_s": task.point.budget_s, "seed": seed, "wall_s": stats.wall_s,
               "kernel_s": stats.kernel_s, "compile_s": stats.compile_s, "rays": stats.rays,
               "integrator": task.strategy.type, "params": params,
               "identity": task.identity, "identity_hash": task.identity_hash,
               "host": socket.gethostname(), "pid": os.getpid(),
               # process-wide high-water mark so far (Linux reports KiB): cheap, not per render
               "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
               "finished": time.time(), **measure(image, task.reference_image, task.regions, task.metrics)}
        result.runs.append((row, image))
    return result


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
