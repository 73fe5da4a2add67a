"""Equi-angular sampling (Kulla and Fajardo 2012) in lab_bdpt's camera subpaths, two kinds, each
with a density the MIS weights evaluate for any path, from either end.

**Equi-angular NEE** (``equiangular_nee``, on by default; lab_mis's technique). On the first flight
of each camera segment in a homogeneous medium (from the sensor or a vertex to the next surface,
t_s away), the camera also draws a point x equi-angularly over [0, t_s] towards a light's fixed
point c_e (e picked by P(e), below) and samples a light from x (``equiangular_nee``); the path goes
on from the free flight as before. This is a second s = 1 technique: its density is s = 1's times

    rho = sum_e P(e) p_eq(t; c_e, [0, t_s]) / p_camera(x)     (``rho``; p_camera: g T, times r below)

so every sum that holds s = 1's term holds it 1 + rho^beta times, and its own weight is s = 1's
times rho^beta (``Recursion.nee``, ``hit``; at a light subpath's first vertex ``connect`` and
``light_to_camera``; past it ``equiangular_term`` and ``add_equiangular``). rho is needed only at a
light subpath's first vertex, whose piece end beyond it the light side finds with one ray
(``beyond``, ``rho_towards``); the camera knows its own (its flight's surface). Not with merging
(lab_vcm's modes vcm, bpm and ppm leave it out).

**The flights' mixture** (``equiangular`` = q, off by default). Along the first flight of a camera-subpath segment (from the sensor or a vertex, up to the next
surface, in a homogeneous medium) the distance t is drawn, with probability q (``equiangular``),
equi-angularly (Kulla and Fajardo 2012) towards a fixed point c_e of an emitter e picked with the
scene's emitter-sampling probability P(e) (a point or spot light's position, an area light's
bounding-box centre; an emitter at infinity has none, and its share draws a free flight), and else
by a free flight. The equi-angular density is taken over the half-line t >= 0, not up to the
surface, so that it depends only on the flight's origin o, its direction and c_e:

    p_eq(t; c) = D / ((pi/2 - theta_a) (D^2 + (t - t_c)^2)),   theta_a = atan2(-t_c, D),

t_c the foot of c's perpendicular on the line and D its distance. A draw beyond the surface at
t_s means the surface is reached. Per unit length at a collision, and as a probability at the
surface, in the path's sampling channel c (sigma = sigma_t,c):

    p(t)   = q sum_e P(e) p_eq(t; c_e)       + (1 - q F) sigma exp(-sigma t)
    P(t_s) = q sum_e P(e) (1 - F_eq(t_s; c_e)) + (1 - q F) exp(-sigma t_s)

(F the finite emitters' total P; the throughput carries T sigma_s / p, or T / P). The MIS weights
(``recursion.Recursion.after_hit``'s ``forward``, ``backward``; the connecting segments' cosines)
need this density only through its ratio r to the free flight's, sigma exp(-sigma t) or
exp(-sigma t), which ``ratio`` evaluates from the segment's ends: the camera subpath for the
segments it samples, the light subpath for the camera's density of the same segments walked the
other way (each light vertex's reverse density), and every connection, NEE and light-tracing join
for its own segment. A segment passing null surfaces (a window's pane) mixes only on its first
flight, to the first surface (``first_surface``), whose end both sides find; later flights are
free flights (r = 1). On fog_shafts the mixture gained little (its draws towards a light behind a
surface mostly land past that surface; experiments/results/2026-11-29-bdpt-equiangular.md).

Heterogeneous media keep delta tracking (neither kind runs there). Scenes with more than
``MAX_EMITTERS`` emitters, or with both kinds off, render the images from before (free flights only).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import media

#: More emitters than this: no equi-angular sampling (its density sums over them at every segment).
MAX_EMITTERS = 8


def _centre(emitter):
    """The fixed point an equi-angular flight aims at for ``emitter``, or None (at infinity)."""
    if mi.has_flag(emitter.flags(), mi.EmitterFlags.Infinite):
        return None
    shape = emitter.get_shape()
    if shape is not None:
        c = shape.bbox().center()
        return (float(c[0]), float(c[1]), float(c[2]))
    it = dr.zeros(mi.Interaction3f, 1)
    ds, _ = emitter.sample_direction(it, mi.Point2f(0.5, 0.5))
    return (float(ds.p.x[0]), float(ds.p.y[0]), float(ds.p.z[0]))


class EquiangularMixture:
    """The mixture for one scene: ``q``, and per emitter (in ``scene.emitters()`` order) its
    sampling probability and fixed point (None at infinity). ``on``: whether any camera flight
    mixes (q > 0, at most ``MAX_EMITTERS`` emitters, one of them finite); ``passable``: the scene
    has null surfaces, which a segment's pieces may cross (``first_surface`` casts a ray)."""

    def __init__(self, scene: mi.Scene, q: float, nee: str = "off"):
        emitters = scene.emitters()
        self.q = float(q)
        self.emitters = []
        if (self.q > 0 or nee != "off") and 0 < len(emitters) <= MAX_EMITTERS:
            for i, e in enumerate(emitters):
                p = float(scene.pdf_emitter(mi.UInt32(i))[0])
                self.emitters.append((p, _centre(e)))
        self.finite = sum(p for p, c in self.emitters if c is not None)
        #: equi-angular NEE (``nee``: off, on the camera's first segment, on all), a second s = 1
        #: technique; ``on``: anything to track
        self.nee = nee != "off" and self.finite > 0
        self.nee_all = self.nee and nee == "all"
        self.mixes = self.q > 0 and self.finite > 0
        self.on = self.mixes or self.nee
        self.passable = any(mi.has_flag(s.bsdf().flags(), mi.BSDFFlags.Null) for s in scene.shapes()
                            if s.bsdf() is not None)

    @staticmethod
    def off() -> "EquiangularMixture":
        mix = EquiangularMixture.__new__(EquiangularMixture)
        mix.q, mix.emitters, mix.finite, mix.on, mix.passable = 0.0, [], 0.0, False, False
        mix.nee = mix.nee_all = mix.mixes = False
        return mix

    def _aims(self):
        """(P(e), fixed point) of the finite emitters."""
        return [(p, mi.Point3f(*c)) for p, c in self.emitters if c is not None]


