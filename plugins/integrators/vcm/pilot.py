"""lab_vcm's pilot (``pilot = true``): every technique or path tracing alone, whichever a pilot
finds more efficient, and the render of the one it chooses.

A few short renders of every technique (at each light-subpath count it may choose) and of
lab_mis (path tracing alone, mode pt's estimator), each timed after Dr.Jit has finished it and
counting its work; ``selection`` turns them into relative variances and costs per iteration and
chooses. The plugin (``integrator``) holds one ``Pilot`` and hands it its render when ``pilot``
is on.
"""
from __future__ import annotations

import math
import time
from collections import Counter

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab.plugins.integrators.bdpt.passes import pass_seed
from mitsuba_lab.plugins.integrators.common.aim import target_shapes
from mitsuba_lab.plugins.integrators.common.support import render_arguments

from .selection import (EVERY_OVER_PATH_PLAN, PATH_TRACING_SIZE, PILOT_MIN_ITERATIONS, PILOT_RENDERS, PilotCosts,
                        PilotPlan, choose, every_seconds, light_path_ratios, pilot_iterations, pilot_variances, seconds,
                        share_budget)

#: The pilot renders' seeds: the render's seed with this mixed in, then one per render; the
#: light seed of the renders that share camera seeds mixes in one more.
SALT = 0x2545F491
LIGHT_SALT = 0x68E31DA4


def timed(integrator, scene, sensor, seed: int, spp: int, develop=True, evaluate=True):
    """(image, seconds) of a render, after Dr.Jit has finished it."""
    start = time.perf_counter()
    image = integrator.render(scene, sensor, seed, spp, develop, evaluate)
    dr.eval(image)
    dr.sync_thread()
    return image, time.perf_counter() - start



def pass_times(integrator) -> tuple[float, float]:
    """(light pass + grid, camera pass) seconds of the integrator's last render."""
    stats = integrator.bdpt_stats()
    return stats["light_s"] + stats["grid_s"], stats["camera_s"]


