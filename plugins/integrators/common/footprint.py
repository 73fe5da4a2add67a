"""A pixel's footprint in the scene: the default merging radius of lab_vcm and lab_photon where
light vertices are dense enough (``density_radius.first_radius`` takes a larger one where a probe
light pass finds them sparse at the median pixel; this module's probe pixels are its too).

Merging blurs light over a disc of radius r; a disc about one pixel wide where the camera
looks is as much blur as the film can show, so the first radius is the median, over a grid of
pixels, of the distance between the first camera hits of a pixel's centre ray and of its
neighbour's ray (the ray differential one pixel to the side, carried to the same distance).
Surfaces with a null BSDF alone (a medium's boundary, index-matched: nothing is seen or merged
there) are passed through: in fog the first hit is what lies behind the fog's box, not its walls.
This follows the film (resolution, crop) and the sensor (field of view, orthographic width,
thin lens: the lens centre's ray) instead of a number per scene. Rays that leave the scene
are skipped; when every ray leaves, the scene's bounding-box diagonal over the film's larger
side is used.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

#: at most this many pixels per film side are probed (a grid of pixel centres)
PROBES_PER_SIDE = 32
#: at most this many null-BSDF surfaces (medium boundaries) a probe ray passes through
NULL_CROSSINGS = 8


def bbox_radius(scene: mi.Scene, sensor: mi.Sensor) -> float:
    """The scene's bounding-box diagonal over the film's larger side (the fallback)."""
    bbox = scene.bbox()
    diag = float(dr.norm(bbox.max - bbox.min)) if bbox.valid() else 1.0
    size = sensor.film().crop_size()
    return max(diag, 1e-6) / max(int(size[0]), int(size[1]), 1)


def is_null(bsdf) -> mi.Bool:
    """Whether the BSDF has a null lobe and nothing else (a medium's index-matched boundary)."""
    flags = bsdf.flags()
    # (BSDFFlags.Delta holds Null too)
    scatters = (mi.BSDFFlags.Smooth, mi.BSDFFlags.DeltaReflection, mi.BSDFFlags.DeltaTransmission,
                mi.BSDFFlags.Delta1D)
    null = mi.has_flag(flags, mi.BSDFFlags.Null)
    for lobe in scatters:
        null &= ~mi.has_flag(flags, lobe)
    return null


def first_hits(scene: mi.Scene, sensor: mi.Sensor):
    """The probe pixels' centre rays carried to the first surface the camera sees (through
    null-BSDF surfaces): (surface interactions, each pixel's width there; both Dr.Jit arrays,
    one lane per probe pixel, a grid of at most PROBES_PER_SIDE per film side)."""
    film = sensor.film()
    size = np.array(film.crop_size(), dtype=np.int64)
    offset = np.array(film.crop_offset(), dtype=np.int64)
    full = np.array(film.size(), dtype=np.float64)
    axes = [(np.arange(min(n, PROBES_PER_SIDE)) + 0.5) * n / min(n, PROBES_PER_SIDE) for n in size]
    px, py = np.meshgrid(axes[0] + offset[0], axes[1] + offset[1], indexing="xy")
    pos = mi.Point2f(mi.Float(px.ravel() / full[0]), mi.Float(py.ravel() / full[1]))
    n = dr.width(pos)
    ray, _ = sensor.sample_ray_differential(dr.zeros(mi.Float, n), dr.full(mi.Float, 0.5, n), pos,
                                            mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(mi.Ray3f(ray))
    t = mi.Float(si.t)
    for _ in range(NULL_CROSSINGS):
        # a null BSDF alone is a medium's boundary, not a surface the camera sees: go on through it
        crossing = si.is_valid() & is_null(si.bsdf())
        if not dr.any(crossing):
            break
        si_next = scene.ray_intersect(si.spawn_ray(ray.d), crossing)
        t = dr.select(crossing, t + si_next.t, t)
        si[crossing] = si_next
    # a pixel's neighbour ray, carried to the centre ray's hit distance (ray differentials are one pixel apart)
    dx = (ray.o_x + ray.d_x * t) - (ray.o + ray.d * t)
    dy = (ray.o_y + ray.d_y * t) - (ray.o + ray.d * t)
    return si, dr.sqrt(dr.maximum(dr.norm(dx) * dr.norm(dy), 0.0))


def pixel_footprint(scene: mi.Scene, sensor: mi.Sensor, hits=None) -> float:
    """Median width of one pixel at the first surfaces the camera sees, in scene units (``hits``:
    ``first_hits``'s answer, if the caller has it)."""
    si, width = hits or first_hits(scene, sensor)
    valid = np.array(si.is_valid() & dr.isfinite(width) & (width > 0))
    widths = np.array(width)[valid]
    if widths.size == 0:
        return bbox_radius(scene, sensor)
    return float(np.median(widths))
