"""Pieces shared by the lab's unidirectional path tracers.

``LabPathIntegrator.sample`` is the one path loop, written in the sections that
Mitsuba's ``path.cpp`` and ``prb.py`` use (Configure loop state, Direct
emission, Emitter sampling, BSDF sampling, Update loop variables, Stopping
criterion). The estimators differ only in how they weight the two ways a path
can reach an emitter, so each subclass supplies two small methods:

* ``emitter_hit_weight``: the weight of emission found by a BSDF-sampled ray;
* ``emitter_sample_weight``: the weight of one next-event (shadow-ray) sample,
  or ``None`` when the estimator does not sample emitters at all.

With these, ``lab_naive``, ``lab_nee`` and ``lab_mis`` can be read side by side
and their differences are exactly those two sections (Veach 1997, ch. 9).
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.variant import require_jit_variant
from mitsuba_lab.plugins.params import HEURISTICS, UNBOUNDED  # noqa: F401 (re-exported)

#: Survival probability cap: every path stops with probability >= 5% per bounce
#: past rr_depth, so even a closed box of albedo 1 terminates.
RR_MAX_SURVIVAL = 0.95
#: max_depth = -1 (unbounded) as the path loop holds it: 2^32 - 1 segments.
DEPTH_UNBOUNDED = 0xFFFFFFFF


def mis_weight(pdf_self, pdf_other, heuristic: str = "power", beta: float = 2.0):
    """MIS weight of a sample drawn by the technique with effective density ``pdf_self``.

    ``pdf_self`` and ``pdf_other`` are n_i * p_i(x) (Veach's multi-sample
    estimator), in the same measure. The weights of the two techniques sum to 1
    wherever either density is positive, for densities anywhere in [0, inf]:

    * power (beta) / balance (beta = 1): 1 / (1 + r^beta) with r = pdf_other / pdf_self.
      Working with the ratio avoids pdf^beta, which overflows float32 once
      pdf > 3.4e38^(1/beta); an overflowing r^beta gives the right limit (0).
    * max: 1 for the larger density, 1/2 each on a tie.
    * average: 1/2 wherever both densities are positive (the plain average,
      Veach's cautionary example), 1 where only this technique can sample x.
    A zero (or NaN) ``pdf_self`` gets weight 0; inf against a finite pdf gets 1.
    A NaN or negative ``pdf_other`` counts as 0 (that technique cannot sample x), so a
    broken density elsewhere never turns this weight into NaN.
    """
    pdf_other = dr.select(pdf_other > 0, pdf_other, 0.0)
    both_inf = dr.isinf(pdf_self) & dr.isinf(pdf_other)
    if heuristic in ("balance", "power"):
        if heuristic == "balance":
            beta = 1.0
        r = dr.select(both_inf, 1.0, pdf_other / pdf_self)
        if beta == 1.0:
            r_beta = r
        elif beta == 2.0:
            r_beta = dr.square(r)
        else:
            r_beta = dr.power(r, beta)
        w = dr.rcp(1.0 + r_beta)
    elif heuristic == "max":
        w = dr.select(pdf_self > pdf_other, 1.0, dr.select(pdf_self == pdf_other, 0.5, 0.0))
    elif heuristic == "average":
        w = dr.select(pdf_other > 0, 0.5, 1.0)
    else:
        raise ValueError(f"unknown MIS heuristic '{heuristic}'; expected one of {', '.join(HEURISTICS)}")
    return dr.select(pdf_self > 0, w, 0.0)


def russian_roulette_probability(beta, eta):
    """Survival probability q = min(max(beta) * eta^2, 0.95).

    Tying q to the throughput kills dim paths early (seed text, "Russian
    roulette"); eta^2 undoes the radiance scaling at refractive boundaries so a
    path inside glass is not culled for a throughput that will come back.
    Returns a value in [0, 0.95]: NaN (0 * inf throughput) maps to 0, i.e. the path
    stops; callers divide by q only where q > 0 (``rr_scale``).
    """
    q = dr.minimum(dr.max(mi.unpolarized_spectrum(beta)) * dr.square(eta), RR_MAX_SURVIVAL)
    return dr.select(q > 0, q, 0.0)


def finite_or_zero(value):
    """``value`` where all its channels are finite, else 0 (a guard against 0 * inf)."""
    return dr.select(dr.isfinite(dr.max(mi.unpolarized_spectrum(value))), value, 0.0)


def rr_scale(q):
    """1 / q for a surviving path; 0 where q = 0 (such a path never survives)."""
    return dr.select(q > 0, dr.rcp(q), 0.0)


# ---------------------------------------------------------------------------
# What a scene contains, as far as the path loop is concerned
# ---------------------------------------------------------------------------
#: Mitsuba class name -> plugin name of the delta emitters (for messages).
DELTA_EMITTER_PLUGINS = {"PointLight": "point", "SpotLight": "spot",
                         "DirectionalEmitter": "directional", "Projector": "projector"}


def emitter_kind(emitter) -> str:
    """'delta' (point, spot, directional, projector: no ray can hit it), 'area'
    (on a shape), 'environment' (at infinity, hit by escaping rays) or 'other'
    (anything else: treated as both hittable and sampleable)."""
    flags = int(emitter.flags())
    if flags & int(mi.EmitterFlags.Delta):
        return "delta"
    if flags & int(mi.EmitterFlags.Surface):
        return "area"
    if flags & int(mi.EmitterFlags.Infinite):
        return "environment"
    return "other"


def bsdf_has_smooth_component(shape) -> bool:
    """Whether the shape's BSDF has a non-delta lobe (a vertex NEE can connect from).

    Conservative: shapes whose BSDF cannot be inspected (instances of shape
    groups) count as smooth, so no code is ever left out that they might need.
    """
    bsdf = shape.bsdf() if shape.class_name() != "Instance" else None
    if bsdf is None:
        return True
    return bool(int(bsdf.flags()) & int(mi.BSDFFlags.Smooth))


@dataclass(frozen=True)
class KernelTraits:
    """The few facts about a scene that decide which code the path loop compiles.

    * ``hittable_emitters``: an area, environment or other non-delta emitter exists,
      so a ray can find emission (else the *Direct emission* section is left out);
    * ``emitters``: any emitter exists to sample;
    * ``smooth_bsdf``: some BSDF has a smooth component, i.e. some vertex can use an
      emitter sample (else *Emitter sampling* is left out: no shadow rays).
    """
    hittable_emitters: bool
    emitters: bool
    smooth_bsdf: bool

    @classmethod
    def of(cls, scene) -> "KernelTraits":
        kinds = [emitter_kind(e) for e in scene.emitters()]
        return cls(hittable_emitters=any(k != "delta" for k in kinds),
                   emitters=bool(kinds),
                   smooth_bsdf=any(bsdf_has_smooth_component(s) for s in scene.shapes()))


class RayCounters:
    """Camera, extension (BSDF) and shadow rays traced, summed over all lanes.

    Each lane counts in registers inside the path loop; one atomic add per
    lane and kind after the loop (reduced within each SIMD packet first)
    keeps the cost to a few instructions per sample.
    """
    KINDS = ("camera", "extension", "shadow")

    def __init__(self):
        self.totals = dr.zeros(mi.UInt64, len(self.KINDS))

    def add(self, kind: str, per_lane, active):
        dr.scatter_reduce(dr.ReduceOp.Add, self.totals, mi.UInt64(per_lane),
                          self.KINDS.index(kind), active, mode=dr.ReduceMode.Local)

    def read(self, reset: bool = True) -> dict[str, int]:
        dr.eval(self.totals)
        values = self.totals.numpy().tolist()
        if reset:
            self.totals = dr.zeros(mi.UInt64, len(self.KINDS))
        return {kind: int(v) for kind, v in zip(self.KINDS, values)}


class LabPathIntegrator(mi.SamplingIntegrator):
    """Base class: parameters shared by every lab path tracer and the path loop.

    Parameters (declared in ``plugins/params.py``, ``params.PATH_TRACER``, and read
    from the plugin's properties by ``params.read_properties``; subclasses extend them):

    ============= ====== ==========================================================
    max_depth     int    Longest path, in segments: 1 = only emitters seen
                         directly, 2 = direct lighting, 0 = nothing (black),
                         -1 = unbounded (Default: -1)
    rr_depth      int    Depth at which Russian roulette starts, >= 1 (Default: 5)
    hide_emitters bool   Mitsuba's meaning: camera rays pass through area
                         emitters to what lies behind them, and where they
                         see only the environment the pixel is invalid
                         (black, alpha 0). (Default: false)
    count_rays    bool   Count camera, extension and shadow rays; read them with
                         ``ray_counts()``. Costs one atomic add per sample.
                         (Default: true)
    ============= ====== ==========================================================
    """

    #: Plugin name, for messages.
    plugin_name = "lab_path"
    #: Declared parameters (``plugins/params.py``); subclasses extend the tuple there.
    PARAMETERS = params.PATH_TRACER

    def __init__(self, props: mi.Properties):
        # Checked before the C++ base reads hide_emitters, so its type errors never come first.
        require_jit_variant(type(self).plugin_name)
        values = params.read_properties(type(self).plugin_name, props, type(self).PARAMETERS, "integrator")
        super().__init__(props)
        self.max_depth = DEPTH_UNBOUNDED if values["max_depth"] == UNBOUNDED else values["max_depth"]
        self.rr_depth = values["rr_depth"]
        self.hide_emitters = values["hide_emitters"]
        self.count_rays = values["count_rays"]
        self.counters = RayCounters()
        self.configure(values)

    def configure(self, values: dict):
        """Take the subclass's own parameters from the checked ``values`` (all declared names)."""

    # -- What differs between the estimators ------------------------------------

    def emitter_hit_weight(self, scene, prev_it, ds, prev_bsdf_pdf, prev_bsdf_delta):
        """Weight of emission found by a BSDF-sampled ray (camera rays and rays
        after a delta bounce arrive with prev_bsdf_delta = True)."""
        raise NotImplementedError

    def emitter_sample_weight(self, ds, bsdf_pdf):
        """Weight of one emitter sample (used only when ``samples_emitters``)."""
        raise NotImplementedError

    #: Whether the estimator samples emitters (next-event estimation) at all.
    samples_emitters = False
    #: Shadow rays per vertex (n_L in Veach's multi-sample estimator).
    emitter_samples = 1

    #: Contract that lets the loop leave code out on scenes whose BSDFs are all
    #: delta: emission reached by a camera ray or right after a delta bounce has
    #: weight 1 (no other technique can produce that path). True for lab_naive,
    #: lab_nee and lab_mis; a subclass that weights such hits otherwise sets False.
    delta_hit_weight_is_one = True

    def kernel_plan(self, scene) -> dict:
        """Python-level switches of the path loop for this scene (see KernelTraits).

        Each switch only leaves out code whose contribution is provably zero or
        whose value is provably constant, so the estimator is unchanged:

        * ``hit_emission`` off: no emitter can be hit (delta lights only, or none);
        * ``sample_emitters`` off: the estimator does not sample emitters, or the
          scene has no emitter, or no BSDF has a smooth component (NEE is only
          done at smooth vertices, so it would never fire);
        * ``unit_hit_weight``: every BSDF is delta, so every emitter hit follows a
          camera ray or a delta bounce and has weight 1 (``delta_hit_weight_is_one``):
          no emitter pdf lookup, no previous-vertex state;
        * ``unit_sample_weight``: no emitter can be hit, so every emitter sample is
          of a delta emitter, which BSDF sampling cannot produce: its weight is 1.
        """
        traits = KernelTraits.of(scene)
        sample_emitters = self.samples_emitters and traits.emitters and traits.smooth_bsdf
        return {"hit_emission": traits.hittable_emitters,
                "sample_emitters": sample_emitters,
                "unit_hit_weight": self.delta_hit_weight_is_one and not traits.smooth_bsdf,
                "unit_sample_weight": not traits.hittable_emitters}

    # -- The path loop ------------------------------------------------------------

    @dr.syntax
    def sample(self, scene: mi.Scene, sampler: mi.Sampler, ray: mi.RayDifferential3f,
               medium: mi.Medium = None, active: mi.Bool = True):
        bsdf_ctx = mi.BSDFContext()
        plan = self.kernel_plan(scene)            # decided once per trace, in Python
        hit_emission = plan["hit_emission"]
        samples_emitters = plan["sample_emitters"]
        unit_hit_weight = plan["unit_hit_weight"]
        unit_sample_weight = plan["unit_sample_weight"]
        track_prev = hit_emission and not unit_hit_weight   # MIS needs the previous vertex
        n_L = self.emitter_samples

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
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
        if dr.hint(self.hide_emitters and hit_emission, mode="scalar"):
            # Mitsuba's meaning: camera rays pass through area emitters to what lies behind
            ray, pi = self.skip_directly_visible_emitters(scene, ray, pi, active)

        while dr.hint(active, max_iterations=-1, label=f"{self.plugin_name} path loop"):
            si = pi.compute_surface_interaction(ray, ray_flags=mi.RayFlags.All, active=active)

            # ----------------------- Direct emission -----------------------
            if dr.hint(hit_emission, mode="scalar"):
                ds = mi.DirectionSample3f(scene, si=si, ref=prev_it)
                if dr.hint(unit_hit_weight, mode="scalar"):
                    w_hit = mi.Float(1.0)
                else:
                    w_hit = self.emitter_hit_weight(scene, prev_it, ds, prev_bsdf_pdf, prev_bsdf_delta)
                emission_on = active & (w_hit > 0)   # (a new array: `&=` on an alias would change `active`)
                if dr.hint(self.hide_emitters, mode="scalar"):
                    emission_on = emission_on & (depth > 0)
                L += beta * w_hit * ds.emitter.eval(si, emission_on)   # beta is finite (checked below)

            active_next = active & (depth + 1 < self.max_depth) & si.is_valid()
            bsdf = si.bsdf(ray)

            # ----------------------- Emitter sampling ----------------------
            if dr.hint(samples_emitters, mode="scalar"):
                active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
                ds_em, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
                n_shadow += dr.select(active_em, n_L, 0)

            # ------------------------ BSDF sampling ------------------------
            if dr.hint(samples_emitters, mode="scalar"):
                # One BSDF call both evaluates the emitter direction and samples the next one
                # (as Mitsuba's path.cpp does): one virtual call per vertex instead of two.
                bsdf_val, bsdf_pdf, bsdf_sample, bsdf_weight = bsdf.eval_pdf_sample(
                    bsdf_ctx, si, si.to_local(ds_em.d), sampler.next_1d(), sampler.next_2d(), active_next)
            else:
                bsdf_sample, bsdf_weight = bsdf.sample(bsdf_ctx, si, sampler.next_1d(), sampler.next_2d(),
                                                       active_next)

            # --------------- Emitter sampling contribution -----------------
            if dr.hint(samples_emitters, mode="scalar"):
                L += self.emitter_contribution(beta, ds_em, em_weight, bsdf_val, bsdf_pdf, active_em,
                                               unit_sample_weight)
                for _ in range(n_L - 1):   # Veach's multi-sample estimator: n_L shadow rays
                    ds_em, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
                    bsdf_val, bsdf_pdf = bsdf.eval_pdf(bsdf_ctx, si, si.to_local(ds_em.d), active_em)
                    L += self.emitter_contribution(beta, ds_em, em_weight, bsdf_val, bsdf_pdf, active_em,
                                                   unit_sample_weight)

            # ------------------- Update loop variables ---------------------
            ray = si.spawn_ray(si.to_world(bsdf_sample.wo))
            beta *= bsdf_weight
            eta *= bsdf_sample.eta
            valid_ray |= active & si.is_valid() & ~mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Null)
            if dr.hint(track_prev, mode="scalar"):
                prev_it = dr.zeros(mi.Interaction3f)
                prev_it.p, prev_it.n, prev_it.t, prev_it.time = si.p, si.n, si.t, si.time
                prev_it.wavelengths = si.wavelengths
                prev_bsdf_pdf = bsdf_sample.pdf
            prev_bsdf_delta = mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Delta)

            # --------------------- Stopping criterion ----------------------
            depth[si.is_valid()] += 1
            beta_max = dr.max(mi.unpolarized_spectrum(beta))
            active_next &= (beta_max != 0) & dr.isfinite(beta_max)
            q = russian_roulette_probability(beta, eta)
            rr_active = depth >= self.rr_depth
            beta[rr_active] *= rr_scale(q)
            active_next &= ~rr_active | (sampler.next_1d() < q)

            pi = scene.ray_intersect_preliminary(ray, coherent=False, active=active_next)
            n_ext += dr.select(active_next, 1, 0)
            active = active_next

        if dr.hint(self.count_rays, mode="scalar"):
            self.counters.add("camera", mi.UInt32(1), camera_lanes)
            self.counters.add("extension", n_ext, camera_lanes)
            if dr.hint(samples_emitters, mode="scalar"):
                self.counters.add("shadow", n_shadow, camera_lanes)
        return dr.select(valid_ray, L, 0), valid_ray, []

    def emitter_contribution(self, beta, ds, em_weight, bsdf_val, bsdf_pdf, active,
                             unit_weight: bool = False):
        """beta * w_L * f * L_e G / (n_L p_L) for one emitter sample (em_weight = L_e G / p_L).

        ``unit_weight``: the scene's emitters are all delta, so w_L = 1 (see kernel_plan).
        A sample with a zero, negative or NaN pdf, or a non-finite value (a degenerate
        emitter, e.g. of zero area), contributes 0.
        """
        sampled = active & (ds.pdf > 0)
        if unit_weight:
            w_em = mi.Float(1.0 / self.emitter_samples)
        else:
            w_em = self.emitter_sample_weight(ds, bsdf_pdf) / self.emitter_samples
        return dr.select(sampled, finite_or_zero(beta * w_em * bsdf_val * em_weight), 0)

    def skip_directly_visible_emitters(self, scene, ray, pi, active):
        """(ray, first intersection) with area emitters hit by camera rays skipped."""
        skip = active & pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711 (Dr.Jit pointer test)
        si_skip = pi.compute_surface_interaction(ray, mi.RayFlags.Minimal, skip)
        ray_skip = si_skip.spawn_ray(ray.d)
        pi_skip = self.skip_area_emitters(scene, ray_skip, True, skip)
        return dr.select(skip, ray_skip, ray), dr.select(skip, pi_skip, pi)

    # -- Reporting --------------------------------------------------------------------

    def ray_counts(self, reset: bool = True) -> dict[str, int]:
        """Rays traced since the last reset, by kind (all zero when count_rays is off)."""
        return self.counters.read(reset)

    def settings(self) -> dict:
        """The parameters in force, as plain values, every declared one in declaration
        order (equal to ``params.resolve(plugin_name, given)``; for file metadata and messages)."""
        values = {p.name: getattr(self, p.name) for p in self.PARAMETERS}
        values["max_depth"] = UNBOUNDED if self.max_depth == DEPTH_UNBOUNDED else self.max_depth
        return values

    def to_string(self):
        fields = ", ".join(f"{k}={v}" for k, v in self.settings().items())
        return f"{type(self).__name__}[{fields}]"

    def aov_names(self):
        return []