def _angles(o, d, c, t_b=None):
    """(t_c, D, theta_a, span) of the fixed point ``c`` seen from the half-line o + t d (from
    its piece [0, t_b] where ``t_b`` is given)."""
    to_c = c - o
    t_c = dr.dot(to_c, d)
    D = dr.maximum(dr.norm(to_c - t_c * d), 1e-6 * (1.0 + dr.norm(to_c)))
    theta_a = dr.atan2(-t_c, D)
    theta_b = 0.5 * math.pi if t_b is None else dr.atan2(t_b - t_c, D)
    return t_c, D, theta_a, theta_b - theta_a


def eq_pdf(o, d, c, t, t_b=None):
    """p_eq(t; c) over the half-line, or [0, t_b] (per unit length)."""
    t_c, D, _, span = _angles(o, d, c, t_b)
    return D / (span * (dr.square(D) + dr.square(t - t_c)))


def eq_survival(o, d, c, t):
    """1 - F_eq(t; c): the probability that an equi-angular draw lies beyond t."""
    t_c, D, theta_a, span = _angles(o, d, c)
    return dr.clip((0.5 * math.pi - dr.atan2(t - t_c, D)) / span, 0.0, 1.0)


def eq_sample(o, d, c, u, t_b=None):
    """An equi-angular distance over the half-line, or [0, t_b] (inf where the angle rounds
    past pi/2)."""
    t_c, D, theta_a, span = _angles(o, d, c, t_b)
    # t = D (tan theta - tan theta_a), written so that it is accurate near t = 0 and turns to
    # inf where theta rounds to pi/2 or past it (cos <= 0)
    delta = u * span
    cos_theta = dr.cos(theta_a + delta)
    t = D * dr.sin(delta) / (cos_theta * dr.cos(theta_a))
    return dr.select(cos_theta > 0, dr.maximum(t, 0.0), dr.inf)


def eq_density(mix, o, d, t, t_s):
    """Equi-angular NEE's density of distance t along the piece [0, t_s] from o: sum_e P(e)
    p_eq(t; c_e) over the finite emitters."""
    p = mi.Float(0.0)
    for p_e, c in mix._aims():
        p += p_e * eq_pdf(o, d, c, t, t_s)
    return p


def rho(mix, medium, o, x, t_s, r, wavelengths, channel, active):
    """rho: equi-angular NEE's density of the medium vertex ``x`` along the piece of length
    ``t_s`` from ``o`` over the camera's own (the free flight's times ``r``, ``ratio``); 0
    where it cannot build x (no homogeneous medium, or off)."""
    if mix is None or not mix.nee:
        return None
    use, t, d, sigma_c = _piece(medium, o, x, wavelengths, channel, active)
    value = eq_density(mix, o, d, t, t_s) / (sigma_c * dr.exp(-sigma_c * t) * r)
    return dr.select(use & (t > 0) & (t < t_s) & dr.isfinite(value), value, 0.0)


