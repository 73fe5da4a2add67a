"""``lab_bdpt``: the driver (passes, the light-vertex buffer, the two images) and the plugin."""
from __future__ import annotations

import math
import time

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins import interrupts
from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.integrators.common import majorants, spawn, spectral
from mitsuba_lab.plugins.integrators.common.aim import AimedEmission
from mitsuba_lab.plugins.integrators.common.counters import RayCounters
from mitsuba_lab.plugins.integrators.common.support import base_render, render_arguments, warn_if_unsupported
from mitsuba_lab.plugins.params import UNBOUNDED
from mitsuba_lab.plugins.samplers.layout import bind_film_layout
from mitsuba_lab.plugins.variant import plugin_settings
from mitsuba_lab.plugins.scene_traits import SceneTraits

from . import splats
from .camera_subpath import CameraPass, sensor_constants, trace_camera_subpaths
from .endpoints import direction_is_delta
from .estimator import Bidirectional
from .light_subpath import LightTracer, check_variant
from .camera_flight import EquiangularMixture
from .media_paths import trace_camera, trace_light
from mitsuba_lab.plugins.integrators.common.subpath_media import Tracking, emitter_media
from .passes import PassPlan, Passes, pass_seed
from .techniques import Strategy, Technique
from .vertices import NONE, LightVertices, vertex_bytes
from .weights import BdptWeights

#: max_depth = -1 (unbounded) as the loops hold it.
DEPTH_UNBOUNDED = 0xFFFFFFFF
#: First guess of stored light vertices per light subpath, at the start of every render (then
#: learnt from each of its passes: what one render learns never sizes the next one's passes).
FIRST_GUESS_VERTICES = 3.0


