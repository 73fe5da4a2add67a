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
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import majorants, spawn


#: The medium parameters (``params._media``) as the path tracers hold them: (name, attribute,
#: value where the plugin does not declare it: lab_naive's free flights, as Mitsuba's volpath).
SETTINGS = (("medium_sampling", "medium_sampling", "distance"), ("transmittance", "tracking_kind", "ratio"),
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
    scattered, weight, ratios).

    ``ratios`` (spectral MIS, after Miller et al. 2019 and ``volpathmis``): None, or per channel
    r_c = P_c / P_s normalised to mean 1, P_c the density with which channel c's coefficients
    would have sampled the path's distances so far and P_s the sampling channel's. The path's
    weight is then f / mean_c(P_c) (one-sample MIS over a uniformly chosen channel, balance
    heuristic) instead of f / P_s: with q_c = p_c / p_s this flight's density ratios, the weight
    is divided by mean(r q) and r becomes r q / mean(r q)."""
    if grid is None:
        mei, scattered, weight, q = global_free_flight(medium, ray, t_max, sampler, channel, active)
    else:
        on_grid = active & (medium == grid.pointer)
        mei, scattered, weight, q = global_free_flight(medium, ray, t_max, sampler, channel, active & ~on_grid)
        mei_g, scattered_g, weight_g = majorants.free_flight(grid, ray, t_max, sampler, on_grid)
        mei[on_grid] = mei_g
        scattered, weight = scattered | scattered_g, dr.select(on_grid, weight_g, weight)
    if ratios is not None:
        rq = ratios * q
        mean = dr.mean(rq)
        ok = active & (mean > 0)
        weight = dr.select(ok, weight / mean, dr.select(active, 0.0, weight))
        ratios = dr.select(ok, rq / mean, ratios)
    return mei, scattered, weight, ratios


@dr.syntax
def global_free_flight(medium: mi.MediumPtr, ray: mi.Ray3f, t_max, sampler: mi.Sampler, channel, active):
    """Delta tracking along ``ray`` inside ``medium`` up to distance ``t_max`` (the next surface).

    Returns (mei, scattered, weight): ``scattered`` where a real collision was found before
    ``t_max``, ``mei`` that collision (its point, coefficients and medium), and ``weight`` the
    factor of the path's throughput: per channel, T / p_c at every tentative collision and at
    the escape, sigma_n / P_null at a null collision and sigma_s / P_real at the real one, with
    P_real = mean(sigma_t / sigma_bar) = 1 - P_null. With equal channels this is 1 through the
    medium and the albedo sigma_s / sigma_t at a scattering event.
    """
    ray = mi.Ray3f(ray)
    ray.maxt = dr.select(active, t_max, 0.0)
    weight = mi.UnpolarizedSpectrum(1.0)
    q = mi.UnpolarizedSpectrum(1.0)           # per channel, the steps' densities over the sampling channel's
    mei = dr.zeros(mi.MediumInteraction3f)
    scattered = mi.Bool(False)
    tracking = mi.Bool(active)
    while tracking:
        m = medium.sample_interaction(ray, sampler.next_1d(tracking), channel, tracking)
        collided = tracking & m.is_valid()
        w_step, q_step = _tracked_weight(medium, m, ray.maxt, channel, tracking)
        weight[tracking] *= w_step
        q[tracking] *= q_step
        p_null = dr.mean(dr.select(m.combined_extinction > 0, m.sigma_n / m.combined_extinction, 0.0))
        null = collided & (sampler.next_1d(collided) < p_null)
        real = collided & ~null
        weight[null] *= m.sigma_n / p_null
        weight[real] *= m.sigma_s / (1.0 - p_null)
        mei[real] = m
        scattered |= real
        # a null collision: go on from it, the surface as far away as before
        ray.o[null] = m.p
        ray.maxt[null] = ray.maxt - m.t
        tracking = null & (dr.max(mi.unpolarized_spectrum(weight)) > 0)
    return mei, scattered, weight, q


def segment_transmittance(medium: mi.MediumPtr, ray: mi.Ray3f, sampler: mi.Sampler, channel, active,
                          tracking_kind: str = "ratio", grid=None):
    """``global_segment_transmittance``, or in the lanes whose medium is ``grid``'s, ratio or
    delta tracking against the grid's local bounds (``majorants.track``)."""
    if grid is None:
        return global_segment_transmittance(medium, ray, sampler, channel, active, tracking_kind)
    on_grid = active & (medium == grid.pointer)
    T = global_segment_transmittance(medium, ray, sampler, channel, active & ~on_grid, tracking_kind)
    _, _, T_grid = majorants.track(grid, ray, ray.maxt, sampler, on_grid, tracking_kind)
    return dr.select(on_grid, T_grid, T)