def nee_segment(mix, depth):
    """Whether equi-angular NEE runs on the camera segment leaving the vertex ``depth`` segments
    from the sensor (all, or only the sensor's: mode first, which the light side knows without
    knowing how far its vertices lie from the sensor)."""
    return True if mix.nee_all else depth == 0


def beyond(scene, p, d, active):
    """The distance from the medium point ``p`` along ``d`` to the first surface (inf: none)."""
    pi = scene.ray_intersect_preliminary(mi.Ray3f(p, d), coherent=False, active=active)
    return dr.select(active & pi.is_valid(), pi.t, dr.inf)


def rho_towards(scene, mix, medium, x, y, r, floor, wavelengths, channel, active):
    """``rho`` of the medium vertex ``y`` seen from ``x`` (an interaction, normal 0 in a medium):
    0 where the first flight from x ends at a surface before y, else with the piece's end found
    beyond y (one ray)."""
    if mix is None or not mix.nee:
        return None
    end, crossed = first_surface(scene, mix, x.p, x.n, y, floor, active)
    d = dr.normalize(y - x.p)
    use = active & ~crossed
    t_s = dr.norm(y - x.p) + beyond(scene, y, d, use)
    return dr.select(use, rho(mix, medium, x.p, y, t_s, r, wavelengths, channel, use), 0.0)


def _piece(medium, o, x, wavelengths, channel, active):
    """(use, t, d, sigma_t in ``channel``) of the straight piece from ``o`` to ``x``: ``use`` where
    it lies in a homogeneous medium, its length and direction."""
    use = active & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
    use &= medium.is_homogeneous()
    to_x = x - o
    t = dr.norm(to_x)
    _, _, sigma_c = _sigma(medium, o, wavelengths, channel, use)
    return use, t, to_x / t, sigma_c


def _sigma(medium, p, wavelengths, channel, active):
    """(sigma_s, sigma_t, sigma_t in ``channel``) of the homogeneous ``medium``."""
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.p, mei.wavelengths = p, wavelengths
    sigma_s, _, sigma_t = medium.get_scattering_coefficients(mei, active)
    return sigma_s, sigma_t, media.channel_value(sigma_t, channel)


def _mixed(mix, o, d, t, collides, sigma_c):
    """(mixture density, free flight's) of reaching distance t (a collision there, or the
    surface at t), both per unit length at a collision."""
    free = dr.select(collides, sigma_c, 1.0) * dr.exp(-sigma_c * t)
    eq = mi.Float(0.0)
    for p, c in mix._aims():
        eq += p * dr.select(collides, eq_pdf(o, d, c, t), eq_survival(o, d, c, t))
    return mix.q * eq + (1.0 - mix.q * mix.finite) * free, free


def ratio(mix, medium, o, x, collides, wavelengths, channel, active):
    """r: the mixture's density of the segment from ``o`` to ``x`` (a collision at x where
    ``collides``, else x reached: a surface, an emitter, a null surface crossed) over the free
    flight's, in ``medium`` (1 where it is no homogeneous medium, or the mixture is off)."""
    if not mix.mixes:
        return mi.Float(1.0)
    use, t, d, sigma_c = _piece(medium, o, x, wavelengths, channel, active)
    p, free = _mixed(mix, o, d, t, collides, sigma_c)
    r = p / free
    return dr.select(use & (free > 0) & (t > 0) & dr.isfinite(r), r, 1.0)


def first_surface(scene, mix, o, n, target, floor, active):
    """(end, crossed): where the first flight from ``o`` (normal ``n``; 0 in a medium) towards
    ``target`` ends: the first surface before ``target`` where the scene has null surfaces
    (``crossed``), else ``target``."""
    if not (mix.on and mix.passable):
        return target, dr.zeros(mi.Bool, dr.width(active))
    from mitsuba_lab.plugins.integrators.common import spawn

    it = dr.zeros(mi.Interaction3f)
    it.p, it.n = o, n
    ray = spawn.spawn_ray_to(it, target, floor)
    pi = scene.ray_intersect_preliminary(ray, coherent=False, active=active)
    crossed = active & pi.is_valid()
    return dr.select(crossed, ray(pi.t), target), crossed


