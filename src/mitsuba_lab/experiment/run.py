"""Run a sweep: references first, then every point's renders, one stored row per render.

Each point gets one untimed warm-up render (Dr.Jit compiles on first use; the
sample count is part of the compiled kernel), then R timed renders with
distinct seeds, each synchronised before the clock stops (``render.render``).
Rows already in the store are skipped, so a killed sweep resumes where it was.
"""
from __future__ import annotations

import os
import platform
import resource
import socket
import time

import numpy as np

from .. import images, metrics
from ..render import render
from ..runtime import versions
from ..scene import make_integrator
from ..scene_xml import load_scene_variant
from .config import Config, SceneSpec, with_depth
from .plan import Plan, Point
from .reference import Reference, get_reference
from .store import ResultStore

#: Pilot sample counts for time budgets: two timed renders fit time = c0 + c1 * spp.
PILOT_SPP = (2, 8)


def pixel_regions(scene: SceneSpec, width: int, height: int) -> dict[str, tuple[int, int, int, int]]:
    """Regions in pixels: float rectangles are fractions of the image, int ones pixels."""
    out = {}
    for name, rect in scene.regions.items():
        if any(isinstance(v, float) for v in rect):
            out[name] = metrics.fraction_rect_to_pixels(rect, width, height)
        else:
            out[name] = tuple(int(v) for v in rect)
        metrics.region(np.zeros((height, width)), out[name])      # raises if outside the image
    return out


def measure(image: np.ndarray, ref: Reference, regions: dict, optional: tuple[str, ...]) -> dict:
    """Error metrics of one render against the reference (raw: the floor is not subtracted)."""
    row = {"mse": metrics.mse(image, ref.image), "rel_mse": metrics.rel_mse(image, ref.image),
           "finite": bool(np.isfinite(image).all()), "negative": int((image < 0).sum())}
    if "flip" in optional:
        row["flip"] = metrics.flip_hdr(image, ref.image)
    if "ciede2000" in optional:
        row["ciede2000"] = metrics.ciede2000_mean(image, ref.image)
    row["regions"] = {name: {"mse": metrics.mse(metrics.region(image, rect), metrics.region(ref.image, rect)),
                             "rel_mse": metrics.rel_mse(metrics.region(image, rect),
                                                        metrics.region(ref.image, rect))}
                      for name, rect in regions.items()}
    return row


def machine_info() -> dict:
    return {"host": socket.gethostname(), "cpus": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), **versions()}


