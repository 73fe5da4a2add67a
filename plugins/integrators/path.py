"""The lab's unidirectional path tracers: one path loop, three estimators, three plugins.

``LabPathIntegrator.sample`` is the one path loop, written in the sections that Mitsuba's
``path.cpp`` and ``prb.py`` use (Configure loop state, Direct emission, Emitter sampling,
BSDF sampling, Update loop variables, Stopping criterion). At every vertex it has the
densities of both techniques (``estimator.Densities``: p_B and n_L p_L in solid angle, and
whether the sample came from a delta component); the estimators differ only in the weights
they give an emitter hit and an emitter sample (``naive.Naive``, ``nee.NEE``, ``mis.MIS``;
Veach 1997, ch. 9). The shared pieces: ``direct`` (emitter sampling and emitter hits),
``roulette`` (Russian roulette), ``counters`` (ray counts).

In a scene with participating media the loop gains a *Medium interaction* section (free
flights by delta tracking, ``common.media``); a vertex is then a surface point or a medium
point, whose phase function stands in for the BSDF with the same two weights, and lab_nee and
lab_mis add a third technique for the light scattered along a ray in a medium: equi-angular
sampling towards a light point (Kulla and Fajardo 2012; ``medium_sampling``, ``common.equiangular``).

The plugins ``lab_naive``, ``lab_nee`` and ``lab_mis`` are the subclasses at the end, each
naming its estimator (``ESTIMATOR``), which also answers the experiment planner's questions
(``estimator.Estimator``).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.integrators.common import direct, equiangular, majorants, media, spawn
from mitsuba_lab.plugins.integrators.common.counters import RayCounters
from mitsuba_lab.plugins.integrators.estimator import PathEstimator
from mitsuba_lab.plugins.integrators.mis import MIS
from mitsuba_lab.plugins.integrators.naive import Naive
from mitsuba_lab.plugins.integrators.nee import NEE
from mitsuba_lab.plugins.integrators.common.roulette import russian_roulette
from mitsuba_lab.plugins.integrators.common.support import base_render, warn_if_unsupported
from mitsuba_lab.plugins.params import UNBOUNDED
from mitsuba_lab.plugins.samplers.layout import bind_film_layout
from mitsuba_lab.plugins.variant import plugin_settings
from mitsuba_lab.plugins.scene_traits import SceneTraits

#: max_depth = -1 (unbounded) as the path loop holds it: 2^32 - 1 segments.
DEPTH_UNBOUNDED = 0xFFFFFFFF


@dataclass(frozen=True)
class KernelPlan:
    """Which sections the path loop compiles for a scene, from its ``SceneTraits``.

    Each switch leaves out only code whose contribution is provably zero or whose value is
    provably constant, so the estimator is unchanged:

    * ``emitter_hits`` off: no emitter can be hit (delta lights only, or none): no *Direct
      emission* section;
    * ``emitter_sampling`` off: the estimator does not sample emitters, or the scene has no
      emitter, or no BSDF has a smooth component (NEE is done only at smooth vertices): no
      *Emitter sampling* section, no shadow rays;
    * ``hits_are_delta``: every BSDF is delta and there is no medium, so every emitter hit
      follows a camera ray or a delta bounce, which only BSDF sampling can produce: its weight is
      1 for every unbiased estimator (``PathEstimator``), and no emitter pdf lookup or
      previous-vertex state is needed;
    * ``media`` on: the scene has participating media: the *Medium interaction* section (free
      flights, ``media.free_flight``), phase functions at medium vertices, shadow rays that
      carry transmittance through media and null boundaries (``media.transmittance``), and
      Mitsuba's ``volpath`` counting of depth (null boundaries are no vertices).

    ``offset_floor`` is the scene's coordinate scale for ray offsets (``spawn.offset_floor``).
    """
    emitter_hits: bool
    emitter_sampling: bool
    hits_are_delta: bool
    offset_floor: float = 1.0
    media: bool = False

    @classmethod
    def of(cls, traits: SceneTraits, estimator: PathEstimator) -> "KernelPlan":
        smooth = traits.smooth_bsdf or traits.media          # phase functions are smooth
        return cls(emitter_hits=traits.hittable_emitters,
                   emitter_sampling=estimator.samples_emitters and traits.emitters > 0 and smooth,
                   hits_are_delta=not smooth,
                   offset_floor=spawn.offset_floor(traits),
                   media=traits.media)

    @property
    def tracks_previous_vertex(self) -> bool:
        """Emitter-hit weights need the previous vertex and its BSDF pdf."""
        return self.emitter_hits and not self.hits_are_delta


class LabPathIntegrator(mi.SamplingIntegrator):
    """Base class of the lab's path tracers: the path loop over an estimator (``ESTIMATOR``).

    Parameters are declared in ``plugins/params.py`` (``params.PATH_TRACER``, and an
    estimator's own), read by ``params.read_properties``, and listed at the end of each
    plugin's docstring. ``max_depth`` counts segments: 1 = only emitters seen directly, 2 =
    direct lighting, 0 = nothing (black). ``count_rays`` costs one atomic add per sample.

    Participating media (any phase function, behind ``null`` boundaries, inside dielectrics,
    around the sensor) as ``volpath`` renders them (``common.media``): free flights by delta
    tracking, max_depth counting medium vertices, not null boundaries; in polarized variants
    the media's weights scale the path's Mueller matrix, as in ``volpath``; a shadow ray takes a
    null-transmitting boundary by its unpolarized part (exact for ``null`` and ``mask``; volpath
    keeps a ``thindielectric``'s Mueller matrix). lab_nee and lab_mis declare the medium parameters (``params._media``):
    ``medium_sampling``, ``transmittance``, ``majorants`` and ``spectral_mis``.
    """
    #: The estimator class (weights, own parameters, what it knows about scenes).
    ESTIMATOR: type[PathEstimator] = PathEstimator
    #: Declared parameters (``plugins/params.py``), those of the estimator.
    PARAMETERS = params.PATH_TRACER

    def __init__(self, props: mi.Properties):
        name = self.ESTIMATOR.plugin_name
        # Checked before the C++ base reads hide_emitters, so its type errors never come first.
        values = plugin_settings(name, props, self.PARAMETERS, "integrator")
        super().__init__(props)
        self.max_depth = DEPTH_UNBOUNDED if values["max_depth"] == UNBOUNDED else values["max_depth"]
        self.rr_depth = values["rr_depth"]
        self.hide_emitters = values["hide_emitters"]
        self.count_rays = values["count_rays"]
        # (declared by the path tracers that sample emitters: lab_nee, lab_mis)
        for name, attribute, default in media.SETTINGS:      # lab_naive: the defaults
            setattr(self, attribute, values.get(name, default))
        self.estimator = self.ESTIMATOR(values)
        self.counters = RayCounters()
        self._plan = None                      # (scene, KernelPlan) while render() runs

    @property
    def emitter_samples(self) -> int:
        """Shadow rays per vertex, n_L."""
        return self.estimator.emitter_samples

    # -- The kernel's specialisation ------------------------------------------------------

    def render(self, scene: mi.Scene, sensor=0, seed=0, spp: int = 0, develop: bool = True,
               evaluate: bool = True):
        if self._plan is not None and self._plan[0] is scene:
            # Mitsuba's render(sensor index) calls render(sensor object) back: planned already
            return base_render(self, scene, sensor, seed, spp, develop, evaluate)
        # The plan is made here, before the kernel is traced: reading the scene's traits
        # evaluates scene data (emitter areas, sensor transforms), which inside the trace
        # would split the render into several kernels.
        traits = SceneTraits.from_scene(scene)
        warn_if_unsupported(self, traits)         # never an image silently missing light
        if traits.media:
            majorants.of_integrator(self, scene)     # majorants = grid: built once per scene, or refused
        bind_film_layout(scene, sensor)           # samplers that order pixels learn the film's shape
        self._plan = (scene, KernelPlan.of(traits, self.estimator))
        try:
            return base_render(self, scene, sensor, seed, spp, develop, evaluate)
        finally:
            self._plan = None

    def kernel_plan(self, scene: mi.Scene) -> KernelPlan:
        """The plan for ``scene`` (made by ``render``, else here)."""
        if self._plan is not None and self._plan[0] is scene:
            return self._plan[1]
        return KernelPlan.of(SceneTraits.from_scene(scene), self.estimator)

    # -- The path loop ------------------------------------------------------------

    @dr.syntax
    def sample(self, scene: mi.Scene, sampler: mi.Sampler, ray: mi.RayDifferential3f,
               medium: mi.Medium = None, active: mi.Bool = True):
        bsdf_ctx = mi.BSDFContext()
        plan = self.kernel_plan(scene)            # decided once per trace, in Python
        # (as plain bools: the symbolic loop would treat the dataclass as loop state)
        emitter_hits, emitter_sampling = plan.emitter_hits, plan.emitter_sampling
        hits_are_delta, track_prev = plan.hits_are_delta, plan.tracks_previous_vertex
        floor = plan.offset_floor
        has_media = plan.media
        # equi-angular sampling of the light in media (medium_sampling equiangular or mis), and whether NEE at free-flight collisions is a technique beside it (mis)
        equiangular_on = has_media and emitter_sampling and self.medium_sampling != "distance"
        nee_in_media = self.medium_sampling != "equiangular"
        n_E = self.equiangular_samples              # (on camera rays' segments; one on later ones)
        at_infinity = equiangular.lights_at_infinity(scene)
        spectral = has_media and self.spectral_mis and not mi.is_monochromatic   # (media.free_flight)
        tracking = self.tracking_kind
        estimator = self.estimator
        n_L = estimator.emitter_samples

        # --------------------- Configure loop state ----------------------
        ray = mi.Ray3f(ray)
        active = mi.Bool(active) & (self.max_depth > 0)
        depth = mi.UInt32(0)
        L = mi.Spectrum(0)
        beta = mi.Spectrum(1)                  # path throughput
        eta = mi.Float(1)                      # relative IOR along the path
        prev_it = dr.zeros(mi.Interaction3f)   # previous vertex, for emitter pdfs
        prev_bsdf_pdf = mi.Float(1)
        prev_bsdf_delta = mi.Bool(True)        # camera rays count as "delta": no NEE could reach them
        valid_ray = mi.Bool(False)
        if dr.hint(not self.hide_emitters, mode="scalar"):
            valid_ray = mi.Bool(scene.environment() is not None) & active
        n_ext = mi.UInt32(0)
        n_shadow = mi.UInt32(0)
        camera_lanes = active & dr.full(mi.Bool, True, dr.width(ray))  # `active` may arrive as a scalar
        if dr.hint(has_media, mode="scalar"):
            # the medium the ray travels in (the sensor's, at first), and the channel whose
            # coefficients sample its free flights
            medium = mi.MediumPtr(medium) if medium is not None else dr.zeros(mi.MediumPtr)
            channel = media.sampling_channel(sampler, active)
            phase_ctx = mi.PhaseFunctionContext(sampler)
            grid = majorants.of_integrator(self, scene)
        # the previous vertex's equi-angular state, for emitter hits' weights
        prev_ea = equiangular.Equiangular() if equiangular_on else mi.Bool(False)
        ratios = mi.UnpolarizedSpectrum(1.0) if spectral else mi.Bool(False)   # spectral MIS's r_c
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
        if dr.hint(self.hide_emitters and emitter_hits, mode="scalar"):
            # Mitsuba's meaning: camera rays pass through area emitters to what lies behind them
            ray, pi = spawn.pass_through_emitters(scene, ray, pi, active, floor)

        while dr.hint(active, max_iterations=-1, label=f"{estimator.plugin_name} path loop"):
            si = pi.compute_surface_interaction(ray, ray_flags=mi.RayFlags.All, active=active)
            on_surface = active                     # lanes whose ray reached the surface si

            # --------------------- Medium interaction ----------------------
            # a free flight through the ray's medium: it scatters at mei before si, or gets
            # there with its throughput weighted (media.free_flight)
            if dr.hint(has_media, mode="scalar"):
                in_medium = active & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
                if dr.hint(equiangular_on, mode="scalar"):
                    # the light scattered along the whole segment, sampled towards a light point
                    ea_lanes = in_medium & medium.use_emitter_sampling() & (depth + 1 < self.max_depth)
                    segment = equiangular.Segment.of_ray(medium, ray, si.t, ea_lanes)
                    ea_lanes &= segment.t_max > 0
                    L_ea = mi.Spectrum(0)
                    for k in range(n_E):
                        # n_E samples on a camera ray's segments (depth 0, null boundaries passed), their mean
                        lanes_k = ea_lanes if k == 0 else ea_lanes & (depth == 0)
                        L_k, traced = equiangular.equiangular_scatter(scene, sampler, phase_ctx, medium, segment,
                                                                      ray.wavelengths, beta, channel,
                                                                      estimator.equiangular_weight, n_L,
                                                                      nee_in_media, lanes_k, floor, tracking, grid,
                                                                      ratios if spectral else None)
                        L_ea += L_k
                        n_shadow += dr.select(traced, 1, 0)
                    L += dr.select(depth == 0, L_ea / n_E, L_ea) if n_E > 1 else L_ea
                mei, scattered, w_flight, ratios_next, nulls = media.free_flight(
                    medium, ray, si.t, sampler, channel, in_medium, grid, ratios if spectral else None)
                beta[in_medium] *= mi.Spectrum(w_flight)      # (a diagonal Mueller matrix in polarized variants)
                on_surface = active & ~scattered

            # ----------------------- Direct emission -----------------------
            # L += beta w_B L_e, w_B from the densities of the BSDF sample that found the emitter
            if dr.hint(emitter_hits, mode="scalar"):
                ds = mi.DirectionSample3f(scene, si=si, ref=prev_it)
                if dr.hint(hits_are_delta, mode="scalar"):
                    w_hit = mi.Float(1.0)
                else:
                    d_hit = direct.hit_densities(scene, prev_it, ds, prev_bsdf_pdf, prev_bsdf_delta, n_L)
                    if dr.hint(equiangular_on, mode="scalar"):
                        d_hit = prev_ea.densities(scene, d_hit, prev_it, ds, on_surface, nee_in_media)
                    w_hit = estimator.hit_weight(d_hit)
                emission_on = on_surface & (w_hit > 0)   # (a new array: `&=` on an alias would change `active`)
                if dr.hint(self.hide_emitters, mode="scalar"):
                    emission_on = emission_on & (depth > 0)
                L += beta * w_hit * ds.emitter.eval(si, emission_on)   # beta is finite (checked below)

            bsdf = si.bsdf(ray)
            if dr.hint(has_media, mode="scalar"):
                # --------- Emitter sampling + scattering, at a surface or in a medium ---------
                # the vertex is si (on_surface, a real one unless its BSDF sample is null) or mei
                # (scattered), with the phase function in place of the BSDF
                surface = on_surface & si.is_valid()
                further = depth + 1 < self.max_depth
                phase = mei.medium.phase_function()
                phase[~scattered] = dr.zeros(mi.PhaseFunctionPtr)
                it = dr.zeros(mi.Interaction3f)
                it[surface] = si
                it[scattered] = mei
                ea_here = None
                if dr.hint(equiangular_on, mode="scalar"):
                    p_d = equiangular.distance_pdf(medium, mei.t, mei.sigma_t, channel, ratios if spectral else None,
                                                   equiangular.flight_nulls(nulls, tracking))
                    ea_here = equiangular.Equiangular(segment, p_d, scattered & ea_lanes)
                if dr.hint(emitter_sampling, mode="scalar"):
                    in_medium_nee = scattered & mei.medium.use_emitter_sampling()
                    if dr.hint(equiangular_on and not nee_in_media and not at_infinity, mode="scalar"):
                        in_medium_nee &= ~ea_here.lanes    # equi-angular sampling alone finds that light
                    active_em = further & ((surface & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth))
                                           | in_medium_nee)
                    L, traced = media.emitter_sampling(scene, sampler, bsdf_ctx, phase_ctx, it, si, bsdf, mei,
                                                       phase, scattered, medium, channel, beta, L,
                                                       estimator.sample_weight, n_L, active_em, floor, tracking,
                                                       ea_here, nee_in_media, grid)
                    n_shadow += traced
                # null boundaries are crossed whatever the depth; real vertices scatter below max_depth
                bsdf_sample, bsdf_weight = bsdf.sample(bsdf_ctx, si, sampler.next_1d(), sampler.next_2d(), surface)
                null = mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Null)
                wo, phase_weight, phase_pdf = phase.sample(phase_ctx, mei, sampler.next_1d(), sampler.next_2d(),
                                                           scattered & further)
                real = (surface & ~null) | scattered
                active_next = (surface & (null | further)) | (scattered & further & (phase_pdf > 0))

                # ------------------- Update loop variables ---------------------
                ray = dr.select(scattered, mei.spawn_ray(wo), spawn.spawn_ray(si, si.to_world(bsdf_sample.wo), floor))
                beta *= dr.select(scattered, phase_weight, bsdf_weight)
                eta[surface] *= bsdf_sample.eta
                valid_ray |= real
                if dr.hint(track_prev, mode="scalar"):
                    prev_it[real] = it
                    prev_bsdf_pdf[real] = dr.select(scattered, phase_pdf, bsdf_sample.pdf)
                if dr.hint(equiangular_on, mode="scalar"):
                    prev_ea = dr.select(real, ea_here, prev_ea)
                prev_bsdf_delta[real] = dr.select(scattered, ~mei.medium.use_emitter_sampling(),
                                                  mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Delta))
                medium[surface & si.is_medium_transition()] = si.target_medium(ray.d)
                depth[real] += 1
                if dr.hint(spectral, mode="scalar"):
                    ratios = ratios_next
            else:
                active_next = active & (depth + 1 < self.max_depth) & si.is_valid()

                # ----------------- Emitter sampling + BSDF sampling -----------------
                # L += beta w_L f L_e G / (n_L p_L) for n_L emitter samples; one BSDF sample continues
                if dr.hint(emitter_sampling, mode="scalar"):
                    active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                    L, bsdf_sample, bsdf_weight = direct.emitter_sampling(
                        scene, sampler, bsdf_ctx, si, bsdf, beta, L, estimator.sample_weight, n_L, active_em,
                        active_next, floor)
                    n_shadow += dr.select(active_em, n_L, 0)
                else:
                    bsdf_sample, bsdf_weight = bsdf.sample(bsdf_ctx, si, sampler.next_1d(), sampler.next_2d(),
                                                           active_next)

                # ------------------- Update loop variables ---------------------
                ray = spawn.spawn_ray(si, si.to_world(bsdf_sample.wo), floor)
                beta *= bsdf_weight
                eta *= bsdf_sample.eta
                valid_ray |= active & si.is_valid() & ~mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Null)
                if dr.hint(track_prev, mode="scalar"):
                    prev_it = dr.zeros(mi.Interaction3f)
                    prev_it.p, prev_it.n, prev_it.t, prev_it.time = si.p, si.n, si.t, si.time
                    prev_it.wavelengths = si.wavelengths
                    prev_bsdf_pdf = bsdf_sample.pdf
                prev_bsdf_delta = mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Delta)

                depth[si.is_valid()] += 1

            # --------------------- Stopping criterion ----------------------
            beta_max = dr.max(mi.unpolarized_spectrum(beta))
            active_next &= (beta_max != 0) & dr.isfinite(beta_max)
            beta, survives = russian_roulette(beta, sampler.next_1d(), depth >= self.rr_depth, eta=eta)
            active_next &= survives

            pi = scene.ray_intersect_preliminary(ray, coherent=False, active=active_next)
            n_ext += dr.select(active_next, 1, 0)
            active = active_next

        if dr.hint(self.count_rays, mode="scalar"):
            self.counters.add("camera", mi.UInt32(1), camera_lanes)
            self.counters.add("extension", n_ext, camera_lanes)
            if dr.hint(emitter_sampling, mode="scalar"):
                self.counters.add("shadow", n_shadow, camera_lanes)
        # valid_ray is the pixel's alpha only. Mitsuba's path zeroes L where it is false, which
        # drops the light gathered at a mask's opaque part whenever the path then leaves through
        # its null lobe and escapes (a one-sided mask sphere under a point light renders 0.76x
        # Mitsuba's own `direct`); volpath and direct keep L, and so does the lab.
        return L, valid_ray, []

    # -- Reporting --------------------------------------------------------------------

    def ray_counts(self, reset: bool = True) -> dict[str, int]:
        """Rays traced since the last reset, by kind (all zero when count_rays is off)."""
        return self.counters.read(reset)

    def settings(self) -> dict:
        """The parameters in force, as plain values, every declared one in declaration order
        (equal to ``params.resolve(plugin_name, given)``; for file metadata and messages)."""
        values = {"max_depth": UNBOUNDED if self.max_depth == DEPTH_UNBOUNDED else self.max_depth,
                  "rr_depth": self.rr_depth, "hide_emitters": self.hide_emitters,
                  "count_rays": self.count_rays, **{name: getattr(self, a) for name, a, _ in media.SETTINGS},
                  **self.estimator.settings()}
        return {p.name: values[p.name] for p in self.PARAMETERS}

    def to_string(self):
        fields = ", ".join(f"{k}={v}" for k, v in self.settings().items())
        return f"{type(self).__name__}[{fields}]"

    def aov_names(self):
        return []


# ---------------------------------------------------------------------------
# The plugins
# ---------------------------------------------------------------------------
@documented("lab_naive")
class LabNaiveIntegrator(LabPathIntegrator):
    r"""Naive path tracer (:monosp:`lab_naive`)

    Each vertex samples one direction from the BSDF; emitted radiance is added, with weight 1,
    wherever a path happens to hit an emitter: the plain Neumann-series estimator of the
    rendering equation (Kajiya 1986). Unbiased for every emitter a BSDF-sampled ray can hit,
    and very noisy when emitters are small. It never samples emitters, so it **cannot reach
    delta lights** (point, spot, directional): in scenes lit by them its image lacks that
    light (biased).

    Parameters: ``max_depth`` (default -1, unbounded), ``rr_depth`` (5), ``hide_emitters``
    (false), ``count_rays`` (true); see ``LabPathIntegrator``. Estimator: ``naive.Naive``.

    .. code-block:: python

        {'type': 'lab_naive', 'max_depth': 8}
    """
    ESTIMATOR = Naive
    PARAMETERS = Naive.PARAMETERS


@documented("lab_nee")
class LabNEEIntegrator(LabPathIntegrator):
    r"""Next-event estimation (:monosp:`lab_nee`)

    At every vertex whose BSDF has a non-delta (smooth) component, sample a point on an
    emitter and trace a shadow ray (the direct term of the three-point form). BSDF sampling
    only extends the path: emission it finds counts for camera rays and after delta
    (specular) bounces, which NEE cannot produce, and nowhere else, so no light is counted
    twice. Unbiased for area, environment and delta emitters. Near-specular reflections of
    large emitters are noisy here (a point sampled on the emitter rarely falls in a sharp
    BSDF lobe): that is what ``lab_mis`` fixes.

    Parameters: ``max_depth`` (default -1, unbounded), ``rr_depth`` (5), ``hide_emitters``
    (false), ``count_rays`` (true); see ``LabPathIntegrator``. In media ``medium_sampling``
    (``distance``, the default: NEE at free-flight collisions; ``equiangular``; or ``mis``, the two
    light samples weighted by the balance heuristic), ``equiangular_samples``, ``transmittance``, ``majorants``,
    ``majorant_resolution`` and ``spectral_mis`` (true). Estimator: ``nee.NEE``.

    .. code-block:: python

        {'type': 'lab_nee', 'max_depth': 8}
    """
    ESTIMATOR = NEE
    PARAMETERS = NEE.PARAMETERS


@documented("lab_mis")
class LabMISIntegrator(LabPathIntegrator):
    r"""Multiple importance sampling path tracer (:monosp:`lab_mis`)

    Every vertex with a smooth BSDF component takes ``emitter_samples`` (n_L) emitter samples
    and one BSDF sample; each sample that reaches an emitter is weighted by Veach's
    multi-sample MIS estimator (Veach & Guibas 1995; Veach 1997, sec. 9.2):

        w_B(x) = h(p_B(x), n_L p_L(x)),  w_L(x) = h(n_L p_L(x), p_B(x)),

    with both densities in solid angle and the emitter-sample contributions divided by n_L.
    Delta emitters (only NEE reaches them) and delta BSDF lobes (only BSDF sampling reaches
    their emitters) get weight 1, which keeps the estimator unbiased.

    All weights are computed from pdf ratios (``mis_weight.mis_weight``), so pdfs of 0, 1e-30,
    1e30 or inf give the right limit and never NaN. Estimator: ``mis.MIS``. ``heuristic =
    average`` weights 1/2 each wherever both techniques can sample x: the plain average of the
    two estimators, Veach's cautionary example, kept for study. The kernel holds
    ``emitter_samples`` copies of the emitter-sampling code.

    In a medium, ``medium_sampling = mis`` adds a third technique for the light
    scattered along each ray segment: a light point y sampled from the segment's origin and a
    distance t with density proportional to 1 / |x(t) - y|^2 (equi-angular sampling, Kulla and
    Fajardo 2012). The three techniques (free flight + emitter sample, free flight + phase
    sample, equi-angular) are weighted by the heuristic over their densities per unit distance
    and solid angle (``mis_weight.mis_weight_many``); in heterogeneous media the free flight's
    density is taken over its null collisions (``common.equiangular``). ``equiangular_samples``
    (n_E, default 1) takes n_E equi-angular samples on the segments of camera rays and averages
    them (splitting the single scattering the pixel sees directly, where a point light's
    visibility through occluders is noisiest); later segments take one. A sample whose MIS weight
    is 0 (``heuristic = max``: another technique's density is larger there) traces no shadow
    ray, so with ``max`` each light sample in a medium costs a shadow ray only where it counts. In chromatic media ``spectral_mis``
    samples distances with one channel's coefficients and weights by the mean of every
    channel's density (one-sample MIS over the channels, as ``volpathmis``, Miller et al. 2019);
    in heterogeneous media ``majorants = grid`` tracks against local bounds of a coarse grid
    walked cell by cell (``common.majorants``, as pbrt-v4's majorant grid) instead of one bound.

    .. code-block:: python

        {'type': 'lab_mis', 'heuristic': 'power', 'beta': 2.0, 'emitter_samples': 1}
    """
    ESTIMATOR = MIS
    PARAMETERS = MIS.PARAMETERS


mi.register_integrator("lab_naive", lambda props: LabNaiveIntegrator(props))
mi.register_integrator("lab_nee", lambda props: LabNEEIntegrator(props))
mi.register_integrator("lab_mis", lambda props: LabMISIntegrator(props))