@dr.syntax
def global_segment_transmittance(medium: mi.MediumPtr, ray: mi.Ray3f, sampler: mi.Sampler, channel, active,
                                 tracking_kind: str = "ratio"):
    """T over ``ray`` (from its origin to ``ray.maxt``) inside ``medium``: Beer-Lambert in a
    homogeneous medium. In a heterogeneous one, ``ratio`` tracking: per channel the product of
    T / p_c over the steps and of sigma_n at each tentative collision (= 1 - sigma_t / sigma_bar
    with equal channels); ``delta`` tracking: each tentative collision is null with probability
    P_null (as in ``free_flight``), weighted sigma_n / P_null, and real otherwise, where T becomes
    0 (with equal channels the estimate is 0 or 1)."""
    ray = mi.Ray3f(ray)
    T = mi.UnpolarizedSpectrum(1.0)
    exact = active & medium.is_homogeneous()
    tracking = mi.Bool(active)
    while tracking:
        m = medium.sample_interaction(ray, sampler.next_1d(tracking), channel, tracking)
        m.t[exact] = dr.inf                       # homogeneous: the whole segment at once
        end = dr.zeros(mi.SurfaceInteraction3f)
        end.t = ray.maxt
        tr, _ = medium.transmittance_eval_pdf(m, end, exact)
        T[exact] *= tr
        ratio = tracking & ~exact
        collided = ratio & m.is_valid()
        T[ratio] *= _tracked_weight(medium, m, ray.maxt, channel, ratio)[0]
        if dr.hint(tracking_kind == "delta", mode="scalar"):
            p_null = dr.mean(dr.select(m.combined_extinction > 0, m.sigma_n / m.combined_extinction, 0.0))
            null = collided & (sampler.next_1d(collided) < p_null)
            T[collided & ~null] = 0.0
            T[null] *= m.sigma_n / p_null
            collided = null
        else:
            T[collided] *= m.sigma_n
        ray.o[collided] = m.p
        ray.maxt[collided] = ray.maxt - m.t
        tracking = collided & (dr.max(mi.unpolarized_spectrum(T)) > 0)
    return T


