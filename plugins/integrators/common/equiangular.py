"""Equi-angular sampling (Kulla and Fajardo 2012) of the light scattered along a ray in a medium.

A light point y is sampled from the ray segment's origin, then a distance t along the segment
with density proportional to 1 / |x(t) - y|^2; the sample carries T(0, t) sigma_s(t) f_p L_e
T(t, y) over its two densities. lab_nee and lab_mis combine it by MIS with the free flight's
collision (NEE there, and for lab_mis the phase-sampled direction), their densities per unit
distance and solid angle (``Equiangular``, ``equiangular_scatter``).

In a homogeneous medium the free flight's density at t is sigma_t exp(-sigma_t t), exact. In a
heterogeneous medium it has no closed form, so the lab weighs the techniques as Miller et al.
(2019) and pbrt-v4's volpath do: over the tentative collisions too. A free flight reaches x
through null collisions at the same places, with the same majorant, as the ratio tracking that
estimates an equi-angular sample's T(0, t); relative to them, its density at x is

    p_d(x) = mean_c sigma_t,c(x) * prod_i P_null(t_i)            (P_null = mean_c sigma_n,c / sigma_bar)

over the null collisions t_i of whichever tracking produced the sample (the *null chain*,
``media``; with ``transmittance = delta`` equi-angular samples pass nulls as free flights do,
and the product is 1 for both). The weights then sum to 1 over the techniques for every path
with its null collisions, so the estimate stays unbiased; its T(0, t) is the ratio-tracking
estimate itself, from the shadow rays' code (``media.segment_transmittance``).

In a heterogeneous medium the segment is clipped to the medium's box, where its collisions
can be (Mitsuba tracks only inside it).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common.media import channel_value, segment_transmittance, transmittance


class Segment:
    """A ray's path through a medium: origin ``o``, unit direction ``d``, length ``t_max`` (to
    the next surface; inf where there is none; ``of_ray``)."""
    DRJIT_STRUCT = {"o": mi.Point3f, "d": mi.Vector3f, "t_max": mi.Float}

    def __init__(self, o=None, d=None, t_max=None):
        self.o = mi.Point3f(0) if o is None else o
        self.d = mi.Vector3f(0) if d is None else d
        self.t_max = mi.Float(0) if t_max is None else t_max

    @staticmethod
    def of_ray(medium, ray: mi.Ray3f, t_surface, active) -> "Segment":
        """The part of ``ray`` up to ``t_surface`` where equi-angular sampling can find a
        collision: all of it in a homogeneous medium, the part inside the medium's box in a
        heterogeneous one (length 0 where it misses the box)."""
        hit, t_in, t_out = medium.intersect_aabb(ray)
        clip = active & ~medium.is_homogeneous()
        t0 = dr.select(clip, dr.maximum(t_in, 0.0), 0.0)
        t1 = dr.select(clip, dr.minimum(t_out, t_surface), t_surface)
        length = dr.select(~clip | (hit & (t1 > t0)), t1 - t0, 0.0)
        return Segment(mi.Point3f(ray.o + t0 * ray.d), mi.Vector3f(ray.d), length)


def lights_at_infinity(scene) -> bool:
    """Whether ``scene`` has an emitter at infinity (an environment map, ``constant``,
    ``directional``). Equi-angular sampling has no point of it to aim at, so where there is one,
    NEE at medium vertices must sample it even in mode ``equiangular``."""
    return any(mi.has_flag(e.flags(), mi.EmitterFlags.Infinite) for e in scene.emitters())


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


def distance_pdf(medium, segment_t, mei_sigma_t, channel, ratios=None, nulls=1.0):
    """p_d(t): the density of a free flight's collision at distance t along the segment. In a
    homogeneous medium sigma_t,c exp(-sigma_t,c t) in the sampling channel c; with spectral MIS's
    ``ratios`` r (of the path before this flight, ``media.free_flight``) the mean over the
    channels weighted by r, which is what the path's density mean_c(P_c p_c(t)) is to mean_c(P_c).
    In a heterogeneous medium mean_c sigma_t,c times ``nulls``, the null chain of the tracking
    that led to the point (the module's docstring; the same for every channel, as the majorant is)."""
    if ratios is None:
        sigma = channel_value(mei_sigma_t, channel)
        exact = sigma * dr.exp(-sigma * segment_t)
    else:
        exact = dr.mean(ratios * mei_sigma_t * dr.exp(-mei_sigma_t * segment_t)) / dr.mean(ratios)
    return dr.select(medium.is_homogeneous(), exact, dr.mean(mi.unpolarized_spectrum(mei_sigma_t)) * nulls)


def flight_nulls(nulls, tracking_kind: str):
    """The null chain to weigh a free flight's collision with: its own (``media.free_flight``)
    where equi-angular samples are tracked by ratio tracking, 1 where by delta tracking."""
    return nulls if tracking_kind == "ratio" else 1.0


class Equiangular:
    """What the MIS weights at a medium vertex need to know of equi-angular sampling: the segment
    the vertex was found on, p_d (its free flight's density there), the lanes where equi-angular
    sampling ran along that segment (``lanes``). ``densities``' ``nee``: whether NEE at the free
    flight's collision is one of the techniques (mode ``mis``; not in mode ``equiangular``).
    Elsewhere (surface vertices) the third density is 0 and p_d is 1."""
    DRJIT_STRUCT = {"segment": Segment, "pdf_distance": mi.Float, "lanes": mi.Bool}

    def __init__(self, segment=None, pdf_distance=None, lanes=None):
        self.segment = Segment() if segment is None else segment
        self.pdf_distance = mi.Float(1.0) if pdf_distance is None else pdf_distance
        self.lanes = mi.Bool(False) if lanes is None else lanes

    def densities(self, scene, d, it, ds, active, nee: bool):
        """``d`` (the densities of a hit or an emitter sample at the vertex ``it``, in solid angle)
        with the equi-angular density added, all per unit distance and solid angle. Without
        ``nee``, NEE at the collision samples only the lights that equi-angular sampling cannot
        (those at infinity: p_E = 0)."""
        from mitsuba_lab.plugins.integrators.estimator import Densities

        p_d = dr.select(self.lanes, self.pdf_distance, 1.0)
        p_e = equiangular_density(scene, self.segment, it, ds, active & self.lanes)
        emitter = d.emitter if nee else dr.select(self.lanes & (p_e > 0), 0.0, d.emitter)
        return Densities(bsdf=p_d * d.bsdf, emitter=p_d * emitter, delta=d.delta, equiangular=p_e)


def equiangular_scatter(scene, sampler, phase_ctx, medium, segment: Segment, wavelengths, beta, channel,
                        equiangular_weight, n_L: int, nee: bool, active, floor: float,
                        tracking_kind: str = "ratio", grid=None, ratios=None):
    """One equi-angular sample of the direct light scattered towards the segment's origin along
    ``segment`` (inside ``medium``): a light point y sampled from the origin,
    a distance t towards it (``equiangular_sample``), and

        beta T(0, t) sigma_s(t) f_p L_e T(t, y) w_E / (p_ea(t) p_y),

    p_y the density of y per unit solid angle at x(t), w_E = ``equiangular_weight(Densities)``
    against NEE at a free flight's collision (``nee``: n_L samples) and phase-function sampling,
    both with the collision's density p_d(t) (``distance_pdf``, with ``ratios``). T(0, t) is
    Beer-Lambert in a homogeneous medium, else tracked as the shadow rays' T (``tracking_kind``,
    ``grid``), whose null chain enters p_d(t). Returns (the contribution, 0 for emitters at
    infinity, which have no point to aim at; whether its shadow ray was traced: not for a sample of
    MIS weight 0)."""
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
    tracked = ok & ~medium.is_homogeneous()
    to_x = mi.Ray3f(segment.o, segment.d, t, ds_o.time, wavelengths)
    T_tracked, nulls = segment_transmittance(medium, to_x, sampler, channel, tracked, tracking_kind, grid)
    T_ray = dr.select(tracked, T_tracked, dr.exp(-sigma_t * t))
    p_d = distance_pdf(medium, t, sigma_t, channel, ratios, nulls)
    pdf_nee = dr.select(ds.delta, ds.pdf, scene.pdf_emitter_direction(it, ds, ok & ~ds.delta))
    p_e = pdf_t * pdf_y
    w = equiangular_weight(Densities(bsdf=p_d * pdf_phase, emitter=p_d * n_L * pdf_nee if nee else 0.0 * p_d,
                                     delta=ds.delta, equiangular=p_e))
    # (after the weight, which needs no visibility: no shadow ray for a sample of weight 0)
    shadow = ok & (w > 0)
    T_light = transmittance(scene, medium, it, ds.p, sampler, channel, floor, shadow, tracking_kind, grid)
    value = beta * mi.Spectrum(T_ray * sigma_s * w / p_e * T_light) * f * emitted
    return dr.select(ok & (p_e > 0) & dr.isfinite(p_e), spectrum_or_zero(value), 0.0), shadow