def flight(mix, medium, ray: mi.Ray3f, t_max, u, u_pick, channel, active, exact):
    """``subpath_media.flight``'s (mei, scattered, weight, T_c) with, in the ``active`` lanes (a
    homogeneous medium, a segment's first flight), the mixture: ``u_pick`` < q picks an emitter
    by P(e) and draws t equi-angularly towards its point with ``u``, else (or for an emitter at
    infinity) a free flight with ``u``. The weight is T sigma_s / p(t) at a collision, T / P(t_max)
    at the surface; T_c stays the free flight's (the weights' g T; ``ratio`` gives the rest)."""
    mei_x, scattered_x, weight_x, T_c_x = exact
    sigma_s, sigma_t, sigma_c = _sigma(medium, ray.o, ray.wavelengths, channel, active)
    t = -dr.log(1.0 - u) / sigma_c
    pick = u_pick < mix.q
    u_e = u_pick / mix.q
    low = 0.0
    for p, c in mix.emitters:
        here = pick & (u_e >= low) & (u_e < low + p)
        if c is not None:
            t = dr.select(here, eq_sample(ray.o, ray.d, mi.Point3f(*c), u), t)
        low += p
    scattered = active & (t < t_max)
    t_end = dr.select(scattered, t, t_max)
    p, _ = _mixed(mix, ray.o, ray.d, t_end, scattered, sigma_c)
    ok = active & (p > 0) & dr.isfinite(t_end)
    scattered &= ok
    tr = dr.exp(-sigma_t * t_end)
    weight = dr.select(scattered, tr * sigma_s, tr) / dr.select(ok, p, 1.0)
    weight = dr.select(ok, mi.UnpolarizedSpectrum(weight), 0.0)

    mei = dr.zeros(mi.MediumInteraction3f)
    mei.t = dr.select(scattered, t_end, dr.inf)
    mei.p = ray(t_end)
    mei.wi = -ray.d
    mei.sh_frame = mi.Frame3f(mei.wi)
    mei.time, mei.wavelengths, mei.medium = ray.time, ray.wavelengths, medium
    mei.mint = 0.0
    mei.sigma_s, mei.sigma_t = sigma_s, sigma_t
    mei.sigma_n = dr.zeros(mi.Spectrum)
    mei.combined_extinction = sigma_t
    mei_x[active] = mei
    T_c = dr.select(ok, dr.exp(-sigma_c * t_end), 0.0)
    return (mei_x, dr.select(active, scattered, scattered_x), dr.select(active, weight, weight_x),
            dr.select(active, T_c, T_c_x))


def mixture(tracer):
    """The light tracer's mixture where it is on, else None."""
    mix = getattr(tracer, "equiangular", None)
    return mix if mix is not None and mix.on else None


def segment_ratio(scene, mix, medium, x, target, collides, floor, channel, active):
    """``ratio`` of the segment a camera subpath would sample from the vertex ``x`` (an
    interaction: a medium vertex has normal 0) to ``target`` (a collision there where
    ``collides``): of its first flight, to the first surface on the way (``first_surface``)."""
    if mix is None or not mix.mixes:
        return 1.0
    active = active & (medium != None)  # noqa: E711 (Dr.Jit pointer test; no ray where r = 1 anyway)
    active &= medium.is_homogeneous()
    end, crossed = first_surface(scene, mix, x.p, x.n, target, floor, active)
    return ratio(mix, medium, x.p, end, collides & ~crossed, x.wavelengths, channel, active)


def from_sensor(scene, mix, tracer, sensor_p, target, collides, wavelengths, channel, active):
    """``segment_ratio`` of the camera's first segment, from the sensor's point ``sensor_p``
    to ``target``, in the sensor's medium (light tracing's joins)."""
    if mix is None:
        return 1.0
    it = dr.zeros(mi.Interaction3f)
    it.p = sensor_p
    it.wavelengths = wavelengths
    return segment_ratio(scene, mix, tracer.sensor_medium, it, target, collides, tracer.floor, channel, active)


def _eq_draw(mix, o, d, t_s, u_pick, u):
    """(t, density): equi-angular NEE's distance along [0, t_s] from o towards the point of an
    emitter picked by P(e) with ``u_pick`` (density 0 where one at infinity is picked)."""
    t, low = mi.Float(dr.inf), 0.0
    for p, c in mix.emitters:
        if c is not None:
            here = (u_pick >= low) & (u_pick < low + p)
            t = dr.select(here, eq_sample(o, d, mi.Point3f(*c), u, t_s), t)
        low += p
    ok = t < t_s
    return t, dr.select(ok, eq_density(mix, o, d, t, t_s), 0.0)


