"""Camera side: the kernel density estimate of reflected radiance at a camera vertex.

At a camera vertex x with outgoing direction wo (towards the camera), the photons
p within distance r estimate the reflected radiance (Jensen 2001, eq. 7.6, with a
smooth kernel instead of the constant disk):

    L_r(x, wo) ~= sum_p f(x, wo, wi_p) (|wi_p . n_s| / |wi_p . n_p|) Phi_p K(|x - x_p| / r) / r^2

with the 2D Epanechnikov kernel K(t) = (2 / pi) (1 - t^2) for t < 1, 0 otherwise,
normalised over the plane: int_{R^2} K(|u|) du = 1. The photons' flux is per unit of
*geometric* area, Phi_p ~ L_i |wi_p . n_g|, while the reflected radiance integrates
f L_i |wi_p . n_s| over directions (n_s the shading normal the BSDF uses), so each photon
counts with f |wi_p . n_s| / |wi_p . n_g|: Mitsuba's ``BSDF.eval(ctx, si, wi_p)`` (which is
f times the cosine of the BSDF's own shading normal, perturbed by a normal map if there is
one) divided by |wi_p . n_p|, the photon's geometric cosine. Without shading normals that is
f: the photon's flux per area already is irradiance. (Veach 1997, sec. 5.3; the photons'
own adjoint correction is in ``tracer``.)

A photon counts only if

* it lies in the 3 x 3 x 3 cells around x's cell (cell size = r) and its own cell is
  the one being visited (a hash collision never counts a photon twice);
* |x - x_p| < r;
* n_x . n_p > ``NORMAL_COS`` (a photon on a surface facing another way, e.g. on the
  other wall at a corner or the far side of a thin slab, is rejected);
* its path length plus the camera's stays within ``max_depth``.

**Camera paths** (``CameraPass.sample``) follow delta lobes (mirror, glass, a ``mask``'s
pass-through) and estimate the radiance at every vertex with a smooth lobe, as pbrt-v4's
SPPM makes its visible points at non-specular interactions. A BSDF with both (``plastic``,
``mask`` with partial opacity, ``blendbsdf`` of a dielectric and a diffuse BSDF,
``twosided`` of those) gets both: the density estimate and next-event estimation there see
only its smooth lobes (``eval`` never includes a delta lobe, and the BSDF sample of the
direct-light MIS is dropped when it picks a delta lobe), and the path goes on through its
delta lobes alone, sampled with a ``BSDFContext`` whose type mask holds only the delta
flags (weight w_d, E[w_d] = the delta lobes' share of the reflected light). The two parts
add up to the BSDF (splitting: no choice between them, so a bright mirror image in a
plastic's weak Fresnel reflection is not amplified by a 1 / probability). A path that
crosses k mixed vertices gathers up to k + 1 times; where no BSDF is mixed it gathers once,
at its first smooth vertex. (Sampling the delta lobes alone also sidesteps ``blendbsdf``'s
full ``sample()``, which adds the smooth BSDF's density to the delta lobe's discrete
probability and so weights a delta sample low: 0.55 instead of 0.6 for a 0.4 blend of a
mirror and a diffuse BSDF. Mitsuba's ``path`` inherits that.)

``hide_emitters``: camera rays pass through area emitters (Mitsuba's meaning, as the lab's
path tracers); a camera ray that sees only the environment leaves its pixel invalid (alpha 0).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import direct, spawn
from mitsuba_lab.plugins.integrators.common.counters import RayCounters
from mitsuba_lab.plugins.integrators.common.mis_weight import hit_weight, sample_weight
from mitsuba_lab.plugins.integrators.common.roulette import russian_roulette

from . import media_camera
from .estimates import DELTA_MASK, density_estimate  # noqa: F401 (tests import DELTA_MASK from here)

class CameraPass(mi.SamplingIntegrator):
    """One camera pass of ``lab_photon`` against the current photon map (not a plugin).

    Its ``render`` is Mitsuba's own ``SamplingIntegrator.render`` (film, filter,
    sampler, spp); its ``sample`` follows camera paths through delta lobes and estimates
    the radiance at every vertex with a smooth lobe (see the module's docstring).
    ``grid`` (a PhotonGrid or None), ``with_direct`` (count emission and NEE: only
    in the first batch of a pass), ``offset_floor`` (``spawn.offset_floor``) and
    ``hide_emitters`` are set by the driver, and in scenes with media ``volume_grid``, ``media``
    and ``tracking``; ``settings`` is its PhotonSettings.
    """

    def __init__(self, settings):
        super().__init__(mi.Properties())
        self.settings = settings
        self.grid = None
        #: the volumetric photons' grid (a PhotonGrid or None), ``media`` (the scene has media:
        #: ``media_camera``'s loop) and ``tracking`` (``subpath_media.Tracking`` or None), set by the driver
        self.volume_grid = None
        self.media = False
        self.tracking = None
        self.with_direct = True
        self.hide_emitters = False
        self.offset_floor = 1.0
        self.counters = RayCounters()                  # camera-side extension and shadow rays

    @dr.syntax
    def sample(self, scene: mi.Scene, sampler: mi.Sampler, ray: mi.RayDifferential3f,
               medium: mi.Medium = None, active: mi.Bool = True):
        if dr.hint(self.media, mode="scalar"):
            L, valid_ray, n_ext, n_shadow = media_camera.trace_camera(self, scene, sampler, ray, medium, active)
            self.counters.add("extension", n_ext)
            self.counters.add("shadow", n_shadow)
            return L, valid_ray, []
        cfg = self.settings
        grid = self.grid
        with_direct = self.with_direct
        hide = self.hide_emitters
        floor = self.offset_floor
        use_nee = cfg.direct == "nee"
        bsdf_ctx = mi.BSDFContext()
        delta_ctx = mi.BSDFContext(mi.TransportMode.Radiance, DELTA_MASK)
        max_depth = dr.opaque(mi.UInt32, cfg.depth_limit)
        rr_depth = dr.opaque(mi.UInt32, cfg.rr_depth)

        # --------------------- Configure loop state ----------------------
        ray = mi.Ray3f(ray)
        active = mi.Bool(active)
        depth = mi.UInt32(0)
        L = mi.Spectrum(0)
        beta = mi.Spectrum(1)
        eta = mi.Float(1)
        valid_ray = mi.Bool(False)
        if dr.hint(not hide, mode="scalar"):
            valid_ray = mi.Bool(scene.environment() is not None) & active
        n_ext = mi.UInt32(0)
        n_shadow = mi.UInt32(0)
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
        if dr.hint(hide, mode="scalar"):
            # Mitsuba's meaning: camera rays pass through area emitters to what lies behind them
            ray, pi = spawn.pass_through_emitters(scene, ray, pi, active, floor)

        # ---- Camera path: gather at smooth vertices, continue through delta lobes ----
        while dr.hint(active, max_iterations=-1, label="lab_photon camera loop"):
            si = pi.compute_surface_interaction(ray, ray_flags=mi.RayFlags.All, active=active)
            hit = active & si.is_valid()

            # ----------------------- Direct emission -----------------------
            if dr.hint(with_direct, mode="scalar"):
                emission_on = active
                if dr.hint(hide, mode="scalar"):
                    emission_on = active & (depth > 0)        # (a new array: `active` stays)
                L += dr.select(emission_on, beta * si.emitter(scene, emission_on).eval(si, emission_on), 0.0)
            depth[hit] += 1
            bsdf = si.bsdf(ray)
            flags = bsdf.flags()
            here = hit & mi.has_flag(flags, mi.BSDFFlags.Smooth)

            # ---------- Direct light: emitter sampling + BSDF sampling, MIS ----------
            if dr.hint(use_nee, mode="scalar"):
                active_em = here & (depth < max_depth)
                if dr.hint(with_direct, mode="scalar"):
                    L, active_b = self.direct_light(scene, sampler, bsdf_ctx, si, bsdf, beta, L, active_em,
                                                    floor)
                    n_shadow += dr.select(active_em, 1, 0)
                    n_ext += dr.select(active_b, 1, 0)
                else:     # the same sampler dimensions, so every batch follows the same paths
                    sampler.next_2d(), sampler.next_1d(), sampler.next_2d()

            # ------------------------- Density estimate -------------------------
            if dr.hint(grid is not None and grid.photon_count > 0, mode="scalar"):
                max_photon_depth = dr.select(depth < max_depth, max_depth - depth, 0)
                L += beta * density_estimate(grid, si, bsdf, max_photon_depth, here)

            # --------------------- Delta lobes: continue ---------------------
            through = hit & mi.has_flag(flags, mi.BSDFFlags.Delta) & (depth < max_depth)
            bs, w_delta = bsdf.sample(delta_ctx, si, sampler.next_1d(), sampler.next_2d(), through)
            valid_ray |= hit & (here | ~mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null))
            ray = spawn.spawn_ray(si, si.to_world(bs.wo), floor)
            beta *= w_delta
            eta *= bs.eta

            # --------------------- Stopping criterion ----------------------
            beta_max = dr.max(mi.unpolarized_spectrum(beta))
            active_next = through & (beta_max > 0) & dr.isfinite(beta_max)
            beta, survives = russian_roulette(beta, sampler.next_1d(), active_next & (depth >= rr_depth),
                                              eta=eta)
            active_next &= survives
            pi = scene.ray_intersect_preliminary(ray, coherent=False, active=active_next)
            n_ext += dr.select(active_next, 1, 0)
            active = active_next

        self.counters.add("extension", n_ext)
        self.counters.add("shadow", n_shadow)
        return L, valid_ray, []             # (alpha only: L is kept, as in path.py)

    def direct_light(self, scene, sampler, ctx, si, bsdf, beta, L, active, floor):
        """(L, lanes that traced a BSDF-sampled ray): next-event estimation at ``si`` and the
        emitter its BSDF sample finds (one segment: the photons hold the rest), power heuristic.
        A BSDF sample of a delta lobe is dropped: the camera path follows those lobes itself."""
        L, bs, bsdf_weight = direct.emitter_sampling(scene, sampler, ctx, si, bsdf, beta, L,
                                                     sample_weight, 1, active, active,
                                                     offset_floor=floor)
        b_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        active_b = active & ~b_delta & (dr.max(mi.unpolarized_spectrum(bsdf_weight)) > 0)
        si_b = scene.ray_intersect(spawn.spawn_ray(si, si.to_world(bs.wo), floor), ray_flags=mi.RayFlags.All,
                                   coherent=False, active=active_b)
        ds_b = mi.DirectionSample3f(scene, si=si_b, ref=si)
        w_b = hit_weight(direct.hit_densities(scene, si, ds_b, bs.pdf, b_delta, 1, active_b))
        L += dr.select(active_b, beta * bsdf_weight * w_b * ds_b.emitter.eval(si_b, active_b), 0.0)
        return L, active_b

    def aov_names(self):
        return []

    def to_string(self):
        return "LabPhotonCameraPass[]"
