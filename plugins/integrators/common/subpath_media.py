"""The pieces of subpaths in media that lab_bdpt (``bdpt.media_paths`` traces them), lab_vcm and
lab_photon share: the path's sampling
channel, the analytic free flight in it, delta tracking and the weights' stand-in transmittance
in heterogeneous media, the medium each emitter sits in (where its light subpaths start), a
medium vertex as a surface interaction, and a vertex's BSDF-or-phase evaluation. The densities,
the channel and the stand-ins are explained in ``media_paths``."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import media, spawn

#: A key mixed into the light seed for the sampling channel's hash, and one for the light side's
#: second random stream (the transmittance's draws, unused in homogeneous media).
_CHANNEL_KEY = 0x2545F491
_AUX_KEY = 0x68E31DA4


def path_channel(lane, key) -> mi.UInt32:
    """The sampling channel of light subpath ``lane`` (and of the camera lanes paired with it):
    uniform over the three in RGB, the hero wavelength (0) in spectral and mono variants."""
    if not mi.is_rgb:
        return dr.zeros(mi.UInt32, dr.width(lane))
    u = mi.sample_tea_float32(mi.UInt32(lane), dr.opaque(mi.UInt32, (key ^ _CHANNEL_KEY) & 0xFFFFFFFF))
    return mi.UInt32(dr.minimum(mi.UInt32(3.0 * u), 2))


class RngSampler:
    """A ``PCG32`` with the ``next_1d`` / ``next_2d`` of a Mitsuba sampler (for
    ``common.media.transmittance`` on the light side, which has no sampler)."""
    DRJIT_STRUCT = {"rng": mi.PCG32}

    def __init__(self, rng=None):
        self.rng = mi.PCG32() if rng is None else rng

    def next_1d(self, active=True):
        return self.rng.next_float32(active)

    def next_2d(self, active=True):
        return mi.Point2f(self.rng.next_float32(active), self.rng.next_float32(active))


def homogeneous_flight(medium, ray: mi.Ray3f, t_max, u, channel, active):
    """A free flight along ``ray`` in the homogeneous ``medium`` up to ``t_max`` (the next
    surface): (mei, scattered, weight, T_c). ``weight`` multiplies the throughput: T / p_c per
    channel, times sigma_s at a collision (``common.media.free_flight``'s weights with no null
    collisions), p_c the density of the outcome in the sampling channel c: sigma_t,c T_c(t) at a
    collision at t, T_c(t_max) past the surface. ``T_c`` is the transmittance in c up to the
    outcome, the segment's factor of the next vertex's p_A (whose sigma_t,c is its g)."""
    r = mi.Ray3f(ray)
    r.maxt = dr.select(active, t_max, 0.0)
    m = medium.sample_interaction(r, u, channel, active)
    end = dr.zeros(mi.SurfaceInteraction3f)
    end.t = r.maxt
    tr, pdf = medium.transmittance_eval_pdf(m, end, active)
    pdf_c = media.channel_value(pdf, channel)
    ok = active & (pdf_c > 0)
    weight = dr.select(ok, tr / pdf_c, 0.0)
    scattered = ok & m.is_valid()
    weight[scattered] *= m.sigma_s
    return m, scattered, mi.UnpolarizedSpectrum(weight), dr.select(ok, media.channel_value(tr, channel), 0.0)


#: Rays per emitter that ``emitter_media`` walks (a fixed seed: the same media every render).
EMITTER_RAYS = 4096
#: Surfaces a walk passes at most (a medium transition or an opaque surface ends it sooner).
_WALK_STEPS = 64


def emitter_media(scene: mi.Scene, sensor: mi.Sensor, floor: float, plugin: str) -> mi.MediumPtr:
    """The medium each emitter of ``scene`` sits in (one per ``scene.emitters()`` entry, in that
    order; gathered by emitter index): where every light subpath from it starts.

    An emitter's medium is a property of the emitter, decided once per render, not per ray:
    the medium the scene names for it, or for an area light whose shape is a medium transition
    its shape's exterior (the side it emits to); else the media that ``EMITTER_RAYS`` of its own
    emitted rays find (``first_transition``: non-transition surfaces that transmit light are
    passed, an opaque one ends a ray with no answer, the first medium transition answers with
    its side the ray came from). They must all agree (else a one-line ValueError naming the
    emitter); with none, the sensor's medium (volpath's: a path keeps its first medium until it
    crosses a transition)."""
    media = dr.zeros(mi.MediumPtr, max(1, len(scene.emitters())))
    rng = mi.PCG32(EMITTER_RAYS)
    time = mi.Float(sensor.shutter_open())
    for i, emitter in enumerate(scene.emitters()):
        medium = emitter.get_medium()
        shape = emitter.get_shape()
        if medium is None and shape is not None and shape.is_medium_transition():
            medium = shape.exterior_medium()
        elif medium is None:
            u = [rng.next_float32() for _ in range(5)]
            ray, _ = emitter.sample_ray(time, u[0], mi.Point2f(u[1], u[2]), mi.Point2f(u[3], u[4]))
            voted, found = first_transition(scene, ray, floor)
            votes = [(m, dr.count(voted & (found == mi.MediumPtr(m)))[0]) for m in _scene_media(scene, sensor)]
            votes = [(m, n) for m, n in votes if n > 0]
            if len(votes) > 1:
                named = ", ".join(f"{n} in {_medium_name(m)}" for m, n in votes)
                name = f"'{emitter.id()}'" if emitter.id() else f"number {i}"
                raise ValueError(f"{plugin}: emitter {name} is in more than one medium: of "
                                 f"{EMITTER_RAYS} of its rays, the first medium boundary each meets puts it "
                                 f"{named}; name its medium in the scene (<ref id=\"...\"/> inside the emitter)")
            medium = votes[0][0] if votes else sensor.get_medium()
        if medium is not None:
            dr.scatter(media, mi.MediumPtr(medium), mi.UInt32(i))
    return media


def start_medium(emitter_media, emitter_index, infinite):
    """(medium, extinguished) of light subpaths (photons) from emitter ``emitter_index``: the
    medium it sits in (``emitter_media``'s, gathered), and whether they carry nothing: an emitter
    at infinity in a homogeneous medium (an environment in the sensor's unbounded fog), whose light
    crosses an infinite stretch of it, T = 0. A heterogeneous medium is empty outside its grid, so
    its light arrives, T tracked through the grid, as next-event estimation's shadow rays see it
    (``media.transmittance``)."""
    medium = dr.gather(mi.MediumPtr, emitter_media, emitter_index)
    inside = infinite & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
    return medium, inside & medium.is_homogeneous()


@dr.syntax
def first_transition(scene: mi.Scene, ray: mi.Ray3f, floor: float) -> tuple[mi.Bool, mi.MediumPtr]:
    """(found, medium): the medium on ``ray``'s side of the first medium transition it meets,
    passing surfaces that are no transition and transmit light (a null or glass boundary
    between two points in one medium: every path crossing it keeps its medium), and stopping
    without one (``found`` False) at an opaque surface, whose far side may hold any medium (a
    lamp housing's wall), or where it leaves the scene."""
    ray = mi.Ray3f(ray)
    found = dr.zeros(mi.Bool, dr.width(ray.o))
    medium = dr.zeros(mi.MediumPtr, dr.width(ray.o))
    going = dr.full(mi.Bool, True, dr.width(ray.o))
    steps = mi.UInt32(0)
    while going:
        si = scene.ray_intersect(ray, mi.RayFlags.All, coherent=False, active=going)
        hit = going & si.is_valid()
        transition = hit & si.is_medium_transition()
        found |= transition
        medium[transition] = si.target_medium(-ray.d)
        steps += 1
        going = (hit & ~transition & mi.has_flag(si.bsdf().flags(), mi.BSDFFlags.Transmission)
                 & (steps < _WALK_STEPS))
        ray[going] = spawn.spawn_ray(si, ray.d, floor)
    return found, medium


def _scene_media(scene: mi.Scene, sensor: mi.Sensor) -> list:
    """No medium (None), then every medium the scene's shapes, sensor and emitters name."""
    found = [None]
    named = [sensor.get_medium(), *(e.get_medium() for e in scene.emitters())]
    for shape in scene.shapes():
        named += [shape.interior_medium(), shape.exterior_medium()]
    for m in named:
        if m is not None and not any(dr.all(mi.MediumPtr(m) == mi.MediumPtr(f)) for f in found):
            found.append(m)
    return found


def _medium_name(medium) -> str:
    return "no medium" if medium is None else f"medium '{medium.id()}'"


#: The optical depth past which the stand-in transmittance stops falling: 1 / T_det enters the
#: weights squared (power heuristic) and once per segment, and must stay within float range.
TAU_CAP = 10.0


class Tracking:
    """A scene with heterogeneous media: lab_bdpt's subpaths sample distances in them by delta
    tracking (``common.media.free_flight``) against ``grid`` (a ``majorants.MajorantGrid``) or,
    where None, the media's global majorants."""

    def __init__(self, grid=None):
        self.grid = grid


def stand_in(medium, start, end, wavelengths, channel, active):
    """The deterministic stand-in for the transmittance, in ``channel``, of the straight piece
    ``start``-``end`` inside the heterogeneous ``medium``: exp(-L sigma_t,c(midpoint)) over the part
    of the piece inside the medium's grid (L its length; outside its grid the medium is empty),
    its optical depth capped at TAU_CAP. Symmetric in its ends, so both subpaths and every
    connection give a segment the same value; a piece towards an emitter at infinity has the same
    value whether it ends where it leaves the grid or at Mitsuba's stand-in distance beyond."""
    length = dr.norm(end - start)
    piece = mi.Ray3f(start, (end - start) / dr.maximum(length, 1e-30))
    hit, t0, t1 = medium.intersect_aabb(piece)
    t0 = dr.clip(t0, 0.0, length)
    t1 = dr.clip(t1, 0.0, length)
    inside = dr.select(hit, dr.maximum(t1 - t0, 0.0), 0.0)
    mei = dr.zeros(mi.MediumInteraction3f)
    mei.p, mei.wavelengths = piece(0.5 * (t0 + t1)), wavelengths
    tau = inside * sigma_t_channel(medium, mei, channel, active & (inside > 0))
    tau = dr.select(dr.isfinite(tau), dr.minimum(tau, TAU_CAP), TAU_CAP)
    return dr.select(active, dr.exp(-tau), 1.0)


def tracked_flight(medium, ray: mi.Ray3f, t_max, sampler, channel, active, tracking: Tracking, exact):
    """``homogeneous_flight``'s (mei, scattered, weight, T_c) with, in the ``active`` lanes (a
    heterogeneous medium), ``exact`` replaced by delta tracking: ``common.media.free_flight``'s
    collision and weight (unbiased: T / p per channel, sigma_s at the collision), and for the MIS
    weights ``stand_in`` of the piece flown in place of T_c, the unknown escape probability."""
    mei, scattered, weight, T_c = exact
    mei_h, scattered_h, weight_h, _, _ = media.free_flight(medium, ray, t_max, sampler, channel, active,
                                                           tracking.grid)
    end = dr.select(scattered_h, mei_h.p, ray(media.within_grid(medium, ray, t_max, active)))
    mei[active] = mei_h
    scattered = dr.select(active, scattered_h, scattered)
    weight = dr.select(active, weight_h, weight)
    T_c = dr.select(active, stand_in(medium, ray.o, end, ray.wavelengths, channel, active), T_c)
    return mei, scattered, weight, T_c


def flight(medium, ray, t_max, u, sampler, channel, active, tracking):
    """A free flight (mei, scattered, weight, T_c for the weights): ``homogeneous_flight``, and
    in a scene with heterogeneous media (``tracking``) delta tracking in their lanes."""
    if tracking is None:
        return homogeneous_flight(medium, ray, t_max, u, channel, active)
    tracked = active & ~medium.is_homogeneous()
    exact = homogeneous_flight(medium, ray, t_max, u, channel, active & ~tracked)
    return tracked_flight(medium, ray, t_max, sampler, channel, tracked, tracking, exact)


def transmittance(scene, medium, it, target, sampler, channel, floor, active, tracking, unbounded=None):
    """(T, T_c for the weights) from ``it`` to ``target`` (``common.media.transmittance``): T_c
    T's own value in ``channel`` in homogeneous media (exact), else with ``stand_in`` for the
    pieces in heterogeneous media, while T is ratio tracking's unbiased estimate. A surface on a
    passed null face's plane blocks, as the subpaths meet it (``spawn.behind_null_face``).
    ``unbounded``: the lanes whose target is an emitter at infinity (``media.transmittance``)."""
    if tracking is None:
        T = media.transmittance(scene, medium, it, target, sampler, channel, floor, active, coplanar=True,
                                unbounded=unbounded)
        return T, media.channel_value(T, channel)
    return media.transmittance(scene, medium, it, target, sampler, channel, floor, active, grid=tracking.grid,
                               stand_in=stand_in, coplanar=True, unbounded=unbounded)


def sigma_t_channel(medium, mei, channel, active):
    """sigma_t of ``medium`` at ``mei``'s point in the sampling channel."""
    _, _, sigma_t = medium.get_scattering_coefficients(mei, active)
    return media.channel_value(sigma_t, channel)


def phase_reverse_pdf(phase, ctx, mei, wo, active):
    """The phase function's density of ``mei.wi`` given the direction ``wo`` (world): the
    direction back along a subpath, as the other side samples it."""
    rev = mi.MediumInteraction3f(mei)
    rev.wi = wo
    rev.sh_frame = mi.Frame3f(wo)
    return phase.eval_pdf(ctx, rev, mei.wi, active)[1]


def medium_vertex(mei, wavelengths) -> mi.SurfaceInteraction3f:
    """A medium vertex as a SurfaceInteraction3f for the shared code (its position, time and
    wavelengths; normal 0, so rays leave it without an offset)."""
    v = dr.zeros(mi.SurfaceInteraction3f)
    v.p, v.t, v.time, v.wavelengths = mei.p, mei.t, mei.time, wavelengths
    v.wi = mei.wi
    return v


class Sides:
    """The media on the two sides of a subpath vertex: ``medium`` on the side it was reached
    from (the only one at a medium vertex, where ``scattered``), ``beyond`` on the other (a
    medium transition's other side; else the same)."""
    DRJIT_STRUCT = {"n": mi.Vector3f, "arrival": mi.Float, "scattered": mi.Bool, "medium": mi.MediumPtr,
                    "beyond": mi.MediumPtr}

    def __init__(self, n=None, arrival=None, scattered=None, medium=None, beyond=None):
        self.n, self.arrival, self.scattered, self.medium, self.beyond = n, arrival, scattered, medium, beyond

    def toward(self, d):
        """The medium a ray leaving the vertex along ``d`` travels in (``arrival``: the cosine of
        the direction the vertex was reached along, the incoming ray's)."""
        return dr.select(self.scattered | (dr.dot(self.n, d) * self.arrival < 0), self.medium, self.beyond)


def vertex_eval(ctx, ctx_rev, phase_ctx, si, bsdf, mei, phase, scattered, wo_world, active):
    """(f, p_W forward, p_W reverse) at a subpath vertex towards ``wo_world``: its BSDF's
    (cosine included) at a surface, its phase function's where ``scattered``; ``ctx``: the
    subpath's transport mode, ``ctx_rev`` the other side's."""
    on_surface = active & ~scattered
    wo = si.to_local(wo_world)
    f_s, pdf_s = bsdf.eval_pdf(ctx, si, wo, on_surface)
    si_rev = mi.SurfaceInteraction3f(si)
    si_rev.wi = wo
    rev_s = bsdf.pdf(ctx_rev, si_rev, si.wi, on_surface)
    in_medium = active & scattered
    f_p, pdf_p = phase.eval_pdf(phase_ctx, mei, wo_world, in_medium)
    rev_p = phase_reverse_pdf(phase, phase_ctx, mei, wo_world, in_medium)
    return (dr.select(scattered, mi.Spectrum(f_p), f_s), dr.select(scattered, pdf_p, pdf_s),
            dr.select(scattered, rev_p, rev_s))


# ------------------------------------------------------------------------------------------
# Light subpaths
# ------------------------------------------------------------------------------------------