@dr.syntax
def transmittance(scene: mi.Scene, medium: mi.MediumPtr, it: mi.Interaction3f, target: mi.Point3f,
                  sampler: mi.Sampler, channel, floor: float, active, tracking_kind: str = "ratio", grid=None,
                  stand_in=None):
    """T from the vertex ``it`` (inside ``medium``, which a surface vertex has already switched
    to the side facing ``target``) to the point ``target``: through media, and through the
    surfaces between whose BSDFs let light pass unscattered (``null`` boundaries, a mask's clear
    part: ``eval_null_transmission``); every other surface blocks it. Rays start and stop at
    the lab's offsets (``spawn``). ``tracking_kind``, ``grid``: ``segment_transmittance``'s.

    ``stand_in``: None, or a deterministic value for each piece inside a heterogeneous medium,
    ``stand_in(medium, start, end, wavelengths, channel, active)``; then returns (T, T_det): T_det
    the product in ``channel`` of the exact factors (homogeneous pieces, null boundaries) and of
    the stand-ins (lab_bdpt's MIS weights need a transmittance that no random draw changes)."""
    ray = spawn.spawn_ray_to(it, target, floor)
    medium = mi.MediumPtr(medium)
    T = mi.UnpolarizedSpectrum(1.0)
    T_det = mi.Float(1.0)
    going = mi.Bool(active)
    while going:
        si = scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=going)
        crossing = going & si.is_valid()
        segment = mi.Ray3f(ray)
        segment.maxt = dr.select(crossing, si.t, ray.maxt)
        inside = going & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
        T_seg = segment_transmittance(medium, segment, sampler, channel, inside, tracking_kind, grid)
        T[inside] *= T_seg
        bsdf = si.bsdf(ray)
        T_null = bsdf.eval_null_transmission(si, crossing)
        T[crossing] *= T_null
        if dr.hint(stand_in is not None, mode="scalar"):
            # (the last piece ends at the target itself, not where the shortened shadow ray stops)
            tracked = inside & ~medium.is_homogeneous()
            end = dr.select(crossing, segment(segment.maxt), target)
            T_det[inside] *= dr.select(tracked, stand_in(medium, segment.o, end, ray.wavelengths, channel, tracked),
                                       channel_value(T_seg, channel))
            T_det[crossing] *= channel_value(T_null, channel)
        medium[crossing & si.is_medium_transition()] = si.target_medium(ray.d)
        # on past the surface, towards the same target
        ray[crossing] = spawn.spawn_ray_to(si, target, floor)
        going = crossing & (dr.max(mi.unpolarized_spectrum(T)) > 0)
    return T if stand_in is None else (T, T_det)


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
    vertices then weigh their samples against equi-angular sampling too."""
    from mitsuba_lab.plugins.integrators.common.direct import emitter_sample_contribution
    from mitsuba_lab.plugins.integrators.estimator import Densities

    for _ in range(n_L):
        ds, em_weight = scene.sample_emitter_direction(it, sampler.next_2d(), False, active)
        sampled = active & (ds.pdf != 0)
        # a surface at a medium boundary sends the shadow ray into the medium on its side
        start = dr.select(~scattered & si.is_medium_transition(), si.target_medium(ds.d), medium)
        T = transmittance(scene, start, it, ds.p, sampler, channel, floor, sampled, tracking_kind, grid)
        f_bsdf, pdf_bsdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), sampled & ~scattered)
        f_phase, pdf_phase = phase.eval_pdf(phase_ctx, mei, ds.d, sampled & scattered)
        f = dr.select(scattered, f_phase, f_bsdf)
        d = Densities(bsdf=dr.select(scattered, pdf_phase, pdf_bsdf), emitter=n_L * ds.pdf, delta=ds.delta)
        if equiangular is not None:
            d = equiangular.densities(scene, d, it, ds, sampled, nee)
        w = sample_weight(d)
        L = L + emitter_sample_contribution(beta, ds, em_weight * T, f, w / n_L, sampled)
    return L


# ---------------------------------------------------------------------------
# Equi-angular sampling (Kulla and Fajardo 2012)
# ---------------------------------------------------------------------------
class Segment:
    """A ray's path through a homogeneous medium: origin ``o``, unit direction ``d``, length
    ``t_max`` (to the next surface; inf where there is none)."""
    DRJIT_STRUCT = {"o": mi.Point3f, "d": mi.Vector3f, "t_max": mi.Float}

    def __init__(self, o=None, d=None, t_max=None):
        self.o = mi.Point3f(0) if o is None else o
        self.d = mi.Vector3f(0) if d is None else d
        self.t_max = mi.Float(0) if t_max is None else t_max


def _angles(segment: Segment, y):
    """(t0, D, theta_a, theta_b): the foot t0 of the perpendicular from ``y`` to the segment's
    line, its length D, and the angles under which ``y`` sees the segment's ends."""
    to_y = y - segment.o
    t0 = dr.dot(to_y, segment.d)
    D = dr.maximum(dr.norm(to_y - t0 * segment.d), 1e-7 * (1.0 + dr.norm(to_y)))
    return t0, D, dr.atan2(-t0, D), dr.atan2(segment.t_max - t0, D)


def equiangular_sample(segment: Segment, y, u):
    """(t, pdf): a distance along the segment with density proportional to 1 / |x(t) - y|^2,
    t = t0 + D tan(theta), theta uniform in [theta_a, theta_b], and that density
    D / ((theta_b - theta_a)(D^2 + (t - t0)^2))."""
    t0, D, a, b = _angles(segment, y)
    t = t0 + D * dr.tan(dr.lerp(a, b, u))
    return t, D / ((b - a) * (dr.square(D) + dr.square(t - t0)))


