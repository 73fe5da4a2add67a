"""Run a sweep: references first, then every point's renders, one stored row per render.

Each point gets one untimed warm-up render (Dr.Jit compiles on first use; the
sample count is part of the compiled kernel), then R timed renders with
distinct seeds, each synchronised before the clock stops (``worker.execute``).
Points run in this process, in a render process of the sweep's own or on a Dask
cluster (``executors``); either way only this process writes the store. Rows already in the store are skipped, so
a killed sweep resumes where it was. A progressive point (``experiment.progressive``)
renders one accumulating run per seed instead (``progressive``), stored as one row
with its checkpoints.
"""
from __future__ import annotations

import os
import platform
import socket
import time
from collections import Counter

import numpy as np

from ... import images, interrupts, metrics
from ...errors import LabError
from ...runtime import versions
from ...scene_xml import scene_digest
from .config import Config, SceneSpec, with_depth
from ..execution.executors import LocalExecutor
from .plan import Plan, Point
from .reference import Reference, get_reference
from .identity import describe_changes, identity_hash, point_identity
from .store import ResultStore
from .budget import BUDGET_RETRIES, within_budget
from ..execution.worker import PointResult, PointTask


def pixel_regions(scene: SceneSpec, width: int, height: int) -> dict[str, tuple[int, int, int, int]]:
    """Regions in pixels: float rectangles are fractions of the image, int ones pixels."""
    out = {}
    for name, rect in scene.regions.items():
        if any(isinstance(v, float) for v in rect):
            out[name] = metrics.fraction_rect_to_pixels(rect, width, height)
        else:
            out[name] = tuple(int(v) for v in rect)
        try:
            metrics.region(np.zeros((height, width)), out[name])
        except ValueError as err:
            raise LabError(f"scene {scene.name}: region '{name}' {list(rect)} lies outside the "
                           f"{width}x{height} image") from err
    return out


def machine_info() -> dict:
    return {"host": socket.gethostname(), "cpus": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), **versions()}


