"""Camera side: the kernel density estimate of reflected radiance at a camera vertex.

At a camera vertex x with outgoing direction wo (towards the camera), the photons
p within distance r estimate the reflected radiance (Jensen 2001, eq. 7.6, with a
smooth kernel instead of the constant disk):

    L_r(x, wo) ~= sum_p f(x, wo, wi_p) Phi_p K(|x - x_p| / r) / r^2

with the 2D Epanechnikov kernel K(t) = (2 / pi) (1 - t^2) for t < 1, 0 otherwise,
normalised over the plane: int_{R^2} K(|u|) du = 1. f is the BSDF without the
cosine: Mitsuba's ``BSDF.eval(ctx, si, wi_p)`` returns f |cos theta_p| (the cosine of
its direction argument, here the photon's), so it is divided by |cos theta_p|: the
photon's flux per area already is irradiance, there is no cosine left to apply.

A photon counts only if

* it lies in the 3 x 3 x 3 cells around x's cell (cell size = r) and its own cell is
  the one being visited (a hash collision never counts a photon twice);
* |x - x_p| < r;
* n_x . n_p > ``NORMAL_COS`` (a photon on a surface facing another way, e.g. on the
  other wall at a corner or the far side of a thin slab, is rejected);
* its path length plus the camera's stays within ``max_depth``.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators import direct
from mitsuba_lab.plugins.integrators.counters import RayCounters
from mitsuba_lab.plugins.integrators.mis import MIS
from mitsuba_lab.plugins.integrators.roulette import russian_roulette

from .grid import NEIGHBOURS, PhotonGrid, cell_of, hash_cell

#: Photons whose geometric normal is more than ~37 degrees off x's are rejected.
NORMAL_COS = 0.8
KERNEL_NORM = 2.0 / dr.pi
#: Direct light in ``direct = nee`` mode: one emitter sample and one BSDF sample, power heuristic.
DIRECT_MIS = MIS({"heuristic": "power", "beta": 2.0, "emitter_samples": 1})


@dr.syntax
def density_estimate(grid: PhotonGrid, si: mi.SurfaceInteraction3f, bsdf: mi.BSDF, max_photon_depth,
                     active):
    """sum_p f Phi_p K / r^2 for each lane's interaction ``si``; ``max_photon_depth`` per lane."""
    ctx = mi.BSDFContext()
    rec = grid.records
    radius2 = grid.radius2
    inv_r2 = dr.rcp(radius2)
    inv_cell = grid.inv_cell_size
    home = cell_of(si.p, inv_cell)
    result = mi.Spectrum(0)
    k = mi.UInt32(0)
    active = mi.Bool(active)
    while dr.hint(active & (k < NEIGHBOURS), label="lab_photon gather cells"):
        cell = home + mi.Vector3i(mi.Int32(k % 3) - 1, mi.Int32((k // 3) % 3) - 1, mi.Int32(k // 9) - 1)
        bucket = hash_cell(cell, grid.mask)
        j = dr.gather(mi.UInt32, grid.start, bucket, active)
        end = j + dr.gather(mi.UInt32, grid.count, bucket, active)
        while dr.hint(j < end, label="lab_photon gather photons"):
            p = dr.gather(mi.Point3f, rec.p, j)
            d = p - si.p
            dist2 = dr.squared_norm(d)
            n_p = dr.gather(mi.Normal3f, rec.n, j)
            ok = (dist2 < radius2) & (dr.dot(n_p, si.n) > NORMAL_COS)
            ok &= dr.gather(mi.UInt32, rec.depth, j, ok) <= max_photon_depth
            ok &= dr.all(cell_of(p, inv_cell) == cell)
            wi_p = si.to_local(dr.gather(mi.Vector3f, rec.wi, j, ok))
            f_cos = bsdf.eval(ctx, si, wi_p, ok)
            cos_p = dr.abs(mi.Frame3f.cos_theta(wi_p))
            kernel = KERNEL_NORM * (1.0 - dist2 * inv_r2)
            power = dr.gather(mi.Spectrum, rec.power, j, ok)
            result += dr.select(ok & (cos_p > 0), f_cos * power * (kernel / dr.maximum(cos_p, 1e-30)), 0.0)
            j += 1
        k += 1
    return result * inv_r2


class CameraPass(mi.SamplingIntegrator):
    """One camera pass of ``lab_photon`` against the current photon map (not a plugin).

    Its ``render`` is Mitsuba's own ``SamplingIntegrator.render`` (film, filter,
    sampler, spp); its ``sample`` follows camera paths through delta vertices to
    the first vertex with a smooth BSDF and estimates the radiance there.
    ``grid`` (a PhotonGrid or None), ``with_direct`` (count emission and NEE: only
    in the first batch of a pass) and ``settings`` (PhotonSettings) are set by the driver.
    """

    def __init__(self, settings):
        super().__init__(mi.Properties())
        self.settings = settings
        self.grid = None
        self.with_direct = True
        self.counters = RayCounters()                  # camera-side extension and shadow rays

    @dr.syntax
    def sample(self, scene: mi.Scene, sampler: mi.Sampler, ray: mi.RayDifferential3f,
               medium: mi.Medium = None, active: mi.Bool = True):
        cfg = self.settings
        grid = self.grid
        with_direct = self.with_direct
        use_nee = cfg.direct == "nee"
        bsdf_ctx = mi.BSDFContext()
        max_depth = dr.opaque(mi.UInt32, cfg.depth_limit)
        rr_depth = dr.opaque(mi.UInt32, cfg.rr_depth)

        # --------------------- Configure loop state ----------------------
        ray = mi.Ray3f(ray)
        active = mi.Bool(active)
        depth = mi.UInt32(0)
        L = mi.Spectrum(0)
        beta = mi.Spectrum(1)
        eta = mi.Float(1)
        gather = mi.Bool(False)
        valid_ray = mi.Bool(scene.environment() is not None) & active
        n_ext = mi.UInt32(0)

        # ------- Camera path through delta vertices to a smooth vertex --------
        while dr.hint(active, max_iterations=-1, label="lab_photon camera loop"):
            si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=depth == 0, active=active)
            valid_ray |= active & si.is_valid()
            depth[active & si.is_valid()] += 1

            # ----------------------- Direct emission -----------------------
            if dr.hint(with_direct, mode="scalar"):
                L += dr.select(active, beta * si.emitter(scene, active).eval(si, active), 0.0)

            bsdf = si.bsdf(ray)
            smooth = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            gather |= active & si.is_valid() & smooth
            active_next = active & si.is_valid() & ~smooth & (depth < max_depth)

            # ------------------------ BSDF sampling ------------------------
            bs, bsdf_weight = bsdf.sample(bsdf_ctx, si, sampler.next_1d(), sampler.next_2d(), active_next)
            ray[active_next] = si.spawn_ray(si.to_world(bs.wo))
            beta[active_next] *= bsdf_weight
            eta[active_next] *= bs.eta

            # --------------------- Stopping criterion ----------------------
            beta_max = dr.max(mi.unpolarized_spectrum(beta))
            active_next &= (beta_max > 0) & dr.isfinite(beta_max)
            beta, survives = russian_roulette(beta, sampler.next_1d(), active_next & (depth >= rr_depth),
                                              eta=eta)
            active_next &= survives
            n_ext += dr.select(active_next, 1, 0)
            active = active_next

        # The vertex where the camera path stopped on a smooth BSDF (one ray again, cheaper
        # than carrying the interaction through the loop).
        si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False, active=gather)
        bsdf = si.bsdf(ray)
        n_shadow = mi.UInt32(0)

        # ------------- Direct light: emitter sampling + BSDF sampling, MIS -------------
        if dr.hint(use_nee & with_direct, mode="scalar"):
            active_em = gather & (depth < max_depth)
            L, bs, bsdf_weight = direct.emitter_sampling(scene, sampler, bsdf_ctx, si, bsdf, beta, L,
                                                         DIRECT_MIS.sample_weight, 1, active_em, active_em)
            n_shadow += dr.select(active_em, 1, 0)

            # The emitter the BSDF sample finds, if any (one segment: the photons hold the rest)
            active_b = active_em & (dr.max(mi.unpolarized_spectrum(bsdf_weight)) > 0)
            ray_b = si.spawn_ray(si.to_world(bs.wo))
            si_b = scene.ray_intersect(ray_b, ray_flags=mi.RayFlags.All, coherent=False, active=active_b)
            n_ext += dr.select(active_b, 1, 0)
            ds_b = mi.DirectionSample3f(scene, si=si_b, ref=si)
            b_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            w_b = DIRECT_MIS.hit_weight(direct.hit_densities(scene, si, ds_b, bs.pdf, b_delta, 1, active_b))
            L += dr.select(active_b, beta * bsdf_weight * w_b * ds_b.emitter.eval(si_b, active_b), 0.0)

        # ------------------------- Density estimate -------------------------
        if dr.hint(grid is not None and grid.photon_count > 0, mode="scalar"):
            max_photon_depth = dr.select(depth < max_depth, max_depth - depth, 0)
            L += beta * density_estimate(grid, si, bsdf, max_photon_depth, gather)

        self.counters.add("extension", n_ext)
        self.counters.add("shadow", n_shadow)
        return dr.select(valid_ray, L, 0.0), valid_ray, []

    def aov_names(self):
        return []

    def to_string(self):
        return "LabPhotonCameraPass[]"
