"""lab_photon's camera paths in a scene with participating media (``gather.CameraPass`` calls
``trace_camera`` there; scenes without media keep its surface-only loop).

A camera path starts in the sensor's medium and takes free flights as the light subpaths of
lab_bdpt do (``common.subpath_media.flight``: analytic in homogeneous media, delta tracking in
heterogeneous ones, in one channel per path, ``common.media.sampling_channel``, with the weight
T / p_c, times sigma_s at a collision). It ends at its first vertex with a smooth lobe or in a
medium, where the photons estimate the light it sees:

* a collision in a medium: the volumetric photons within r_v, over the ball
  (``estimates.volume_estimate``, divided by sigma_s there);
* a surface with a smooth lobe: the surface photons within r (``estimates.density_estimate``), and
  through the BSDF's delta lobes the path goes on, as in the surface loop.

A null boundary (a ``null`` BSDF, a mask's clear part) is passed without a vertex (volpath's
counting of ``max_depth``), and the medium is tracked across medium transitions. With ``direct =
nee``, next-event estimation at the gathering vertex (BSDF or phase function) carries the
transmittance to the emitter (``common.media.emitter_sampling``: exact in homogeneous media, ratio
tracking in heterogeneous ones). It is emitter sampling alone (weight 1): the path ends at that
vertex, so no BSDF-sampled ray competes for the same light. Emission seen directly, or through
delta lobes and null boundaries, is counted with the flights' weights.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common.subpath_media import flight
from mitsuba_lab.plugins.integrators.common import media, spawn
from mitsuba_lab.plugins.integrators.common.roulette import russian_roulette

from . import estimates


def _emitter_sampling_alone(d):
    """The weight of an emitter sample when nothing else samples that light: 1."""
    return mi.Float(1.0)


@dr.syntax
def trace_camera(cp, scene: mi.Scene, sampler: mi.Sampler, ray: mi.Ray3f, medium, active):
    """(L, valid_ray, n_ext, n_shadow) of the camera paths of ``cp`` (a ``gather.CameraPass``)
    in a scene with media, starting in the sensor's ``medium``."""
    cfg = cp.settings
    grid, volume = cp.grid, cp.volume_grid
    with_direct = cp.with_direct
    floor = cp.offset_floor
    use_nee = cfg.direct == "nee"
    bsdf_ctx = mi.BSDFContext()
    delta_ctx = mi.BSDFContext(mi.TransportMode.Radiance, estimates.DELTA_MASK)
    phase_ctx = mi.PhaseFunctionContext(sampler)
    max_depth = dr.opaque(mi.UInt32, cfg.depth_limit)
    rr_depth = dr.opaque(mi.UInt32, cp.settings.rr_depth)
    # (batches after a pass's first draw the same numbers and add none of the direct light)
    direct_scale = 1.0 if with_direct else 0.0

    ray = mi.Ray3f(ray)
    lanes = dr.width(ray)
    active = mi.Bool(active) & dr.full(mi.Bool, True, lanes)
    medium = mi.MediumPtr(medium) if medium is not None else dr.zeros(mi.MediumPtr, lanes)
    medium = dr.select(active, medium, medium)
    channel = media.sampling_channel(sampler, active)
    depth = mi.UInt32(0)
    L = mi.Spectrum(0)
    beta = mi.Spectrum(1)
    eta = mi.Float(1)
    valid_ray = mi.Bool(scene.environment() is not None) & active
    n_ext = mi.UInt32(0)
    n_shadow = mi.UInt32(0)
    while dr.hint(active, max_iterations=-1, label="lab_photon camera loop in media"):
        si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False, active=active)
        si = spawn.behind_null_face(scene, ray, si, floor, active)
        in_medium = active & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
        mei, scattered, w_flight, _ = flight(medium, ray, si.t, sampler.next_1d(), sampler, channel, in_medium,
                                             cp.tracking)
        beta[in_medium] *= mi.Spectrum(w_flight)
        arrived = active & ~scattered
        surface = arrived & si.is_valid()

        # ----------------------- Direct emission -----------------------
        L += dr.select(arrived, beta * si.emitter(scene, arrived).eval(si, arrived) * direct_scale, 0.0)

        at = depth + 1
        bsdf = si.bsdf(ray)
        flags = bsdf.flags()
        smooth = surface & mi.has_flag(flags, mi.BSDFFlags.Smooth)
        phase = mei.medium.phase_function()
        phase[~scattered] = dr.zeros(mi.PhaseFunctionPtr)
        max_photon_depth = dr.select(at < max_depth, max_depth - at, 0)

        # ---------- Direct light: emitter sampling through the media ----------
        if dr.hint(use_nee, mode="scalar"):
            active_em = (smooth | scattered) & (at < max_depth)
            it = dr.zeros(mi.Interaction3f)
            it[surface] = si
            it[scattered] = mei
            L_em, traced = media.emitter_sampling(scene, sampler, bsdf_ctx, phase_ctx, it, si, bsdf, mei, phase,
                                                  scattered, medium, channel, beta, mi.Spectrum(0),
                                                  _emitter_sampling_alone, 1, active_em, floor)
            L += L_em * direct_scale
            n_shadow += traced

        # ------------------------- Density estimates -------------------------
        if dr.hint(grid is not None and grid.photon_count > 0, mode="scalar"):
            L += beta * estimates.density_estimate(grid, si, bsdf, max_photon_depth, smooth)
        if dr.hint(volume is not None and volume.photon_count > 0, mode="scalar"):
            L += beta * estimates.volume_estimate(volume, mei, phase, max_photon_depth, scattered)

        # --------------------- Delta lobes and null boundaries: continue ---------------------
        through = surface & mi.has_flag(flags, mi.BSDFFlags.Delta)
        bs, w_delta = bsdf.sample(delta_ctx, si, sampler.next_1d(), sampler.next_2d(), through)
        passing = through & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        vertex = scattered | (surface & ~passing)
        depth[vertex] = at
        through &= passing | (depth < max_depth)
        valid_ray |= vertex
        ray = spawn.spawn_ray(si, si.to_world(bs.wo), floor)
        beta *= w_delta
        eta *= bs.eta
        medium[through & si.is_medium_transition()] = si.target_medium(ray.d)

        # --------------------- Stopping criterion ----------------------
        beta_max = dr.max(mi.unpolarized_spectrum(beta))
        active_next = through & (beta_max > 0) & dr.isfinite(beta_max)
        beta, survives = russian_roulette(beta, sampler.next_1d(), active_next & ~passing & (depth >= rr_depth),
                                          eta=eta)
        active_next &= survives
        n_ext += dr.select(active_next, 1, 0)
        active = active_next
    return L, valid_ray, n_ext, n_shadow
