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
from .config import PluginSpec, SceneSpec
from .plan import Point

#: Pilot sample counts for time budgets: two timed renders fit time = c0 + c1 * spp.
PILOT_SPP = (2, 8)


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
    integrator = _cached("integrator", scene_key + json.dumps(task.strategy.as_dict(), sort_keys=True),
                         lambda: make_integrator(task.strategy.type, task.strategy.params))
    result = PointResult(task, task.spp or 0)
    if not task.spp:
        result.spp, result.calibration = calibrate(task.point, scene, integrator, render)
    render(scene, integrator, spp=result.spp, seed=task.point.warmup_seed)    # compile, untimed
    for seed in task.seeds:
        image, stats = render(scene, integrator, spp=result.spp, seed=seed)
        row = {"kind": "run", "point": task.point.id, "scene": task.point.scene,
               "strategy": task.point.strategy, "sampler": task.point.sampler, "spp": result.spp,
               "budget_s": task.point.budget_s, "seed": seed, "wall_s": stats.wall_s,
               "kernel_s": stats.kernel_s, "compile_s": stats.compile_s, "rays": stats.rays,
               "integrator": task.strategy.type, "params": task.strategy.params,
               "host": socket.gethostname(), "pid": os.getpid(),
               # process-wide high-water mark so far (Linux reports KiB): cheap, not per render
               "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
               "finished": time.time(), **measure(image, task.reference_image, task.regions, task.metrics)}
        result.runs.append((row, image))
    return result


def calibrate(point: Point, scene, integrator, render) -> tuple[int, dict]:
    """Sample count that fills the point's time budget, from two pilot renders."""
    times = []
    for spp in PILOT_SPP:
        render(scene, integrator, spp=spp, seed=point.warmup_seed)              # compile
        times.append(render(scene, integrator, spp=spp, seed=point.warmup_seed)[1].wall_s)
    per_spp = max((times[1] - times[0]) / (PILOT_SPP[1] - PILOT_SPP[0]), 1e-9)
    fixed = max(times[0] - per_spp * PILOT_SPP[0], 0.0)
    spp = max(1, int(round((point.budget_s - fixed) / per_spp)))
    return spp, {"kind": "calibration", "point": point.id, "spp": spp, "fixed_s": fixed,
                 "per_spp_s": per_spp, "budget_s": point.budget_s}
