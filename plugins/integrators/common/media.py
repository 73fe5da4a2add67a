"""Participating media for the path loop: where a ray scatters, and how much light gets through.

The volume rendering equation adds to the surface integral an integral along each ray segment
inside a medium: radiance at distance t is attenuated by the transmittance

    T(0, t) = exp(-int_0^t sigma_t(s) ds)            (Beer-Lambert)

and in-scattered with sigma_s(t) times the phase function. Two estimators carry it:

* ``free_flight``: the distance to the next real collision, sampled in proportion to
  sigma_t(t) T(0, t) by delta tracking (Woodcock et al. 1965): tentative collisions at the
  rate of a majorant sigma_bar >= sigma_t, each real with probability sigma_t / sigma_bar,
  otherwise null and passed. In a homogeneous medium (sigma_bar = sigma_t) the first tentative
  collision is real: the analytic inversion t = -ln(1 - u) / sigma_t. Mitsuba's media draw the
  tentative collisions (``Medium.sample_interaction``, against one majorant per medium).
* ``transmittance``: T along a shadow ray, through media and the index-matched (``null``)
  boundaries between them. Exact (Beer-Lambert) in homogeneous media; ratio tracking in
  heterogeneous ones (Novak et al. 2014): at each tentative collision T is multiplied by
  sigma_n / sigma_bar = 1 - sigma_t / sigma_bar instead of being stopped, an unbiased estimate
  of lower variance than delta tracking's 0 or 1.

With chromatic coefficients, distances are sampled with the coefficients of one channel (the
path's ``sampling_channel``) and every channel is weighted by its own transmittance over that
channel's density, as Mitsuba's ``volpath`` does; each real collision then carries the albedo
sigma_s / sigma_t. The weights below are the ones in the comments of each function.

Tracking in a heterogeneous medium also returns its *null chain*: the product, over the null
collisions it passed, of the probability P_null that delta tracking gives each of them. It is
what equi-angular sampling's MIS weights need there (``common.equiangular``).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import majorants, spawn


#: The medium parameters (``params._media``) as the path tracers hold them: (name, attribute,
#: value where the plugin does not declare it: lab_naive's free flights, as Mitsuba's volpath).
SETTINGS = (("medium_sampling", "medium_sampling", "distance"), ("equiangular_samples", "equiangular_samples", 1),
            ("transmittance", "tracking_kind", "ratio"),
            ("majorants", "majorants", "global"), ("majorant_resolution", "majorant_resolution", 16),
            ("spectral_mis", "spectral_mis", False))


def sampling_channel(sampler: mi.Sampler, active) -> mi.UInt32:
    """The channel whose coefficients drive distance sampling along a path: one of the three
    uniformly in RGB variants (one sample, so the path's expectation sums the three), the first
    (hero) wavelength in spectral variants, the only one in mono."""
    if mi.is_rgb:
        n = dr.size_v(mi.Spectrum)
        return mi.UInt32(dr.minimum(n * sampler.next_1d(active), n - 1))
    return mi.UInt32(0)


def channel_value(spectrum, channel):
    """The value of ``spectrum`` in ``channel`` (its only value in mono variants)."""
    if mi.is_rgb:
        return dr.select(channel == 0, spectrum[0], dr.select(channel == 1, spectrum[1], spectrum[2]))
    return spectrum[0]


def _clamped(sigma_n):
    """sigma_n = sigma_bar - sigma_t at least 0: trilinear interpolation can pass Mitsuba's
    majorant (scale x the grid's maximum) by float rounding, which gave a ratio-tracking weight
    of -5e-11 in a render (as pbrt-v4, which clamps it too)."""
    return dr.maximum(sigma_n, 0.0)


def _tracked_weight(medium, m, ray_maxt, channel, active):
    """(T / p_c, p / p_c) for one step of tracking from the ray's origin: T the transmittance
    over the step and p the density of the step's outcome per channel (sigma_bar T at a
    tentative collision, T past ``ray_maxt``), p_c the sampling channel's. Per channel, exact
    against the majorant."""
    end = dr.zeros(mi.SurfaceInteraction3f)
    end.t = ray_maxt
    tr, pdf = medium.transmittance_eval_pdf(m, end, active)
    pdf_c = channel_value(pdf, channel)
    ok = active & (pdf_c > 0)
    return dr.select(ok, tr / pdf_c, 0.0), dr.select(ok, pdf / pdf_c, 1.0)


def free_flight(medium: mi.MediumPtr, ray: mi.Ray3f, t_max, sampler: mi.Sampler, channel, active, grid=None,
                ratios=None):
    """``global_free_flight``, or where ``grid`` (a ``majorants.MajorantGrid``) is given, in the
    lanes whose medium is the grid's, delta tracking against the grid's local bounds
    (``majorants.free_flight``; its weights are ``global_free_flight``'s with a majorant that is
    one number for every channel, so every channel has the same density). Returns (mei,
    scattered, weight, ratios, nulls), ``nulls`` the flight's null chain (1 in homogeneous media).

    ``ratios`` (spectral MIS, after Miller et al. 2019 and ``volpathmis``): None, or per channel
    r_c = P_c / P_s normalised to mean 1, P_c the density with which channel c's coefficients
    would have sampled the path's distances so far and P_s the sampling channel's. The path's
    weight is then f / mean_c(P_c) (one-sample MIS over a uniformly chosen channel, balance
    heuristic) instead of f / P_s: with q_c = p_c / p_s this flight's density ratios, the weight
    is divided by mean(r q) and r becomes r q / mean(r q)."""
    if grid is None:
        mei, scattered, weight, q, nulls = global_free_flight(medium, ray, t_max, sampler, channel, active)
    else:
        on_grid = active & (medium == grid.pointer)
        mei, scattered, weight, q, nulls = global_free_flight(medium, ray, t_max, sampler, channel,
                                                              active & ~on_grid)
        mei_g, scattered_g, weight_g, nulls_g = majorants.free_flight(grid, ray, t_max, sampler, on_grid)
        mei[on_grid] = mei_g
        scattered, weight = scattered | scattered_g, dr.select(on_grid, weight_g, weight)
        nulls = dr.select(on_grid, nulls_g, nulls)
    if ratios is not None:
        rq = ratios * q
        mean = dr.mean(rq)
        ok = active & (mean > 0)
        weight = dr.select(ok, weight / mean, dr.select(active, 0.0, weight))
        ratios = dr.select(ok, rq / mean, ratios)
    return mei, scattered, weight, ratios, nulls


def within_grid(medium, ray: mi.Ray3f, t_max, active):
    """``t_max``, or for a ray that meets no surface (``t_max`` infinite) in a heterogeneous
    medium, the distance to where it leaves the medium's grid (0 where it misses the grid): such a
    medium is empty outside its grid, so the light of an emitter at infinity reaches through it
    with the grid's transmittance (tracking to an infinite distance would give T / p = 0 / 0)."""
    escaping = active & ~dr.isfinite(t_max) & ~medium.is_homogeneous()
    hit, _, box_maxt = medium.intersect_aabb(ray)
    exit = dr.select(hit & dr.isfinite(box_maxt), dr.maximum(box_maxt, 0.0), 0.0)
    return dr.select(escaping, exit, t_max)


@dr.syntax
def global_free_flight(medium: mi.MediumPtr, ray: mi.Ray3f, t_max, sampler: mi.Sampler, channel, active):
    """Delta tracking along ``ray`` inside ``medium`` up to distance ``t_max`` (the next surface).

    Returns (mei, scattered, weight, q, nulls): ``scattered`` where a real collision was found before
    ``t_max``, ``mei`` that collision (its point, coefficients and medium), and ``weight`` the
    factor of the path's throughput: per channel, T / p_c at every tentative collision and at
    the escape, sigma_n / P_null at a null collision and sigma_s / P_real at the real one, with
    P_real = mean(sigma_t / sigma_bar) = 1 - P_null. With equal channels this is 1 through the
    medium and the albedo sigma_s / sigma_t at a scattering event. ``q``: per channel, the
    flight's density over the sampling channel's; ``nulls``: the product of P_null over the null
    collisions.
    """
    ray = mi.Ray3f(ray)
    ray.maxt = dr.select(active, within_grid(medium, ray, t_max, active), 0.0)
    weight = mi.UnpolarizedSpectrum(1.0)
    q = mi.UnpolarizedSpectrum(1.0)           # per channel, the steps' densities over the sampling channel's
    nulls = mi.Float(1.0)
    mei = dr.zeros(mi.MediumInteraction3f)
    scattered = mi.Bool(False)
    tracking = mi.Bool(active)
    while tracking:
        m = medium.sample_interaction(ray, sampler.next_1d(tracking), channel, tracking)
        m.sigma_n = _clamped(m.sigma_n)
        collided = tracking & m.is_valid()
        w_step, q_step = _tracked_weight(medium, m, ray.maxt, channel, tracking)
        weight[tracking] *= w_step
        q[tracking] *= q_step
        p_null = dr.mean(dr.select(m.combined_extinction > 0, m.sigma_n / m.combined_extinction, 0.0))
        null = collided & (sampler.next_1d(collided) < p_null)
        real = collided & ~null
        weight[null] *= m.sigma_n / p_null
        nulls[null] *= p_null
        weight[real] *= m.sigma_s / (1.0 - p_null)
        mei[real] = m
        scattered |= real
        # a null collision: go on from it, the surface as far away as before
        ray.o[null] = m.p
        ray.maxt[null] = ray.maxt - m.t
        tracking = null & (dr.max(mi.unpolarized_spectrum(weight)) > 0)
    return mei, scattered, weight, q, nulls


def segment_transmittance(medium: mi.MediumPtr, ray: mi.Ray3f, sampler: mi.Sampler, channel, active,
                          tracking_kind: str = "ratio", grid=None):
    """``global_segment_transmittance``, or in the lanes whose medium is ``grid``'s, ratio or
    delta tracking against the grid's local bounds (``majorants.track``). Returns (T, nulls)."""
    if grid is None:
        return global_segment_transmittance(medium, ray, sampler, channel, active, tracking_kind)
    on_grid = active & (medium == grid.pointer)
    T, nulls = global_segment_transmittance(medium, ray, sampler, channel, active & ~on_grid, tracking_kind)
    _, _, T_grid, nulls_grid = majorants.track(grid, ray, ray.maxt, sampler, on_grid, tracking_kind)
    return dr.select(on_grid, T_grid, T), dr.select(on_grid, nulls_grid, nulls)


@dr.syntax
def global_segment_transmittance(medium: mi.MediumPtr, ray: mi.Ray3f, sampler: mi.Sampler, channel, active,
                                 tracking_kind: str = "ratio"):
    """T over ``ray`` (from its origin to ``ray.maxt``) inside ``medium``: Beer-Lambert in a
    homogeneous medium. In a heterogeneous one, ``ratio`` tracking: per channel the product of
    T / p_c over the steps and of sigma_n at each tentative collision (= 1 - sigma_t / sigma_bar
    with equal channels); ``delta`` tracking: each tentative collision is null with probability
    P_null (as in ``free_flight``), weighted sigma_n / P_null, and real otherwise, where T becomes
    0 (with equal channels the estimate is 0 or 1). Returns (T, nulls): ``nulls`` the null chain
    of ratio tracking, which passes every tentative collision (1 with delta tracking, which
    passes each with probability P_null, and in homogeneous media)."""
    ray = mi.Ray3f(ray)
    T = mi.UnpolarizedSpectrum(1.0)
    nulls = mi.Float(1.0)
    exact = active & medium.is_homogeneous()
    tracking = mi.Bool(active)
    while tracking:
        m = medium.sample_interaction(ray, sampler.next_1d(tracking), channel, tracking)
        m.sigma_n = _clamped(m.sigma_n)
        m.t[exact] = dr.inf                       # homogeneous: the whole segment at once
        end = dr.zeros(mi.SurfaceInteraction3f)
        end.t = ray.maxt
        tr, _ = medium.transmittance_eval_pdf(m, end, exact)
        T[exact] *= tr
        ratio = tracking & ~exact
        collided = ratio & m.is_valid()
        T[ratio] *= _tracked_weight(medium, m, ray.maxt, channel, ratio)[0]
        p_null = dr.mean(dr.select(m.combined_extinction > 0, m.sigma_n / m.combined_extinction, 0.0))
        if dr.hint(tracking_kind == "delta", mode="scalar"):
            null = collided & (sampler.next_1d(collided) < p_null)
            T[collided & ~null] = 0.0
            T[null] *= m.sigma_n / p_null
            collided = null
        else:
            T[collided] *= m.sigma_n
            nulls[collided] *= p_null
        ray.o[collided] = m.p
        ray.maxt[collided] = ray.maxt - m.t
        tracking = collided & (dr.max(mi.unpolarized_spectrum(T)) > 0)
    return T, nulls


@dr.syntax
def transmittance(scene: mi.Scene, medium: mi.MediumPtr, it: mi.Interaction3f, target: mi.Point3f,
                  sampler: mi.Sampler, channel, floor: float, active, tracking_kind: str = "ratio", grid=None,
                  stand_in=None, coplanar: bool = False, unbounded=None):
    """T from the vertex ``it`` (inside ``medium``, which a surface vertex has already switched
    to the side facing ``target``) to the point ``target``: through media, and through the
    surfaces between whose BSDFs let light pass unscattered (``null`` boundaries, a mask's clear
    part: ``eval_null_transmission``); every other surface blocks it. Rays start and stop at
    the lab's offsets (``spawn``). ``tracking_kind``, ``grid``: ``segment_transmittance``'s.

    ``stand_in``: None, or a deterministic value for each piece inside a heterogeneous medium,
    ``stand_in(medium, start, end, wavelengths, channel, active)``; then returns (T, T_det): T_det
    the product in ``channel`` of the exact factors (homogeneous pieces, null boundaries) and of
    the stand-ins (lab_bdpt's MIS weights need a transmittance that no random draw changes).
    ``coplanar``: a surface on a passed null face's plane blocks too (``spawn.behind_null_face``).
    ``unbounded``: None, or the lanes whose ``target`` stands for an emitter at infinity (Mitsuba
    puts it 2 bounding-sphere radii away): their last piece, past the last surface, runs on for
    ever, so in a homogeneous medium T is exp(-sigma_t inf), 0 wherever sigma_t > 0 (a
    heterogeneous medium is empty outside its grid: its pieces keep their tracked T)."""
    ray = spawn.spawn_ray_to(it, target, floor)
    medium = mi.MediumPtr(medium)
    T = mi.UnpolarizedSpectrum(1.0)
    T_det = mi.Float(1.0)
    going = mi.Bool(active)
    while going:
        si = scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=going)
        if dr.hint(coplanar, mode="scalar"):
            si = spawn.behind_null_face(scene, ray, si, floor, going)
        crossing = going & si.is_valid()
        segment = mi.Ray3f(ray)
        segment.maxt = dr.select(crossing, si.t, ray.maxt)
        inside = going & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
        T_seg = segment_transmittance(medium, segment, sampler, channel, inside, tracking_kind, grid)[0]
        T[inside] *= T_seg
        if dr.hint(unbounded is not None, mode="scalar"):
            forever = inside & ~crossing & unbounded & medium.is_homogeneous()
            T_inf = unbounded_transmittance(medium, segment, forever)
            T[forever] *= T_inf
        bsdf = si.bsdf(ray)
        # (its unpolarized part: exact for null and mask boundaries, which scale light)
        T_null = mi.unpolarized_spectrum(bsdf.eval_null_transmission(si, crossing))
        T[crossing] *= T_null
        if dr.hint(stand_in is not None, mode="scalar"):
            # (the last piece ends at the target itself, not where the shortened shadow ray stops)
            tracked = inside & ~medium.is_homogeneous()
            end = dr.select(crossing, segment(segment.maxt), target)
            T_det[inside] *= dr.select(tracked, stand_in(medium, segment.o, end, ray.wavelengths, channel, tracked),
                                       channel_value(T_seg, channel))
            T_det[crossing] *= channel_value(T_null, channel)
            if dr.hint(unbounded is not None, mode="scalar"):
                T_det[forever] *= channel_value(T_inf, channel)
        medium[crossing & si.is_medium_transition()] = si.target_medium(ray.d)
        # on past the surface, towards the same target
        ray[crossing] = spawn.spawn_ray_to(si, target, floor)
        going = crossing & (dr.max(mi.unpolarized_spectrum(T)) > 0)
    return T if stand_in is None else (T, T_det)