class SweepRunner:
    """Executes a plan into a store. ``progress(event: str, **info)`` reports to the CLI."""

    def __init__(self, config: Config, plan: Plan, store: ResultStore, progress=None):
        self.config, self.plan, self.store = config, plan, store
        self.progress = progress or (lambda event, **info: None)
        self.references: dict[str, Reference] = {}

    def run(self) -> None:
        self.store.append({"kind": "meta", "config": self.config.source, "name": self.config.name,
                           "started": time.time(), "machine": machine_info(),
                           "left_out": self.plan.left_out, "aliases": self.plan.aliases})
        for scene in self.config.scenes:
            self.references[scene.name] = self.reference(scene)
        done = self.store.done_runs()
        todo = [p for p in self.plan.points if any((p.id, s) not in done for s in p.seeds)]
        self.progress("start", total=len(todo), skipped=len(self.plan.points) - len(todo))
        for scene in self.config.scenes:
            for sampler in self.config.samplers:
                points = [p for p in todo if p.scene == scene.name and p.sampler == sampler.name]
                if points:
                    self._run_group(scene, sampler, points, done)

    def reference(self, scene: SceneSpec) -> Reference:
        spec = self.config.reference
        integrator = with_depth(spec.integrator, self.config.max_depth)
        self.progress("reference", scene=scene.name)
        ref, cached = get_reference(scene.path, scene.resolution, scene.defaults, integrator, spec.spp,
                                    spec.chunks, spec.cache,
                                    progress=lambda k, n: self.progress("reference_chunk", scene=scene.name,
                                                                        done=k, total=n))
        self.keep_copy(ref)
        if not any(r.get("kind") == "reference" and r["key"] == ref.key and r["scene"] == scene.name
                   for r in self.store.rows):
            height, width = ref.image.shape[:2]
            self.store.append({"kind": "reference", "scene": scene.name, "key": ref.key, "cached": cached,
                               "regions": pixel_regions(scene, width, height),
                               "path": os.path.join(spec.cache, ref.key + ".exr"),
                               "mse_floor": ref.mse_floor, "rel_mse_floor": ref.rel_mse_floor(),
                               "spp": spec.spp, "chunks": spec.chunks, "integrator": integrator.type,
                               "params": integrator.params, "seconds": ref.meta.get("seconds")})
        self.progress("reference_done", scene=scene.name, cached=cached, floor=ref.mse_floor)
        return ref

    def keep_copy(self, ref: Reference) -> None:
        """The sweep folder keeps its own copy of each reference: reports read only that folder."""
        folder = os.path.join(self.store.folder, "references")
        os.makedirs(folder, exist_ok=True)
        for suffix, image in ((".exr", ref.image), (".var.exr", ref.variance)):
            target = os.path.join(folder, ref.key + suffix)
            if not os.path.exists(target):
                images.write_exr(target, image, {"mitsuba_lab.reference": ref.key})

    def _run_group(self, scene: SceneSpec, sampler, points: list[Point], done: set) -> None:
        scene_obj = load_scene_variant(scene.path, scene.resolution, sampler.as_dict(), scene.defaults)
        ref = self.references[scene.name]
        height, width = ref.image.shape[:2]
        regions = pixel_regions(scene, width, height)
        strategies = {s.name: s for s in self.config.strategies}
        for strategy_name in dict.fromkeys(p.strategy for p in points):
            spec = with_depth(strategies[strategy_name], self.config.max_depth)
            integrator = make_integrator(spec.type, spec.params)
            for point in (p for p in points if p.strategy == strategy_name):
                spp = point.spp or self.calibrated_spp(point, scene_obj, integrator)
                render(scene_obj, integrator, spp=spp, seed=point.warmup_seed)      # compile, untimed
                for seed in point.seeds:
                    if (point.id, seed) in done:
                        continue
                    image, stats = render(scene_obj, integrator, spp=spp, seed=seed)
                    image_path = self.store.image_path(point.id, seed)
                    os.makedirs(os.path.dirname(image_path), exist_ok=True)
                    images.write_exr(image_path, image, {"mitsuba_lab.point": point.id,
                                                         "mitsuba_lab.seed": str(seed)})
                    self.store.append({
                        "kind": "run", "point": point.id, "scene": point.scene, "strategy": point.strategy,
                        "sampler": point.sampler, "spp": spp, "budget_s": point.budget_s, "seed": seed,
                        "wall_s": stats.wall_s, "kernel_s": stats.kernel_s, "compile_s": stats.compile_s,
                        "rays": stats.rays, "image": os.path.relpath(image_path, self.store.folder),
                        "integrator": spec.type, "params": spec.params, "host": socket.gethostname(),
                        # process-wide high-water mark so far (Linux reports KiB): cheap, not per render
                        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                        "finished": time.time(), **measure(image, ref, regions, self.config.metrics)})
                self.progress("point_done", point=point.id)

    def calibrated_spp(self, point: Point, scene_obj, integrator) -> int:
        """Sample count that fills the point's time budget, fitted once and stored."""
        for row in self.store.of_kind("calibration"):
            if row["point"] == point.id:
                return row["spp"]
        times = []
        for spp in PILOT_SPP:
            render(scene_obj, integrator, spp=spp, seed=point.warmup_seed)             # compile
            times.append(render(scene_obj, integrator, spp=spp, seed=point.warmup_seed)[1].wall_s)
        per_spp = max((times[1] - times[0]) / (PILOT_SPP[1] - PILOT_SPP[0]), 1e-9)
        fixed = max(times[0] - per_spp * PILOT_SPP[0], 0.0)
        spp = max(1, int(round((point.budget_s - fixed) / per_spp)))
        self.store.append({"kind": "calibration", "point": point.id, "spp": spp, "fixed_s": fixed,
                           "per_spp_s": per_spp, "budget_s": point.budget_s})
        return spp
