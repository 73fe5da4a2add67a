"""Scale-robust ray offsets: where a ray leaving a surface starts.

A hit point is known only to floating-point precision, so a ray leaving it starts a little
off the surface, along the normal, to avoid hitting the surface it left. Mitsuba 3.9 offsets by

    (1 + max_i |p_i|) * eps_ray,    eps_ray = 1500 * 2^-24 = 8.9e-5,

which is relative to the point's magnitude far from the origin but an absolute 8.9e-5 near
it: in a scene 2e-4 across (``scenes/stiff/scaled_1e-4.xml``) that is half the scene, and
rays leak through walls and miss corners (every Mitsuba integrator renders it about 8% dark).

The rounding error of a hit point is proportional to the magnitude of the coordinates it was
computed from (pbrt-v4 bounds it per intersection; Pharr et al., *Physically Based Rendering*,
4th ed., sec. 6.8), so the lab replaces the absolute 1 by the scene's own coordinate scale s,
capped at 1:

    (s + max_i |p_i|) * eps_ray,    s = min(1, largest |coordinate| of the scene's bounding box).

A scene of ordinary size (s = 1, e.g. the Cornell box) gets exactly Mitsuba's offsets, the same
rays and the same image; a tiny scene gets offsets that shrink with it, so its image does not
depend on its scale. Shadow rays stop short of their target by the same relative amount
(1 - 10 eps_ray) of their length as Mitsuba's.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Mitsuba's RayEpsilon for single precision (1500 float32 ulps of 1), and ShadowEpsilon.
RAY_EPSILON = 1500 * 2.0 ** -24
SHADOW_EPSILON = 10 * RAY_EPSILON


def offset_floor(traits) -> float:
    """s: the scene's coordinate scale, capped at 1 (1 when the scene has no extent).
    ``traits``: the scene's ``SceneTraits``."""
    scale = max(abs(v) for v in (*traits.bbox_min, *traits.bbox_max))
    return min(1.0, scale) if scale > 0 and scale == scale else 1.0


def offset_point(it: mi.Interaction3f, d: mi.Vector3f, floor: float) -> mi.Point3f:
    """The origin of a ray leaving ``it`` in direction ``d``: ``it.p`` moved along the normal,
    to the side ``d`` points to, by (floor + max|p|) eps_ray (not differentiated)."""
    mag = (floor + dr.max(dr.abs(it.p))) * RAY_EPSILON
    mag = dr.detach(dr.mulsign(mag, dr.dot(it.n, d)))
    return dr.fma(mag, dr.detach(it.n), it.p)


def offset_from_emitted(ps: mi.PositionSample3f, d: mi.Vector3f, floor: float) -> mi.Point3f:
    """``offset_point`` for a ray leaving an emitter's sampled point ``ps`` (an area light's
    ``sample_position``) in direction ``d``."""
    it = dr.zeros(mi.Interaction3f)
    it.p, it.n = ps.p, ps.n
    return offset_point(it, d, floor)


def spawn_ray(it: mi.Interaction3f, d: mi.Vector3f, floor: float) -> mi.Ray3f:
    """A ray leaving ``it`` in direction ``d`` (unbounded)."""
    return mi.Ray3f(offset_point(it, d, floor), d, it.time, it.wavelengths)


def spawn_ray_to(it: mi.Interaction3f, target: mi.Point3f, floor: float) -> mi.Ray3f:
    """A ray from ``it`` towards ``target``, stopping just short of it (for visibility tests)."""
    origin = offset_point(it, target - it.p, floor)
    d = target - origin
    dist = dr.norm(d)
    return mi.Ray3f(origin, d / dist, dist * (1.0 - SHADOW_EPSILON), it.time, it.wavelengths)


def sample_visible_emitter(scene: mi.Scene, it: mi.Interaction3f, sample: mi.Point2f, floor: float,
                           active) -> tuple[mi.DirectionSample3f, mi.Spectrum]:
    """``scene.sample_emitter_direction`` with the visibility test done by a shadow ray from
    ``spawn_ray_to``: an occluded sample has weight 0 and pdf 0, as Mitsuba's."""
    ds, weight = scene.sample_emitter_direction(it, sample, False, active)
    test = active & (ds.pdf != 0)
    occluded = scene.ray_test(spawn_ray_to(it, ds.p, floor), test)
    weight = dr.select(occluded, 0.0, weight)
    ds.pdf = dr.select(occluded, 0.0, ds.pdf)
    return ds, weight


@dr.syntax
def pass_through_emitters(scene: mi.Scene, ray: mi.Ray3f, pi: mi.PreliminaryIntersection3f, active,
                          floor: float) -> tuple[mi.Ray3f, mi.PreliminaryIntersection3f]:
    """(ray, first intersection) of camera rays that pass through the area emitters they hit
    (``hide_emitters``, Mitsuba's meaning); ``pi`` is the camera ray's first intersection."""
    through = active & pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711 (Dr.Jit pointer test)
    while through:
        si = pi.compute_surface_interaction(ray, mi.RayFlags.Minimal, through)
        ray = spawn_ray(si, ray.d, floor)
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=through)
        through &= pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711
    return ray, pi


def behind_null_face(scene: mi.Scene, ray: mi.Ray3f, si: mi.SurfaceInteraction3f, floor: float,
                     active) -> mi.SurfaceInteraction3f:
    """``si`` (``ray``'s hit), or where it is a surface with a null lobe and another surface lies
    on its far side within the offset a ray passing it would start at (a fog box's null face on
    the floor's plane), that other surface, met along ``ray`` (``wi`` and ``t`` from ``ray``).

    The two surfaces tie to rounding; a ray that meets the null face first and then starts past
    the offset would leave through the floor. A probe from that offset back to the face, along
    its normal, meets whichever of the two lies nearer that side: the other one, where the ray
    met the null face first by the surfaces' rounding (the floor's tilt), so both directions see
    the same floor."""
    probe_on = active & si.is_valid() & mi.has_flag(si.bsdf().flags(), mi.BSDFFlags.Null)
    origin = offset_point(si, ray.d, floor)
    back = dr.mulsign(si.n, -dr.dot(si.n, ray.d))          # the normal, towards the side the ray came from
    probe = mi.Ray3f(origin, back, 2.0 * dr.norm(origin - si.p), si.time, si.wavelengths)
    other = scene.ray_intersect(probe, mi.RayFlags.All, coherent=False, active=probe_on)
    found = probe_on & other.is_valid() & (other.shape != si.shape)
    other.wi = other.to_local(-ray.d)
    other.t = si.t
    return dr.select(found, other, si)
