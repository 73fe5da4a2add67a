"""Aimed emission: a share of the directions an area light emits, sent at chosen shapes.

Light reaches a caustic only through the specular shape that focuses it, and from a light
that shape often fills a small solid angle (scenes/sds.xml's glass sphere: 0.14 sr, about 1%
of what a sphere light emits), so most light subpaths never make a caustic vertex. Jensen's
photon maps emit caustic photons through a *projection map* of the directions that reach
the specular objects; this is its simplest form. From the emitted point y, with probability
``share`` the direction is uniform in the cone that the bounding sphere (centre c_k, radius
R_k) of one target shape subtends (the target chosen uniformly among K), otherwise
cosine-weighted, as Mitsuba's ``sample_ray`` draws it:

    p(d | y) = (1 - s(y)) max(cos, 0) / pi + s(y) / K(y) sum_{k aimed at from y} [d in cone_k(y)] / (2 pi (1 - cos theta_k))

with cos theta_k = sqrt(1 - R_k^2 / |c_k - y|^2). A target is aimed at from y only when its cone
is narrower than 60 degrees (cos theta_k >= 1/2, under pi sr): over a wider cone the aimed
density s / (K 2 pi (1 - cos theta_k)) is at most s / pi, no more than cosine emission already
gives those directions (up to 1 / pi), while the aim takes that share from every other
direction. So a light inside a target's bounding sphere (light_in_glass.xml: the whole sphere of
directions) or close to a large one (sds.xml's pane fills 5 sr from the light) does not aim at
it. K(y) counts the targets aimed at from y, and s(y) = share when K(y) > 0, else 0 (the light
then emits as Mitsuba samples it). The emitted weight Le cos / (p_pos p(d | y)) stays exact for any
share < 1, because the cosine part still covers every direction the light emits into; BDPT's
and VCM's MIS weights use this p(d | y) wherever they need the emission density of an area
light (``endpoints.EmitterTable.emission``). Other emitters (point, spot, at infinity) emit
as Mitsuba samples them.

Targets: ``"specular"`` takes every non-emitting shape whose BSDF has only delta lobes
(smooth glass, mirrors, thin dielectrics); otherwise a comma-separated list of shape ids.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np


def _is_specular(shape) -> bool:
    """Only delta lobes, at least one that changes direction (a ``null`` BSDF passes light unchanged)."""
    bsdf = shape.bsdf()
    if bsdf is None:
        return False
    flags = bsdf.flags()
    delta = mi.has_flag(flags, mi.BSDFFlags.DeltaReflection) or mi.has_flag(flags, mi.BSDFFlags.DeltaTransmission)
    return delta and not mi.has_flag(flags, mi.BSDFFlags.Smooth)


def bounding_sphere(shape) -> tuple[list[float], float]:
    """(centre, radius) of a sphere around ``shape``: a ``sphere`` itself; a mesh's vertices around
    their box's centre; otherwise the sphere around the bounding box (sqrt(3) times a sphere's
    radius, so three times the solid angle)."""
    if shape.class_name() == "Sphere":
        m = np.array(mi.traverse(shape)["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        return m[:3, 3].tolist(), float(max(np.linalg.norm(m[:3, i]) for i in range(3)))
    if shape.is_mesh():
        p = np.array(shape.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
        if len(p):
            c = (p.min(axis=0) + p.max(axis=0)) / 2.0
            return c.tolist(), float(np.sqrt(((p - c) ** 2).sum(axis=1).max()))
    sphere = shape.bbox().bounding_sphere()
    return [float(v) for v in sphere.center], float(sphere.radius)


def target_shapes(scene: mi.Scene, targets: str, plugin: str) -> list:
    """The shapes ``targets`` names in ``scene`` ("specular" or comma-separated ids); ValueError
    naming the first unknown id."""
    shapes = [s for s in scene.shapes() if not s.is_emitter()]
    if targets.strip() == "specular":
        return [s for s in shapes if _is_specular(s)]
    by_id = {s.id(): s for s in shapes if s.id()}
    chosen = []
    for name in (t.strip() for t in targets.split(",")):
        if name not in by_id:
            known = ", ".join(sorted(by_id)) or "none"
            raise ValueError(f"{plugin}: parameter 'aim_at' names shape '{name}', which the scene does not have "
                             f"(shapes with an id, emitters excluded: {known})")
        chosen.append(by_id[name])
    return chosen


class AimedEmission:
    """The mixture above for one scene; ``enabled`` is False when ``share`` is 0 or no shape is a
    target (the light then emits exactly as before, with the same random numbers)."""

    #: a target is aimed at from y only when its cone's cos theta_k is at least this (module docstring)
    COS_NARROWEST = 0.5

    def __init__(self, scene: mi.Scene, share: float, targets: str = "specular", plugin: str = "lab_vcm"):
        spheres = []
        if share > 0:
            # (a little larger than the shape: the cone must hold every direction that reaches it)
            spheres = [(c, r * 1.0001 + 1e-6) for c, r in map(bounding_sphere, target_shapes(scene, targets, plugin))]
        self.share = float(share)
        self.spheres = spheres
        self.enabled = bool(spheres)

    def _cone(self, y, center, radius):
        """(axis, cos theta_max, aimed at) of the bounding sphere seen from y: aimed at when y is
        outside it and the cone is narrow enough (``COS_NARROWEST``)."""
        to_c = center - y
        dist = dr.norm(to_c)
        outside = dist > radius
        cos_max = dr.safe_sqrt(1.0 - dr.square(radius / dr.maximum(dist, 1e-30)))
        axis = to_c / dr.maximum(dist, 1e-30)
        # (through the instance: switching variants reloads this module, and an object made
        # before then keeps its own class's value)
        return axis, cos_max, outside & (cos_max >= self.COS_NARROWEST)

    def _cones(self, y):
        """Every target's (axis, cos theta_max, aimed at) from y, and K(y), how many are aimed at."""
        cones = [self._cone(y, mi.Point3f(*center), radius) for center, radius in self.spheres]
        count = mi.UInt32(0)
        for _, _, aimed in cones:
            count += dr.select(aimed, 1, 0)
        return cones, count

    def _aimed_pdf(self, y, d):
        """s(y) / K(y) sum_{k aimed at from y} [d in cone_k(y)] / (2 pi (1 - cos theta_k))."""
        cones, count = self._cones(y)
        total = mi.Float(0.0)
        for axis, cos_max, aimed in cones:
            inside = aimed & (dr.dot(d, axis) >= cos_max)
            total += dr.select(inside, dr.rcp(2.0 * math.pi * (1.0 - cos_max)), 0.0)
        return total * self.share / dr.maximum(mi.Float(count), 1.0)

    def pdf(self, cos_out, y, d):
        """p(d | y): the emission direction density of an area light's point y in direction d, at
        |cos| ``cos_out`` to its normal."""
        _, count = self._cones(y)
        cosine_share = dr.select(count > 0, 1.0 - self.share, 1.0)
        return cosine_share * cos_out * dr.inv_pi + self._aimed_pdf(y, d)

    def sample(self, y, n, d_cosine, u_choice, u_cone, active=True):
        """(direction, weight factor) replacing ``d_cosine`` (the cosine-weighted direction Mitsuba
        drew at y, normal n): with probability s(y) a direction aimed at one of the K(y) targets
        aimed at from y; the factor (cos / pi) / p(d | y) turns the cosine sampling's weight into
        the mixture's (0 where the direction leaves below the surface, which the light does not
        emit into). Lanes not ``active`` (other emitters) keep their direction and a factor of 1."""
        cones, count = self._cones(y)
        aim = active & (count > 0) & (u_choice < self.share)
        # the j-th of the targets aimed at from y, j uniform in [0, K(y))
        j = dr.minimum(mi.UInt32(u_choice / self.share * mi.Float(count)), count - 1)
        axis, cos_max, seen = mi.Vector3f(0, 0, 1), mi.Float(1.0), mi.UInt32(0)
        for k_axis, k_cos, aimed in cones:
            pick = aimed & (seen == j)
            axis, cos_max = dr.select(pick, k_axis, axis), dr.select(pick, k_cos, cos_max)
            seen += dr.select(aimed, 1, 0)
        local = mi.warp.square_to_uniform_cone(u_cone, cos_max)
        d = dr.select(aim, mi.Frame3f(axis).to_world(local), d_cosine)
        cos = dr.dot(n, d)
        p = self.pdf(dr.maximum(cos, 0.0), y, d)
        factor = dr.select((cos > 0) & (p > 0), cos * dr.inv_pi / dr.maximum(p, 1e-30), 0.0)
        return dr.select(active, d, d_cosine), dr.select(active, factor, 1.0)