def equiangular_pdf(segment: Segment, y, t):
    """The density of ``equiangular_sample`` at distance ``t`` (0 outside the segment)."""
    t0, D, a, b = _angles(segment, y)
    inside = (t >= 0) & (t <= segment.t_max)
    return dr.select(inside, D / ((b - a) * (dr.square(D) + dr.square(t - t0))), 0.0)


def _origin(segment: Segment, wavelengths) -> mi.Interaction3f:
    it = dr.zeros(mi.Interaction3f)
    it.p, it.wavelengths = segment.o, wavelengths
    return it


def equiangular_density(scene, segment: Segment, it: mi.Interaction3f, ds: mi.DirectionSample3f, active):
    """p_E at the medium point ``it`` (distance t = |it.p - o| along ``segment``) for the light
    point of ``ds`` (sampled from ``it``): the equi-angular density of t given that point, times
    the density with which a light sample from the segment's origin picks that point, expressed
    per unit solid angle at ``it`` (the measure of the other two techniques' densities there).
    0 for emitters at infinity, which have no point to aim at."""
    o = _origin(segment, it.wavelengths)
    at_o = dr.zeros(mi.DirectionSample3f)
    at_o.p, at_o.n, at_o.uv, at_o.time, at_o.emitter, at_o.delta = ds.p, ds.n, ds.uv, ds.time, ds.emitter, ds.delta
    to_y = ds.p - o.p
    at_o.dist = dr.norm(to_y)
    at_o.d = to_y / at_o.dist
    finite = active & ~mi.has_flag(ds.emitter.flags(), mi.EmitterFlags.Infinite)
    pdf_o = scene.pdf_emitter_direction(o, at_o, finite & ~ds.delta)
    # per unit area at y, then per unit solid angle at it
    cos_o, cos_it = dr.abs(dr.dot(at_o.d, ds.n)), dr.abs(dr.dot(ds.d, ds.n))
    to_it = pdf_o * cos_o / dr.square(at_o.dist) * dr.square(ds.dist) / cos_it
    # a delta light: both light samples pick it with the same (discrete) probability
    pdf_light = dr.select(ds.delta, ds.pdf, to_it)
    t = dr.dot(it.p - segment.o, segment.d)
    p = equiangular_pdf(segment, ds.p, t) * pdf_light
    return dr.select(finite & dr.isfinite(p), p, 0.0)


def distance_pdf(medium, segment_t, mei_sigma_t, channel, ratios=None):
    """p_d(t) = sigma_t,c exp(-sigma_t,c t): the density of a free flight's collision at distance
    t in a homogeneous medium, in the sampling channel c; with spectral MIS's ``ratios`` r (of
    the path before this flight, ``free_flight``) the mean over the channels weighted by r,
    which is what the path's density mean_c(P_c p_c(t)) is to mean_c(P_c)."""
    if ratios is None:
        sigma = channel_value(mei_sigma_t, channel)
        return sigma * dr.exp(-sigma * segment_t)
    return dr.mean(ratios * mei_sigma_t * dr.exp(-mei_sigma_t * segment_t)) / dr.mean(ratios)


class Equiangular:
    """What the MIS weights at a medium vertex need to know of equi-angular sampling: the segment
    the vertex was found on, p_d (its free flight's density there), the lanes where equi-angular
    sampling ran along that segment (``lanes``). ``densities``' ``nee``: whether NEE at the free
    flight's collision is one of the techniques (mode ``mis``; not in mode ``equiangular``). Elsewhere (surface
    vertices, heterogeneous media) the third density is 0 and p_d is 1."""
    DRJIT_STRUCT = {"segment": Segment, "pdf_distance": mi.Float, "lanes": mi.Bool}

    def __init__(self, segment=None, pdf_distance=None, lanes=None):
        self.segment = Segment() if segment is None else segment
        self.pdf_distance = mi.Float(1.0) if pdf_distance is None else pdf_distance
        self.lanes = mi.Bool(False) if lanes is None else lanes

    def densities(self, scene, d, it, ds, active, nee: bool):
        """``d`` (the densities of a hit or an emitter sample at the vertex ``it``, in solid angle)
        with the equi-angular density added, all per unit distance and solid angle."""
        from mitsuba_lab.plugins.integrators.estimator import Densities

        p_d = dr.select(self.lanes, self.pdf_distance, 1.0)
        emitter = d.emitter if nee else dr.select(self.lanes, 0.0, d.emitter)
        p_e = equiangular_density(scene, self.segment, it, ds, active & self.lanes)
        return Densities(bsdf=p_d * d.bsdf, emitter=p_d * emitter, delta=d.delta, equiangular=p_e)