def equiangular_nee(scene, cp, mix, sampler, ray, si, medium, beta, state, prev_p, here, channel, phase_ctx,
                    active):
    """Equi-angular NEE on the camera segment ``ray`` (its first flight, in the homogeneous
    ``medium``, up to the surface ``si``): a point x drawn equi-angularly towards a light's point
    (``_eq_draw``), light sampled from it through the media, weighted against every strategy
    with the camera state at x as its flight would have found it (``state`` before the flight,
    ``prev_p`` where the segment starts, x ``here`` segments from the sensor):

        beta T(x) sigma_s(x) / p_E(t) f_p L_e T / p_nee  w_E,   w_E = w_nee(rho) rho^beta."""
    from mitsuba_lab.plugins.integrators.common.direct import spectrum_or_zero
    from mitsuba_lab.plugins.integrators.common.subpath_media import medium_vertex, phase_reverse_pdf
    from mitsuba_lab.plugins.integrators.common.subpath_media import transmittance as through

    from .light_subpath import float_or_zero, strategy_mask
    from .techniques import Technique

    w, table, floor = cp.weights, cp.table, cp.offset_floor
    on = active & strategy_mask(cp.only, 1, here + 1) & (Technique.NEE in w.techniques)
    u_pick, u = sampler.next_1d(), sampler.next_1d()
    t, p_t = _eq_draw(mix, ray.o, ray.d, si.t, u_pick, u)
    on &= p_t > 0
    sigma_s, sigma_t, sigma_c = _sigma(medium, ray.o, ray.wavelengths, channel, on)
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.t, mei.p, mei.wi = t, ray(t), -ray.d
    mei.sh_frame = mi.Frame3f(mei.wi)
    mei.time, mei.wavelengths, mei.medium = ray.time, ray.wavelengths, medium
    mei.sigma_s, mei.sigma_t, mei.combined_extinction = sigma_s, sigma_t, sigma_t
    v = medium_vertex(mei, ray.wavelengths)
    ds, em_weight = scene.sample_emitter_direction(v, sampler.next_2d(), False, on)
    on &= ds.pdf > 0
    infinite = table.at_infinity(ds.emitter, on)
    T, T_c = through(scene, medium, v, ds.p, sampler, channel, floor, on, cp.tracking, unbounded=infinite)
    phase = medium.phase_function()
    f, pdf_fwd = phase.eval_pdf(phase_ctx, mei, ds.d, on)
    pdf_rev = phase_reverse_pdf(phase, phase_ctx, mei, ds.d, on)
    dist2 = dr.select(infinite, 1.0, dr.square(ds.dist))
    cos_light = dr.select(ds.delta | infinite, 1.0, dr.abs(dr.dot(ds.n, ds.d)))
    pdf_nee = dr.select(ds.delta, ds.pdf, ds.pdf * cos_light / dist2)
    pdf_pos, pdf_dir, delta = table.emission(ds.emitter, cos_light, pdf_nee, on, ds.p, -ds.d)
    # the weights' geometry: from where the segment starts (as the light side evaluates it)
    t_mis = dr.norm(v.p - prev_p)
    t_s = dr.select(si.is_valid(), dr.norm(si.p - prev_p), dr.inf)
    r = ratio(mix, medium, prev_p, v.p, True, ray.wavelengths, channel, on)
    rho_x = rho(mix, medium, prev_p, v.p, t_s, r, ray.wavelengths, channel, on)
    mis = w.after_hit(state, dr.square(t_mis), sigma_c, dr.exp(-sigma_c * t_mis), forward=r)
    r_nee = segment_ratio(scene, mix, medium, v, ds.p, False, floor, channel, on)
    w_nee = w.nee(mis, pdf_nee, pdf_pos * pdf_dir, cos_light * T_c * r_nee, sigma_c * T_c, dist2, pdf_fwd, pdf_rev,
                  delta, here, True, rho=rho_x)
    w_e = float_or_zero(w_nee * w._m(rho_x))
    value = beta * mi.Spectrum(dr.exp(-sigma_t * t) * sigma_s / p_t) * mi.Spectrum(f) * em_weight * mi.Spectrum(T) * w_e
    return dr.select(on & (rho_x > 0), spectrum_or_zero(value), 0.0)