class SweepRunner:
    """Executes a plan into a store. ``progress(event: str, **info)`` reports to the CLI."""

    def __init__(self, config: Config, plan: Plan, store: ResultStore, progress=None, executor=None):
        self.config, self.plan, self.store = config, plan, store
        self.executor = executor or LocalExecutor()
        self.progress = progress or (lambda event, **info: None)
        self.references: dict[str, Reference] = {}
        self.identities: dict[str, tuple[dict, str]] = {}

    def run(self) -> None:
        self.store.append({"kind": "meta", "config": self.config.source, "name": self.config.name,
                           "started": time.time(), "machine": machine_info(),
                           "left_out": self.plan.left_out, "aliases": self.plan.aliases,
                           "unsupported": self.plan.unsupported,
                           "progressive": self.config.progressive, "separate": self.plan.separate})
        for scene in self.config.scenes:
            self.references[scene.name] = self.reference(scene)
        self.identities = self.point_identities()
        for (changes, planned), count in self.retire_stale_runs().items():
            self.progress("stale", count=count, changes=changes, planned=planned)
        done = self.store.done_runs()
        todo = [p for p in self.plan.points
                if any(done.get((p.id, s), "missing") != self.identities[p.id][1] for s in p.seeds)]
        self.progress("start", total=len(todo), skipped=len(self.plan.points) - len(todo))
        for result in self.executor.map(list(self.tasks(todo, done))):
            self.record(result)

    def point_identities(self) -> dict[str, tuple[dict, str]]:
        """Point id -> (identity, its hash): what determines the point's runs (``identity``)."""
        scenes = {s.name: s for s in self.config.scenes}
        samplers = {s.name: s for s in self.config.samplers}
        strategies = {s.name: s for s in self.config.strategies}
        digests = {name: scene_digest(spec.path) for name, spec in scenes.items()}
        out = {}
        for point in self.plan.points:
            ident = point_identity(scenes[point.scene],
                                   with_depth(strategies[point.strategy], self.config.max_depth),
                                   samplers[point.sampler], point, self.references[point.scene].key,
                                   digests[point.scene])
            out[point.id] = (ident, identity_hash(ident))
        return out

    def retire_stale_runs(self) -> dict[tuple[str, bool], int]:
        """Mark every stored run that the sweep would not produce now as superseded (it stays
        in the store; resumes and reports skip it). Returns {(what changed, still planned): runs}."""
        seeds = {p.id: set(p.seeds) for p in self.plan.points}
        counts: dict[tuple[str, bool], int] = {}
        for row in self.store.stored_runs():
            planned = self.identities.get(row["point"])
            if planned is None:
                changes = "not in this sweep's plan any more"
            elif row["seed"] not in seeds[row["point"]]:
                changes = f"seed {row['seed']} not in this sweep's plan any more (experiment.seed or repetitions)"
                planned = None
            elif row.get("identity_hash") != planned[1]:
                changes = describe_changes(row.get("identity"), planned[0])
            else:
                continue
            self.store.append({"kind": "superseded", "point": row["point"], "seed": row["seed"],
                               "identity_hash": row.get("identity_hash"), "changes": changes,
                               "time": time.time()})
            key = (changes, planned is not None)
            counts[key] = counts.get(key, 0) + 1
        return counts

    def reference(self, scene: SceneSpec) -> Reference:
        spec = self.config.reference_for(scene)
        integrator = with_depth(spec.integrator, self.config.max_depth)
        self.progress("reference", scene=scene.name)
        ref, cached = get_reference(scene.path, scene.resolution, scene.defaults, integrator, spec.spp,
                                    spec.chunks, spec.cache,
                                    progress=lambda k, n: self.progress("reference_chunk", scene=scene.name,
                                                                        done=k, total=n))
        self.keep_copy(ref)
        in_force = [r for r in self.store.of_kind("reference") if r["scene"] == scene.name]
        if not in_force or in_force[-1]["key"] != ref.key:      # the report reads the last one
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

    def tasks(self, todo: list[Point], done: set):
        """One self-contained task per unfinished point, grouped by scene, sampler and strategy."""
        import mitsuba as mi

        scenes = {s.name: s for s in self.config.scenes}
        samplers = {s.name: s for s in self.config.samplers}
        strategies = {s.name: s for s in self.config.strategies}
        calibrated = {row["point"]: row for row in self.store.of_kind("calibration")
                      if row.get("identity_hash") == self.identities.get(row["point"], (None, "-"))[1]}
        in_force = self.store.stored_runs()
        for point in todo:
            identity, ident_hash = self.identities[point.id]
            ref = self.references[point.scene]
            height, width = ref.image.shape[:2]
            calibration = calibrated.get(point.id)
            # a budget point's seeds already stored at its calibrated count count in its measured time
            stored_times = tuple(r["wall_s"] for r in in_force if r["point"] == point.id and r["seed"] in point.seeds
                                 and r.get("identity_hash") == ident_hash and calibration is not None
                                 and r["spp"] == calibration.get("spp")) if point.budget_s is not None else ()
            yield PointTask(point=point, scene=scenes[point.scene], sampler=samplers[point.sampler],
                            strategy=with_depth(strategies[point.strategy], self.config.max_depth),
                            seeds=tuple(s for s in point.seeds if done.get((point.id, s)) != ident_hash),
                            spp=point.spp or calibrated.get(point.id, {}).get("spp"), reference_image=ref.image,
                            regions=pixel_regions(scenes[point.scene], width, height),
                            metrics=self.config.metrics, variant=mi.variant(),
                            identity=identity, identity_hash=ident_hash,
                            passes=point.passes or tuple(calibrated.get(point.id, {}).get("passes", ())),
                            stored_times=stored_times, calibration=calibration)

    def record(self, result: PointResult) -> None:
        """Store one finished point: calibration, then each image before the row naming it. A
        Ctrl-C meanwhile waits until the point is stored whole (``interrupts.deferred``). A run
        that replaces a stored one of the same identity (a budget point rendered again) gets an
        image of its own; the replaced image is removed once the new row is stored, so a row in
        force never names a missing or another render's image."""
        self.report_budget_tries(result)
        with interrupts.deferred():
            if result.calibration:
                self.store.append(result.calibration)
            point = result.task.point.id
            held = {r["seed"]: r for r in self.store.stored_runs() if r["point"] == point}
            earlier = Counter((r["seed"], r.get("identity_hash")) for r in self.store.of_kind("run")
                              if r["point"] == point)
            for row, image in result.runs:
                attempt = 1 + earlier[(row["seed"], row.get("identity_hash"))]
                if "checkpoints" in row:            # a progressive run: every checkpoint's image first
                    row = {**row, "checkpoints": [{**cp, "image": self.write_image(row, pass_image, cp["spp"], attempt)}
                                                  for cp, pass_image in zip(row["checkpoints"], image)]}
                    row = {**row, "image": row["checkpoints"][-1]["image"]}
                else:
                    row = {**row, "image": self.write_image(row, image, attempt=attempt)}
                self.store.append(row)
                self.remove_replaced(held.get(row["seed"]), row)
        self.progress("point_done", point=result.task.point.id)

    def report_budget_tries(self, result: PointResult) -> None:
        """One progress event per render of a budget point's seeds again (``worker.keep_to_budget``),
        and one when its last renders still missed the budget."""
        tries = (result.calibration or {}).get("budget_tries", [])
        point = result.task.point
        for number, (missed, then) in enumerate(zip(tries, tries[1:]), 1):
            self.progress("budget_retry", point=point.id, budget=point.budget_s, measured=missed["measured_s"],
                          spp=missed["spp"], new_spp=then["spp"], retry=number, retries=BUDGET_RETRIES)
        if tries and not within_budget(tries[-1]["measured_s"], point.budget_s):
            self.progress("budget_missed", point=point.id, budget=point.budget_s, measured=tries[-1]["measured_s"],
                          spp=tries[-1]["spp"], retries=len(tries) - 1)

    def remove_replaced(self, old: dict | None, new: dict) -> None:
        """Remove the images of ``old``, a run row of the same identity that ``new`` (stored) replaced."""
        if old is None or old.get("identity_hash") != new.get("identity_hash"):
            return                                  # (a superseded run's images are kept with its row)
        kept = {new.get("image")} | {cp.get("image") for cp in new.get("checkpoints", [])}
        for relative in [old.get("image")] + [cp.get("image") for cp in old.get("checkpoints", [])]:
            if relative and relative not in kept:
                path = os.path.join(self.store.folder, relative)
                if os.path.exists(path):
                    os.unlink(path)

    def write_image(self, row: dict, image, checkpoint_spp: int | None = None, attempt: int = 1) -> str:
        """Write a run's image (or a progressive run's checkpoint image); its path in the folder."""
        path = self.store.image_path(row["point"], row["seed"], row.get("identity_hash"), checkpoint_spp, attempt)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        tags = {"mitsuba_lab.point": row["point"], "mitsuba_lab.seed": str(row["seed"])}
        if checkpoint_spp is not None:
            tags["mitsuba_lab.checkpoint_spp"] = str(checkpoint_spp)
        images.write_exr(path, image, tags)
        return os.path.relpath(path, self.store.folder)
