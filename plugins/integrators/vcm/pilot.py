"""lab_vcm's pilot (``pilot = true``): every technique or path tracing alone, whichever a pilot
finds more efficient, and the render of the one it chooses.

A few short renders of every technique (at each light-subpath count it may choose) and of
lab_mis (path tracing alone, mode pt's estimator), each timed after Dr.Jit has finished it and
counting its work; ``selection`` turns them into relative variances and costs per iteration and
chooses. The plugin (``integrator``) holds one ``Pilot`` and hands it its render when ``pilot``
is on.
"""
from __future__ import annotations

import time
from collections import Counter

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab.plugins.integrators.bdpt.passes import pass_seed
from mitsuba_lab.plugins.integrators.common.support import render_arguments

from .selection import PATH_TRACING_SIZE, PILOT_RENDERS, PilotCosts, choose, light_path_ratios, pilot_iterations, pilot_variances

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
        they count (``pilot_costs = counted``) or by their times (``measured``)."""
        iterations = pilot_iterations(spp)
        ratios = light_path_ratios(self.plugin.values["light_paths"], self.plugin.values["light_paths_max"])
        counted = self.plugin.values["pilot_costs"] == "counted"
        channels = 1 if mi.is_monochromatic else 3
        base = seed ^ SALT
        images = {"every": [], "shared": [], "camera": []}
        large, camera_times = [], []
        every_work = Counter()
        camera.ray_counts()                     # (path tracing's rays from here on)
        for r in range(PILOT_RENDERS):
            for name, integrator in (("every", every), ("camera", camera)):
                image, seconds = timed(integrator, scene, sensor, pass_seed(base, r + 1), iterations)
                images[name].append(np.array(image)[..., :channels])
                if name == "every":
                    large.append(pass_times(every))
                    every_work.update(every.work_counts())
                else:
                    camera_times.append(seconds)
        if len(ratios) > 1:       # render 0's camera seed, a light seed of its own
            every.passes.light_seed = pass_seed(base ^ LIGHT_SALT, 1)
            image, _ = timed(every, scene, sensor, pass_seed(base, 1), iterations)
            images["shared"].append(np.array(image)[..., :channels])
            every.passes.light_seed = None
        if not counted:
            # marginal costs of an iteration: every technique's from one iteration more than none,
            # path tracing's (cheaper, its times noisier) from PATH_TRACING_SIZE x the iterations;
            # the one-iteration render twice, the second timed (on a fresh clone a first one took
            # 1.1 s, not ~20 ms, and every iteration looked costless)
            for _ in range(2):
                timed(every, scene, sensor, pass_seed(base, PILOT_RENDERS + 1), 1)
        longer = PATH_TRACING_SIZE * iterations
        image, camera_long = timed(camera, scene, sensor, pass_seed(base, PILOT_RENDERS + 1), longer)
        film = sensor.film()
        pass_iterations = every.pass_iterations(int(film.size()[0]) * int(film.size()[1]))
        if counted:
            path_work = camera.ray_counts(reset=False)
            costs = PilotCosts.from_counts(every_work, PILOT_RENDERS * iterations, pass_iterations, path_work,
                                           PILOT_RENDERS * iterations + longer, self.plugin.values)
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
        # (path tracing's images, the longer one included, are this render's estimator if chosen)
        camera_spp = PILOT_RENDERS * iterations + longer
        pilot_image = (camera_images.sum(axis=0) * iterations + np.array(image)[..., :channels] * longer) / camera_spp
        self.variances, self.costs = variances, costs
        return choice, pilot_image, camera_spp, scores

    def render(self, scene, sensor, seed, spp, develop, evaluate):
        sensor, seed, spp = render_arguments(scene, sensor, seed, spp)
        start = time.perf_counter()
        camera, every = self.path_tracer(), self.companion()
        choice, pilot_image, pilot_spp, scores = self.run(scene, sensor, seed, spp, every, camera)
        pilot_s = time.perf_counter() - start
        chosen = None
        if choice is None:
            image, seconds = timed(camera, scene, sensor, seed, spp, develop, evaluate)
            self.plugin.stats = self.plugin.passes.stats_class(passes=1, camera_s=seconds)
            # the pilot's path tracing is this render's estimator: its iterations count too
            out = np.array(image)
            channels = pilot_image.shape[-1]
            out[..., :channels] = (spp * out[..., :channels] + pilot_spp * pilot_image) / (spp + pilot_spp)
            image = mi.TensorXf(out)
        elif choice == 1.0:
            image = self.plugin.render_every(scene, sensor, seed, spp, develop, evaluate)
        else:
            chosen = self.companion(choice)
            image = chosen.render(scene, sensor, seed, spp, develop, evaluate)
            self.plugin.stats = chosen.stats
        for integrator in (camera, every, chosen):    # (the pilot's rays are this render's cost too)
            if integrator is not None and self.plugin.values["count_rays"]:
                self.plugin.counters.add_counts(integrator.ray_counts())
        self.plugin.stats.pilot_s, self.plugin.stats.chose_path_tracing = pilot_s, choice is None
        self.plugin.stats.pilot_costs = self.plugin.values["pilot_costs"]
        self.plugin.stats.light_paths_chosen = 0.0 if choice is None else self.plugin.values["light_paths"] * choice
        self.plugin.stats.pilot_scores = {("path tracing" if r is None else self.plugin.values["light_paths"] * r): float(v)
                                   for r, v in scores.items()}
        return image