@documented("lab_bdpt")
class LabBDPTIntegrator(mi.SamplingIntegrator):
    r"""Bidirectional path tracing (:monosp:`lab_bdpt`)

    Per pass, every pixel sample traces one camera subpath and one light subpath, each with
    BSDF sampling and Russian roulette (Veach & Guibas 1994; Lafortune & Willems 1993), and
    every way of building a path from them is a strategy (s light vertices, t camera vertices):
    s = 0 (the camera subpath hits an emitter), s = 1 (next-event estimation), s >= 2 and t >= 2
    (a connection between a light and a camera vertex, with a shadow ray), and t = 1 (light
    tracing: a light vertex joined to the sensor and splatted into the film, as Mitsuba's
    ``ptracer`` does). Each contribution is weighted by the balance or power heuristic over all
    strategies of its path (Veach 1997, ch. 10), computed in O(1) per connection from running
    quantities carried along both subpaths (Georgiev 2012, "Implementing vertex connection and
    merging"; ``weights.py``), with delta lobes and delta lights handled exactly. Unbiased.

    ``strategies`` subsets renormalise the weights over the enabled strategies, so a subset is
    unbiased for the light it can reach; ``only_strategy`` renders one strategy's weighted
    image (Veach's per-strategy images: over all (s, t) they sum to the full one).
    ``light_paths`` above 1 lets camera sample i connect to light subpath i while the others
    add t = 1 splats only (and store no vertices); below 1 camera samples share light
    subpaths (sample i uses subpath i mod N). The weights count each strategy's samples, so
    any value is unbiased; raise it where light tracing carries the image (light seen through
    glass). ``max_vertices`` bounds the light-subpath vertices held at once (bytes per vertex:
    ``vertices.vertex_bytes``, more where a BSDF is anisotropic or has a normal or bump map):
    a render whose light subpaths need more is split into passes of fewer samples per pixel,
    and when even one sample per pixel does not fit a pass traces fewer light subpaths than
    camera subpaths, sample i using subpath i mod N (still unbiased; passes share nothing).
    ``aim`` draws a share of an area light's directions towards the bounding spheres of the
    ``aim_at`` shapes (``aim.py``), with emission weights and MIS using the mixture's
    density; in a scene without such shapes the light emits as Mitsuba's does, with the same
    random numbers. With ``hide_emitters`` light tracing's rays to the sensor pass through
    area emitters too.

    Handles: area lights (any shape, textured or not), point, spot and directional lights,
    ``projector`` (constant or textured ``irradiance``: emitted by its texture through its
    frustum, with the direction density its ``sample_ray`` uses), ``constant`` and ``envmap``;
    smooth, delta and mixed BSDFs (``plastic``: connections use the smooth lobes, the delta
    lobes are followed); shading normals (the adjoint correction on the light side); the
    ``perspective`` (pinhole), ``thinlens`` and ``orthographic`` sensors with any film size
    and crop window. An orthographic sensor's direction is a delta, so no light vertex can be
    joined to it: there light tracing (t = 1, ``strategies = "light"``) splats nothing and
    the MIS weights count it as impossible, and every other strategy renders the image;
    RGB, mono and spectral variants (spectral: one set of wavelengths per pass, drawn from the
    sensor, so a pass is one sample per pixel; ``spectral.py``). Refused in one line:
    polarized variants, other sensors, ``render(develop=False)``, ``samples_per_pass`` (``params.REFUSED_BASE_PARAMETERS``).
    Homogeneous participating media: both subpaths scatter in them (free flights in one colour
    channel per sample, the phase function at medium vertices, null boundaries passed without a
    vertex), every strategy's connecting segment carries its transmittance, and the MIS weights
    use the distance-sampling densities (``media_paths``); each camera segment's first flight in a
    homogeneous medium adds an equi-angular NEE sample towards the lights (``equiangular_nee``,
    lab_mis's technique, a second s = 1 strategy in the weights; not with merging), and may mix
    equi-angular distances into the flight itself (``equiangular``; ``camera_flight``). Heterogeneous media: delta tracking
    (``majorants``: ``global`` or ``grid``), ratio-tracked connections and deterministic
    stand-in densities in the weights; ``hide_emitters`` with media is refused in one line. Light-subpath seeds come from the
    render's seed; each pass has its own.

    Statistics of the last render: ``bdpt_stats()``.

    .. code-block:: python

        {'type': 'lab_bdpt', 'max_depth': 8, 'heuristic': 'power', 'strategies': 'all'}
    """
    ESTIMATOR = Bidirectional
    PARAMETERS = Bidirectional.PARAMETERS
    #: The kinds ``ray_counts()`` reports.
    RAY_KINDS = ("camera", "extension", "shadow", "connection", "light", "sensor")

    def __init__(self, props: mi.Properties):
        name = self.ESTIMATOR.plugin_name
        values = plugin_settings(name, props, self.PARAMETERS, "integrator")   # (samples_per_pass refused)
        check_variant(name)
        super().__init__(props)
        self.values = values
        self.estimator = self.ESTIMATOR(values)
        self.techniques = self.estimator.techniques()   # the enabled techniques (flags)
        only = values.get("only_strategy", "")
        self.only = Strategy.parse(only) if only else None   # the one strategy rendered, or None
        self.max_depth = DEPTH_UNBOUNDED if values["max_depth"] == UNBOUNDED else values["max_depth"]
        # (read by ``majorants.of_integrator``; lab_vcm has no such parameters: global majorants)
        self.majorants = values.get("majorants", "global")
        self.majorant_resolution = values.get("majorant_resolution", 16)
        #: what the driver does beyond lab_bdpt's parameters (``passes.Passes``: lab_bdpt's own)
        self.passes = Passes()
        self.stats = self.passes.stats_class()
        self.counters = RayCounters(self.RAY_KINDS)
        self._counted_before = {}             # ray counts when the last render began (work_counts)
        self.vertices_per_path = FIRST_GUESS_VERTICES
        self.connectable_per_path = FIRST_GUESS_VERTICES
        self._pass = None                     # CameraPass while a pass's camera subpaths run

    # -- Driver -------------------------------------------------------------------

    def refuse_undeveloped(self, develop: bool) -> None:
        if not develop:
            raise self.error("render(develop=False) is not supported: light tracing splats into a film of "
                             "its own, added to the camera image when developed")

    def refuse_unsupported(self, scene: mi.Scene) -> SceneTraits:
        """The scene's traits; a one-line ValueError naming this plugin where the scene has
        what it cannot render (a sensor, an emitter kind, heterogeneous media)."""
        traits = SceneTraits.from_scene(scene)
        problem = self.ESTIMATOR.unsupported(traits)
        if problem:
            raise ValueError(problem)
        return traits

    def render(self, scene: mi.Scene, sensor=0, seed=0, spp: int = 0, develop: bool = True,
               evaluate: bool = True):
        if self._pass is not None:
            # Mitsuba's render(sensor index) calls render(sensor object) back: the pass is set up
            return base_render(self, scene, sensor, seed, spp, develop, evaluate)
        self.refuse_undeveloped(develop)
        traits = self.refuse_unsupported(scene)
        warn_if_unsupported(self, traits)         # media, or light a strategy subset cannot reach
        sensor, seed, spp = render_arguments(scene, sensor, seed, spp)
        bind_film_layout(scene, sensor)
        film = sensor.film()
        film_px = int(film.size()[0]) * int(film.size()[1])
        crop_px = int(film.crop_size()[0]) * int(film.crop_size()[1])
        v = self.values
        floor = spawn.offset_floor(traits)
        light_depth = -1 if self.max_depth == DEPTH_UNBOUNDED else self.max_depth
        only = self.only
        aim = AimedEmission(scene, v["aim"], v["aim_at"], self.ESTIMATOR.plugin_name)
        tracer = LightTracer(scene, sensor, light_depth, v["rr_depth"], None, floor, only, v["hide_emitters"], aim,
                             self.ESTIMATOR.plugin_name)
        tracer.counters = counters = self.counters if v["count_rays"] else None
        # media: scattered in by both subpaths where the plugin renders them (lab_vcm ignores them)
        media = bool(traits.media and self.ESTIMATOR.RENDERS_MEDIA)
        if media and v["hide_emitters"]:
            raise self.error("hide_emitters is not supported in scenes with participating media yet")
        tracer.media = trace_light if media else False
        # heterogeneous media: delta tracking in both subpaths (majorants = grid: its grid, built once per scene)
        tracer.tracking = Tracking(majorants.of_integrator(self, scene)) if media and traits.heterogeneous_media else None
        # where each emitter's light subpaths start (a one-line error where its rays disagree)
        tracer.emitter_media = emitter_media(scene, sensor, floor, self.ESTIMATOR.plugin_name) if media else None
        # equi-angular flights in the camera subpaths (``camera_flight``; off where equiangular = 0)
        tracer.equiangular = (EquiangularMixture(scene, v.get("equiangular", 0.0), v.get("equiangular_nee", "off"))
                              if media else None)
        tracer.sensor_medium = (mi.MediumPtr(sensor.get_medium()) if media and sensor.get_medium() is not None
                                else dr.zeros(mi.MediumPtr, 1))
        inv_area, axis = sensor_constants(sensor, self.ESTIMATOR.plugin_name)
        passes = self.passes
        self.stats = stats = passes.stats_class()
        # what the passes learn lives in this render: the same first guesses in every render
        self.vertices_per_path = FIRST_GUESS_VERTICES
        self.connectable_per_path = FIRST_GUESS_VERTICES
        self._counted_before = self.counters.read(reset=False) if counters is not None else {}
        total, done, index = None, 0, 0
        light_paths = v.get("light_paths", 1.0)
        u_passes = spectral.pass_samples(seed, spp) if mi.is_spectral else None   # a pass is one spp there
        while done < spp:
            # light subpaths that fit in max_vertices: film pixels x spp_pass, or fewer, shared
            fit = self.light_subpaths_that_fit()
            spp_pass = max(1, min(spp - done, self.pass_iterations(film_px),
                                  1 if mi.is_spectral else spp))        # spectral: one set of wavelengths per pass
            count = passes.light_subpaths(max(1, min(round(film_px * spp_pass * light_paths), fit)), spp_pass,
                                          crop_px * spp_pass)
            plan = PassPlan(index, done, spp_pass, count, crop_px * spp_pass)
            tracer.weights = self.pass_weights(plan)
            u = u_passes[index] if u_passes else None
            if u is not None:
                tracer.pass_spectrum = spectral.sensor_spectrum(sensor, u)
            light_seed = pass_seed(seed if passes.light_seed is None else passes.light_seed, index)
            tracer.channel_key = light_seed
            light = self._light_pass(tracer, film, count, crop_px / count, light_seed, stats,
                                     traits.tangent_bsdf, plan.camera_lanes, media)
            if light is None:                          # did not fit: fewer light subpaths
                continue
            block, vertices, last, stored = light
            self._pass = CameraPass(vertices, last, tracer.weights, tracer.table, inv_area, axis,
                                    self.max_depth, v["rr_depth"], v["hide_emitters"], floor,
                                    traits.hittable_emitters, only, count,
                                    passes.grid(vertices, stored, plan, stats), passes.connect_share,
                                    passes.connect_one, counters, direction_is_delta(sensor), media, light_seed,
                                    sensor.get_medium() if media else None, tracking=tracer.tracking,
                                    equiangular=tracer.equiangular)
            start = time.perf_counter()
            try:
                if u is None:
                    image = base_render(self, scene, sensor, pass_seed(seed, index), spp_pass)
                else:                              # every camera ray at the pass's wavelengths
                    image = spectral.render_pass(self, scene, sensor, dr.opaque(mi.UInt32, pass_seed(seed, index)),
                                                 spp_pass, u)
            finally:
                self._pass = None
            interrupts.checkpoint(self)                # Ctrl-C stops the render here, between passes
            dr.eval(image)
            dr.sync_thread()
            stats.camera_s += time.perf_counter() - start
            image = _add_colour(image, splats.develop(film, block))
            total = image * (spp_pass / spp) if total is None else total + image * (spp_pass / spp)
            dr.eval(total)
            done += spp_pass
            index += 1
            stats.passes += 1
        return total

    # -- What a pass uses -------------------------------------------------------------

    def light_subpaths_that_fit(self) -> int:
        """Light subpaths whose vertices fit in ``max_vertices`` (from the passes so far)."""
        return max(1, int(self.values["max_vertices"] / (1.25 * self.vertices_per_path)))

    def pass_iterations(self, film_pixels: int) -> int:
        """Samples per pixel a pass holds at ``film_pixels`` (before the render's remaining count):
        what fits in ``max_vertices`` at ``light_paths``, and ``Passes.spp_limit``."""
        per_iteration = film_pixels * self.values.get("light_paths", 1.0)
        return max(1, min(int(self.light_subpaths_that_fit() // per_iteration),
                          self.passes.spp_limit(film_pixels, self.stats)))

    def pass_weights(self, plan: PassPlan) -> BdptWeights:
        """The MIS weights of a pass."""
        v, passes = self.values, self.passes
        ratio = plan.light_subpaths / plan.camera_lanes
        weights = (passes.weights_class or BdptWeights)(v["heuristic"], v["beta"], self.techniques, light_paths=ratio,
                                                        merge_area=passes.merge_area(plan),
                                                        merge_from=passes.merge_from,
                                                        caustic_merges=passes.caustic_merges)
        # (opaque: a ratio that changes from pass to pass must not be compiled into the kernels)
        weights.light_paths = dr.opaque(mi.Float, ratio)
        return passes.equip(weights, plan, self.connectable_per_path)

    def _light_pass(self, tracer, film, count: int, sample_scale: float, seed: int, stats, tangents: bool,
                    camera_lanes: int, media: bool = False):
        """Trace ``count`` light subpaths: (splat block, vertices, last slots, stored vertices), or
        None when they needed more than ``max_vertices`` (``vertices_per_path`` is updated; the
        caller retries with fewer). Without merging only the first ``camera_lanes`` subpaths, the
        ones camera subpaths connect to, store vertices."""
        if not tracer.weights.techniques & (Technique.LIGHT | Technique.CONNECT | Technique.MERGE):   # (s <= 1 only)
            return splats.new_block(film), LightVertices(1), dr.full(mi.UInt32, NONE, count), 0
        max_vertices = self.values["max_vertices"]
        capacity = int(min(max_vertices, math.ceil(1.25 * self.vertices_per_path * count) + 1024))
        light_seed = seed ^ 0x5BD1E995
        while True:
            start = time.perf_counter()
            block = splats.new_block(film)
            vertices = LightVertices(capacity, tangents, tracer.weights.merging, tracer.weights.caustic, media)
            reached, stores, last = tracer.trace(count, light_seed, block, sample_scale, vertices,
                                                 None if tracer.weights.merging else camera_lanes)
            dr.eval(block.tensor(), *vertices.arrays(), last, reached, stores)
            dr.sync_thread()
            stats.light_s += time.perf_counter() - start
            n = int(stores[0])
            stats.peak_vertex_bytes = max(stats.peak_vertex_bytes,
                                          capacity * vertex_bytes(tangents, media))
            if n <= capacity:
                break
            stats.retraces += 1
            self.vertices_per_path = max(0.25, n / count)
            if n > max_vertices:
                if count == 1:
                    raise self.error(f"one light subpath stored {n} vertices, more than max_vertices = "
                                     f"{max_vertices}: raise max_vertices or set max_depth")
                return None
            capacity = n                               # same seed, same subpaths: now they fit
        self.vertices_per_path = max(0.25, n / count)
        # (without merging only the subpaths that camera subpaths connect to store vertices)
        self.connectable_per_path = n / (count if tracer.weights.merging else min(count, camera_lanes))
        stats.light_subpaths += count
        stats.light_vertices_reached += int(reached[0])
        stats.light_vertices_stored += n
        return block, vertices, last, n

    # -- Camera subpaths ---------------------------------------------------------------

    def sample(self, scene, sampler, ray, medium=None, active=True):
        """The t >= 2 strategies of one pass (called by Mitsuba's render inside ``render``)."""
        if self._pass is None:
            name = self.ESTIMATOR.plugin_name
            raise self.error(f"cannot be nested inside another integrator (such as aov or moment) that calls "
                             f"its sample(): its light subpaths are traced per pass by its own render(); "
                             f"render the scene with {name} directly")
        if self._pass.media:
            # (the spectral driver's passes, ``spectral.render_pass``, give no medium: the sensor's)
            start = self._pass.sensor_medium if medium is None else medium
            L, valid = trace_camera(scene, self._pass, sampler, mi.Ray3f(ray), start, active)
        else:
            L, valid = trace_camera_subpaths(scene, self._pass, sampler, mi.Ray3f(ray), active)
        return L, valid, []

    # -- Reporting --------------------------------------------------------------------

    def error(self, text: str) -> ValueError:
        """A one-line error naming this plugin (lab_bdpt, or the plugin built on it)."""
        return ValueError(f"{self.ESTIMATOR.plugin_name}: {text}")

    def ray_counts(self, reset: bool = True) -> dict[str, int]:
        """Rays traced since the last reset, by kind (``RAY_KINDS``; all zero when count_rays is off)."""
        return self.counters.read(reset)

    def bdpt_stats(self) -> dict:
        """Statistics of the last render (``BdptStats``), as plain values."""
        return self.stats.as_dict()

    def work_counts(self) -> dict[str, int]:
        """The last render's work by kind (a pilot can price a render by it): its rays as
        ``ray_counts()`` counts them (needs ``count_rays``; else {}), and from its passes
        ``light_vertices`` (stored, for connections and the grids) and ``passes``. The same
        scene, settings, seed and variant count the same."""
        if not self.values["count_rays"]:
            return {}
        now = self.counters.read(reset=False)
        counts = {kind: now[kind] - self._counted_before.get(kind, 0) for kind in now}
        counts.update(light_vertices=self.stats.light_vertices_stored, passes=self.stats.passes)
        return counts

    def settings(self) -> dict:
        return dict(self.values)

    def to_string(self):
        fields = ", ".join(f"{k}={v}" for k, v in self.settings().items())
        return f"LabBDPTIntegrator[{fields}]"

    def aov_names(self):
        return []


def _add_colour(image, splats):
    """``image`` with the colour channels of the light-tracing ``splats`` added (alpha and any
    other channel of the film are the camera image's)."""
    channels = 1 if mi.is_monochromatic else 3
    if image.shape[2] == channels:
        return image + splats
    import numpy as np

    out = np.array(image)
    out[:, :, :channels] += np.array(splats)[:, :, :channels]
    return mi.TensorXf(out)


mi.register_integrator("lab_bdpt", lambda props: LabBDPTIntegrator(props))