def unbounded_transmittance(medium, ray: mi.Ray3f, active) -> mi.UnpolarizedSpectrum:
    """exp(-sigma_t inf) per channel in the homogeneous ``medium`` from ``ray``'s origin: 0 where
    sigma_t > 0, 1 where it is 0 (1 in inactive lanes)."""
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.p, mei.wavelengths = ray.o, ray.wavelengths
    _, _, sigma_t = medium.get_scattering_coefficients(mei, active)
    # (a Spectrum again: in spectral variants the select gives a plain 4-vector)
    return mi.UnpolarizedSpectrum(dr.select(active & (mi.UnpolarizedSpectrum(sigma_t) > 0), 0.0,
                                            mi.UnpolarizedSpectrum(1.0)))


def emitter_sampling(scene, sampler, ctx, phase_ctx, it, si, bsdf, mei, phase, scattered, medium, channel,
                     beta, L, sample_weight, n_L: int, active, floor: float, tracking_kind: str = "ratio",
                     equiangular=None, nee: bool = True, grid=None):
    """Next-event estimation at a vertex of a path in a scene with media: the surface ``si``
    (its ``bsdf``) or, where ``scattered``, the medium point ``mei`` (its ``phase`` function);
    ``it`` is the vertex as an ``Interaction3f``, ``medium`` the medium the path arrived in.

    Adds to ``L`` n_L emitter samples, each beta w f L_e G T / (n_L p_L): an emitter point
    sampled without a visibility test, T the transmittance to it (``transmittance``: media and
    null boundaries pass light, other surfaces block it), f and p_B the BSDF's (with its cosine)
    or the phase function's, and w = ``sample_weight(Densities)`` (direct.py's convention).
    ``equiangular``: None, or the ``Equiangular`` state of the path's vertex, whose medium
    vertices then weigh their samples against equi-angular sampling too. Returns (L, the shadow
    rays traced per lane: a sample of MIS weight 0 traces none). An emitter at infinity
    is infinitely far (``transmittance``'s ``unbounded``: none of its light crosses unbounded fog),
    not at Mitsuba's stand-in distance, 2 bounding-sphere radii, where ``volpath`` leaves it: an
    invisible speck far away that grows the bounding sphere must not change the image."""
    from mitsuba_lab.plugins.integrators.common.direct import emitter_sample_contribution
    from mitsuba_lab.plugins.integrators.estimator import Densities

    traced = mi.UInt32(0)
    for _ in range(n_L):
        ds, em_weight = scene.sample_emitter_direction(it, sampler.next_2d(), False, active)
        sampled = active & (ds.pdf != 0)
        # a surface at a medium boundary sends the shadow ray into the medium on its side
        start = dr.select(~scattered & si.is_medium_transition(), si.target_medium(ds.d), medium)
        infinite = mi.has_flag(ds.emitter.flags(), mi.EmitterFlags.Infinite) & sampled
        f_bsdf, pdf_bsdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), sampled & ~scattered)
        f_phase, pdf_phase = phase.eval_pdf(phase_ctx, mei, ds.d, sampled & scattered)
        f = dr.select(scattered, f_phase, f_bsdf)
        d = Densities(bsdf=dr.select(scattered, pdf_phase, pdf_bsdf), emitter=n_L * ds.pdf, delta=ds.delta)
        if equiangular is not None:
            d = equiangular.densities(scene, d, it, ds, sampled, nee)
        w = sample_weight(d)
        # the weight needs no visibility: a sample of weight 0 (``max`` heuristic) adds 0 whatever
        # its T, so its shadow ray is not traced
        shadow = sampled & (w > 0)
        T = transmittance(scene, start, it, ds.p, sampler, channel, floor, shadow, tracking_kind, grid,
                          unbounded=infinite)
        traced += dr.select(shadow, 1, 0)
        L = L + emitter_sample_contribution(beta, ds, em_weight * mi.Spectrum(T), f, w / n_L, sampled)
    return L, traced