def equiangular_scatter(scene, sampler, phase_ctx, medium, segment: Segment, wavelengths, beta, channel,
                        equiangular_weight, n_L: int, nee: bool, active, floor: float,
                        tracking_kind: str = "ratio", grid=None, ratios=None):
    """One equi-angular sample of the direct light scattered towards the segment's origin along
    ``segment`` (inside the homogeneous ``medium``): a light point y sampled from the origin,
    a distance t towards it (``equiangular_sample``), and

        beta T(0, t) sigma_s(t) f_p L_e T(t, y) w_E / (p_ea(t) p_y),

    p_y the density of y per unit solid angle at x(t), w_E = ``equiangular_weight(Densities)``
    against NEE at a free flight's collision (``nee``: n_L samples) and phase-function sampling,
    both with the collision's density p_d(t) (``distance_pdf``, with ``ratios``). Returns the contribution (0 for
    emitters at infinity, which have no point to aim at)."""
    from mitsuba_lab.plugins.integrators.common.direct import spectrum_or_zero
    from mitsuba_lab.plugins.integrators.estimator import Densities

    o = _origin(segment, wavelengths)
    ds_o, _ = scene.sample_emitter_direction(o, sampler.next_2d(), False, active)
    ok = active & (ds_o.pdf > 0) & ~mi.has_flag(ds_o.emitter.flags(), mi.EmitterFlags.Infinite)
    t, pdf_t = equiangular_sample(segment, ds_o.p, sampler.next_1d())
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.p, mei.t, mei.time, mei.wavelengths, mei.medium = segment.o + t * segment.d, t, ds_o.time, wavelengths, medium
    mei.wi = -segment.d
    mei.sh_frame = mi.Frame3f(mei.wi)
    sigma_s, _, sigma_t = medium.get_scattering_coefficients(mei, ok)
    # the light point seen from x(t) (ds_o redirected: a copy would lose its emitter pointer)
    cos_o, dist_o = dr.abs(dr.dot(ds_o.d, ds_o.n)), mi.Float(ds_o.dist)   # (a copy: the field is reassigned)
    ds = ds_o
    to_y = ds.p - mei.p
    ds.dist = dr.norm(to_y)
    ds.d = to_y / ds.dist
    it = dr.zeros(mi.Interaction3f)
    it.p, it.time, it.wavelengths = mei.p, mei.time, wavelengths
    emitted = scene.eval_emitter_direction(it, ds, ok)
    cos_t = dr.abs(dr.dot(ds.d, ds.n))
    pdf_y = dr.select(ds.delta, ds.pdf, ds.pdf * cos_o / dr.square(dist_o) * dr.square(ds.dist) / cos_t)
    phase = medium.phase_function()
    f, pdf_phase = phase.eval_pdf(phase_ctx, mei, ds.d, ok)
    T_light = transmittance(scene, medium, it, ds.p, sampler, channel, floor, ok, tracking_kind, grid)
    p_d = distance_pdf(medium, t, sigma_t, channel, ratios)
    pdf_nee = dr.select(ds.delta, ds.pdf, scene.pdf_emitter_direction(it, ds, ok & ~ds.delta))
    p_e = pdf_t * pdf_y
    w = equiangular_weight(Densities(bsdf=p_d * pdf_phase, emitter=p_d * n_L * pdf_nee if nee else 0.0 * p_d,
                                     delta=ds.delta, equiangular=p_e))
    T_ray = dr.exp(-sigma_t * t)
    value = beta * (T_ray * sigma_s * w / p_e) * f * emitted * T_light
    return dr.select(ok & (p_e > 0) & dr.isfinite(p_e), spectrum_or_zero(value), 0.0)