class Pilot:
    """The pilot of one lab_vcm plugin (``plugin``: its settings, merging radius, ray counters
    and statistics). After ``run``: ``variances`` and ``costs`` (``selection``), and ``work``,
    the counted work of its renders (every technique's and path tracing's; {} with measured
    costs)."""

    def __init__(self, plugin):
        self.plugin = plugin
        self.variances = self.costs = None
        self.work = {}
        self.every_all, self.path_all = Counter(), {}
        self.counted_s, self.iterations = 0.0, 0

    def companion(self, ratio: float = 1.0):
        """lab_vcm with every technique of this one, without the pilot, at ``ratio`` x its
        light_paths."""
        # (counting rays always: the counted pilot prices its renders by them)
        values = self.plugin.values
        params = dict(values, pilot=False, light_paths_max=0.0, light_paths=values["light_paths"] * ratio,
                      count_rays=True)
        if self.plugin.merging:
            params["radius"] = self.plugin.first_radius
        return mi.load_dict({"type": "lab_vcm", **params})

    def path_tracer(self):
        """lab_mis with this one's path length, roulette, hidden emitters and heuristic: path
        tracing alone, the estimator of lab_vcm's mode pt."""
        shared = ("max_depth", "rr_depth", "hide_emitters", "heuristic", "beta")
        return mi.load_dict({"type": "lab_mis", "count_rays": True, **{k: self.plugin.values[k] for k in shared}})

    def run(self, scene, sensor, seed: int, spp: int, every, camera):
        """(the choice: a multiple of light_paths, or None for path tracing alone; path tracing's
        pilot image, the mean of its iterations; their number; each choice's relative variance x
        seconds per iteration), from pilot renders of both (``selection``): priced by the work
        they count (``pilot_costs = counted``) or by their times (``measured``). The pilot is sized
        so that its counted work is at most ``pilot_share`` of the whole render's (``size``); where
        even its fewest iterations would cost more, the choice is ``fallback``'s, with path
        tracing's image of what the pilot rendered of it (None if nothing) and no scores,
        ``iterations`` 0."""
        values = self.plugin.values
        ratios = light_path_ratios(values["light_paths"], values["light_paths_max"])
        counted = values["pilot_costs"] == "counted"
        channels = 1 if mi.is_monochromatic else 3
        base = seed ^ SALT
        film = sensor.film()
        pass_iterations = every.pass_iterations(int(film.size()[0]) * int(film.size()[1]))
        plan = PilotPlan(every=PILOT_RENDERS + (len(ratios) > 1), path=PILOT_RENDERS, extra_every=0 if counted else 2)
        self.every_all, self.path_all = Counter(), {}
        self.counted_s, self.iterations = 0.0, 0
        camera.ray_counts()                     # (path tracing's rays from here on)
        probe = None
        iterations = self.size(plan, spp, None, None, pass_iterations)
        if iterations:
            # path tracing's cost per iteration, from one iteration (its image joins path tracing's)
            probe, _ = timed(camera, scene, sensor, pass_seed(base, PILOT_RENDERS + 2), 1)
            probe = np.array(probe)[..., :channels]
            probe_counts = camera.ray_counts(reset=False)
            path_iteration = seconds(probe_counts, "path_tracing", values)
            iterations = self.size(plan, spp, path_iteration, None, pass_iterations)
            if not iterations and self.first_fits(spp, path_iteration, pass_iterations):
                iterations = PILOT_MIN_ITERATIONS      # (the plan checked after every technique's first)
        images = {"every": [], "shared": [], "camera": []}
        large, camera_times = [], []
        every_work = Counter()
        first = iterations
        for r in range(PILOT_RENDERS if iterations else 0):
            for name, integrator in (("every", every), ("camera", camera)):
                image, secs = timed(integrator, scene, sensor, pass_seed(base, r + 1), iterations)
                images[name].append(np.array(image)[..., :channels])
                if name == "every":
                    large.append(pass_times(every))
                    work = every.work_counts()
                    every_work.update(work)
                    self.every_all.update(work)
                else:
                    camera_times.append(secs)
            if r == 0:
                # every technique's own cost per iteration: the plan checked against it
                every_iteration = (seconds(every_work, "light", values)
                                   + seconds(every_work, "camera", values)) / iterations
                if not self.size(plan, spp, path_iteration, every_iteration, pass_iterations) >= iterations:
                    iterations = 0
                    break
        if not iterations:
            self.path_all = camera.ray_counts(reset=False)
            self.counted_s = every_seconds(self.every_all, values) + seconds(self.path_all, "path_tracing", values)
            self.variances = self.costs = None
            self.work = {}
            choice = self.fallback(scene)
            if choice is not None or probe is None:
                return choice, None, 0, {}
            # path tracing: the probe's iteration and a first pair's render are its estimator
            done = [probe] + [image * first for image in images["camera"]]
            camera_spp = 1 + first * len(images["camera"])
            return None, np.sum(done, axis=0) / camera_spp, camera_spp, {}
        self.iterations = iterations
        if len(ratios) > 1:       # render 0's camera seed, a light seed of its own
            every.passes.light_seed = pass_seed(base ^ LIGHT_SALT, 1)
            image, _ = timed(every, scene, sensor, pass_seed(base, 1), iterations)
            self.every_all.update(every.work_counts())
            images["shared"].append(np.array(image)[..., :channels])
            every.passes.light_seed = None
        if not counted:
            # marginal costs of an iteration: every technique's from one iteration more than none,
            # path tracing's (cheaper, its times noisier) from PATH_TRACING_SIZE x the iterations;
            # the one-iteration render twice, the second timed (on a fresh clone a first one took
            # 1.1 s, not ~20 ms, and every iteration looked costless)
            for _ in range(2):
                timed(every, scene, sensor, pass_seed(base, PILOT_RENDERS + 1), 1)
                self.every_all.update(every.work_counts())
        longer = PATH_TRACING_SIZE * iterations
        image, camera_long = timed(camera, scene, sensor, pass_seed(base, PILOT_RENDERS + 1), longer)
        self.path_all = camera.ray_counts(reset=False)
        self.counted_s = every_seconds(self.every_all, values) + seconds(self.path_all, "path_tracing", values)
        if counted:
            # (the probe's iteration is left out of path tracing's cost per iteration)
            path_work = {k: v - probe_counts.get(k, 0) for k, v in self.path_all.items()}
            costs = PilotCosts.from_counts(every_work, PILOT_RENDERS * iterations, pass_iterations, path_work,
                                           PILOT_RENDERS * iterations + longer, values)
            self.work = {"every": dict(every_work), "path tracing": path_work}
        else:
            costs = PilotCosts.from_sizes(pass_times(every), tuple(np.median(np.array(large), axis=0)),
                                          iterations, pass_iterations,
                                          (float(np.median(camera_times)), camera_long), iterations, longer)
            self.work = {}
        camera_images = np.array(images["camera"])
        variances = pilot_variances(np.array(images["every"]), np.array(images["shared"]) if images["shared"] else None,
                                    camera_images, iterations, np.array(image)[..., :channels], longer)
        choice, scores = choose(variances, costs, ratios)
        # (path tracing's images, the longer one and the probe included, are this render's
        # estimator if chosen)
        camera_spp = PILOT_RENDERS * iterations + longer + 1
        pilot_image = (camera_images.sum(axis=0) * iterations + np.array(image)[..., :channels] * longer
                       + probe) / camera_spp
        self.variances, self.costs = variances, costs
        return choice, pilot_image, camera_spp, scores

    @staticmethod
    def fallback(scene) -> float | None:
        """The choice where no pilot fits (None: path tracing alone; 1.0: every technique at
        light_paths), from the scene alone: every technique where a shape has only delta lobes
        (``aim.target_shapes``' "specular": glass, mirrors), which path tracing reaches only by
        hitting an emitter through them (caustics, light behind glass); path tracing elsewhere.
        On the four scenes of issue 17's targets it is what the pilot chooses: every technique
        10-57x more efficient on the caustic and sds, path tracing 1.6-4.2x on the Cornell box and
        Veach's plates (``experiments/results/2026-11-28-vcm-defaults-2.md``). Wrong where a glossy
        shape without a delta lobe focuses a small light (scenes/glossy_small_light.xml: every
        technique 4.3x better than path tracing at 2 s, 2026-11-28-vcm-defaults-3.md)."""
        return 1.0 if target_shapes(scene, "specular", "lab_vcm") else None

    def size(self, plan: PilotPlan, spp: int, path: float | None, every: float | None, pass_iterations: float) -> int:
        """Iterations per pilot render within ``pilot_share`` of the render (0: no pilot). The
        render costs at least ``spp`` x path tracing's counted seconds per iteration (``path``;
        every technique's cost more), so the pilot may cost share / (1 - share) of that
        (``selection.share_budget``). Before anything is rendered (``path`` None) the pilot's
        iterations are priced at path tracing's, whatever they cost: no pilot where even that
        passes the share; before every technique has rendered (``every`` None), it is priced at
        ``EVERY_OVER_PATH_PLAN`` x path tracing."""
        share = self.plugin.values["pilot_share"]
        if share >= 1.0:
            return pilot_iterations(spp)
        per_pass = 1e-9 * self.plugin.values["cost_pass"]
        if path is None:        # (unit costs: the pilot's iterations against the render's)
            return plan.iterations(spp, share_budget(share, spp), 1.0, 1.0, 0.0, pass_iterations)
        budget = share_budget(share, spp * path) - path            # (less the probe's iteration)
        return plan.iterations(spp, budget, EVERY_OVER_PATH_PLAN * path if every is None else every, path,
                               per_pass, pass_iterations)

    def first_fits(self, spp: int, path: float, pass_iterations: float) -> bool:
        """Whether the pilot's first renders of ``PILOT_MIN_ITERATIONS`` (every technique's,
        priced at ``EVERY_OVER_PATH_PLAN`` x path tracing's ``path``, and path tracing's with its
        seed) fit within the share: where the whole pilot only fits at every technique's own cost
        per iteration, they count it, and the pilot stops after them if the rest would not fit."""
        k = PILOT_MIN_ITERATIONS
        first = (1e-9 * self.plugin.values["cost_pass"] * math.ceil(k / max(pass_iterations, 1.0))
                 + k * (EVERY_OVER_PATH_PLAN + 1.0) * path)
        return first <= share_budget(self.plugin.values["pilot_share"], spp * path) - path

    def render(self, scene, sensor, seed, spp, develop, evaluate):
        sensor, seed, spp = render_arguments(scene, sensor, seed, spp)
        start = time.perf_counter()
        camera, every = self.path_tracer(), self.companion()
        choice, pilot_image, pilot_spp, scores = self.run(scene, sensor, seed, spp, every, camera)
        pilot_s = time.perf_counter() - start
        chosen, values = None, self.plugin.values
        if choice is None:
            before = camera.ray_counts(reset=False)
            image, secs = timed(camera, scene, sensor, seed, spp, develop, evaluate)
            self.plugin.stats = self.plugin.passes.stats_class(passes=1, camera_s=secs)
            render_counts = {k: v - before.get(k, 0) for k, v in camera.ray_counts(reset=False).items()}
            render_s = seconds(render_counts, "path_tracing", values)
            if pilot_spp:       # the pilot's path tracing is this render's estimator: its iterations count too
                out = np.array(image)
                channels = pilot_image.shape[-1]
                out[..., :channels] = (spp * out[..., :channels] + pilot_spp * pilot_image) / (spp + pilot_spp)
                image = mi.TensorXf(out)
        elif choice == 1.0:
            image = self.plugin.render_every(scene, sensor, seed, spp, develop, evaluate)
            work = self.plugin.work_counts()
            render_s = every_seconds(work, values) if work else None
        else:
            chosen = self.companion(choice)
            image = chosen.render(scene, sensor, seed, spp, develop, evaluate)
            self.plugin.stats = chosen.stats
            render_s = every_seconds(chosen.work_counts(), values)
        for integrator in (camera, every, chosen):    # (the pilot's rays are this render's cost too)
            if integrator is not None and values["count_rays"]:
                self.plugin.counters.add_counts(integrator.ray_counts())
        stats = self.plugin.stats
        stats.pilot_s = pilot_s
        stats.chose_path_tracing = choice is None
        stats.pilot_costs = values["pilot_costs"]
        stats.light_paths_chosen = 0.0 if choice is None else values["light_paths"] * choice
        stats.pilot_scores = {("path tracing" if r is None else values["light_paths"] * r): float(v)
                              for r, v in scores.items()}
        stats.pilot_iterations = self.iterations
        stats.pilot_counted_s = self.counted_s
        stats.render_counted_s = render_s
        stats.pilot_share = None if render_s is None else self.counted_s / (self.counted_s + render_s)
        return image
