"""The first merging radius where light vertices are sparse: lab_vcm's and lab_photon's default r_1.

A pixel's width (``footprint.pixel_footprint``) is as much blur as the film can show, but where
an iteration's light vertices are sparse a disc that small almost never holds one, and merging
renders the surface black for many iterations (a camera 1 cm above a wide floor, a huge light far
above a small stage). So the default r_1 is

    r_1 = max(footprint, min(r_density, cap))

r_density: a *probe* light pass (PROBE_LIGHT_SUBPATHS light subpaths from a fixed seed, emitters
chosen by power as the renders choose them, area lights' directions aimed as the plugin's ``aim``
and ``aim_at`` aim them) keeps its vertices at smooth surfaces, each standing for N / 2048 of a
render's N light subpaths per iteration (a quarter of it is traced first, and where that finds
r_density under half the footprint it is not traced whole; where it puts no vertex near the median
pixel, it is traced again with 4 times the subpaths, up to PROBE_MAX_LIGHT_SUBPATHS). At the first
camera hits with a smooth lobe of the footprint's probe pixels (every k-th of them, at most
MEDIAN_PIXELS), a nearest-neighbour estimate of the density of light vertices facing the hit's way
(normals within ``kernels.NORMAL_COS``, as merging accepts them) gives r_j, the radius of the disc
that holds K_EXPECTED vertices of one iteration; r_density is the median of r_j. cap: the diagonal
of the box around those camera hits over CAP_DIVISOR, so the blur stays a small part of what the
camera sees. Where light vertices are dense the footprint is the larger and nothing changes (every
scene of issue 17); where the cap is reached, merges at the median pixel find a light vertex less
often than once in 1 / K_EXPECTED iterations and the image stays noisy at small counts
(huge_dim_light.xml; aimed emission, ``aim_at`` the seen shapes, brings light subpaths there).
r_density is inf where even the largest probe puts no vertex near the median pixel.

The probe is counted work from a fixed seed: r_1 is a function of the scene, the plugin's
settings and the film, never of the render's seed or load. Approximations: probe light subpaths
take at most PROBE_SEGMENTS segments, with BSDF sampling and no roulette (renders use roulette
from ``rr_depth`` on and may go deeper: fewer vertices counted, a larger r_density); scenes with
participating media keep the footprint (the probe does not trace media: light that reaches a
surface only after scattering in fog would be missing from it); camera pixels whose first
surface has delta lobes alone (glass, mirrors: merging happens behind them) are left out of the
median; every smooth vertex counts (lab_vcm's ``merge_vertices = caustic`` merges with fewer), at
the plugin's ``light_paths`` (its pilot may choose more).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab.plugins.scene_traits import SceneTraits

from .footprint import NULL_CROSSINGS, first_hits, is_null, pixel_footprint
from .kernels import NORMAL_COS

#: light vertices of one iteration that the median probe pixel's disc should hold in expectation: a
#: merge there finds one about once in 64 iterations. The footprint holds 0.03-2 on the lab's scenes
#: where merging converges (sds.xml 0.03 in mode vcm, 0.06 in ppm; caustic.xml 0.12; the Cornell box
#: 1.5-1.9) and below 1e-5 on grazing_camera.xml (experiments/results/2026-11-29-ppm-density-radius.md)
K_EXPECTED = 1.0 / 64
#: light subpaths of the probe pass (its vertices are scaled to the render's subpaths per iteration)
PROBE_LIGHT_SUBPATHS = 2048
#: where the median probe pixel's disc holds no probe vertex, the probe is traced again with 4 times
#: the light subpaths, up to this many (huge_dim_light.xml: about 2e-4 of them reach the stage)
PROBE_MAX_LIGHT_SUBPATHS = 32768
#: at most this many segments per probe light subpath
PROBE_SEGMENTS = 4
#: the density at a camera hit is estimated from the nearest light vertices holding this many times
#: a probe vertex's mean weight (a k-nearest-neighbour estimate: about 25% error in the density)
PROBE_NEIGHBOURS = 16
#: the probe's fixed seed: the radius never depends on the render's seed
PROBE_SEED = 0x2C1B3C6D
#: r_density is at most the diagonal of the box around the probe's camera hits over this
CAP_DIVISOR = 8.0
#: r_density is the median over at most this many of the footprint's probe pixels (evenly strided)
MEDIAN_PIXELS = 256
#: probe pixels compared at once with every light vertex (bounds the distance matrix's memory)
_ROWS = 64


@dataclass
class FirstRadius:
    """The default r_1 and what made it: the pixel footprint, r_density (inf: not even the whole
    probe puts K_EXPECTED vertices near the median pixel), the cap, and the light vertices the
    probe stored."""
    radius: float
    footprint: float
    density: float
    cap: float
    probe_vertices: int

    @property
    def capped(self) -> bool:
        return self.density > self.cap


def _channel_mean(spectrum):
    value = mi.unpolarized_spectrum(spectrum)
    total = value[0]
    for i in range(1, len(value)):
        total = total + value[i]
    return total * (1.0 / len(value))


def light_vertices(scene: mi.Scene, max_segments: int, first_segment: int = 1, aim=None,
                   subpaths: int = PROBE_LIGHT_SUBPATHS):
    """The probe's light vertices at smooth surfaces: (points (V, 3), normals (V, 3), weights (V,)),
    a vertex's weight the expected count of such vertices per light subpath of the render that
    it stands for (its emitter's selection probability by power over the probe's rays from it).
    Every emitter gets an equal share of the probe's lanes, all traced in one wavefront."""
    emitters = scene.emitters()
    empty = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    if not emitters or max_segments < first_segment:
        return empty
    per_emitter = max(1, subpaths // len(emitters))
    n = per_emitter * len(emitters)
    lane = dr.arange(mi.UInt32, n)
    index = lane // per_emitter
    rng = mi.PCG32(n)
    rng.seed(mi.sample_tea_64(mi.UInt32(PROBE_SEED), lane), mi.UInt64(PROBE_SEED))
    emitter = dr.gather(mi.EmitterPtr, scene.emitters_dr(), index)
    time = mi.Float(0.0)
    u_wavelength = rng.next_float32()
    sample2 = mi.Point2f(rng.next_float32(), rng.next_float32())
    sample3 = mi.Point2f(rng.next_float32(), rng.next_float32())
    ray, weight = emitter.sample_ray(time, u_wavelength, sample2, sample3)
    u_choice = rng.next_float32()
    u_cone = mi.Point2f(rng.next_float32(), rng.next_float32())
    if aim is not None and aim.enabled:
        # area lights' directions drawn as the plugin's aimed emission draws them (the same point again)
        area = mi.has_flag(emitter.flags(), mi.EmitterFlags.Surface)
        ps, _ = emitter.sample_position(time, sample2, area)
        d, factor = aim.sample(ps.p, ps.n, ray.d, u_choice, u_cone, area)
        ray = mi.Ray3f(ray.o, d, ray.time, ray.wavelengths)
        weight = weight * factor
    value = _channel_mean(weight)
    finite = dr.isfinite(value)
    # each emitter's power: the mean of its rays' weights (Phi_e per ray), as the renders choose by it
    values = np.array(dr.select(finite, value, 0.0), dtype=np.float64).reshape(len(emitters), per_emitter)
    powers = np.maximum(values.mean(axis=1), 0.0)
    pmf = powers / powers.sum() if powers.sum() > 0 else np.full(len(emitters), 1.0 / len(emitters))
    # one symbolic loop (one kernel: a few tenths of a second to compile); vertex (lane, segment) of
    # each lane goes to its own slot of ``store``: position and normal, NaN where there is none
    store = dr.full(mi.Float, math.nan, n * max_segments * 6)
    ctx = mi.BSDFContext(mi.TransportMode.Importance)

    def alive(active, depth, steps, ray, rng):
        return active & (steps < max_segments + NULL_CROSSINGS)

    def step(active, depth, steps, ray, rng):
        si = scene.ray_intersect(ray, active)
        active &= si.is_valid()
        bsdf = si.bsdf(ray)
        crossing = active & is_null(bsdf)      # a medium's boundary: no vertex, no segment
        scatters = active & ~crossing
        depth = dr.select(scatters, depth + 1, depth)
        keep = scatters & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth) & (depth >= first_segment)
        slot = (lane * max_segments + depth - 1) * 6
        for k in range(3):
            dr.scatter(store, si.p[k], slot + k, keep)
            dr.scatter(store, si.n[k], slot + 3 + k, keep)
        bs, bsdf_weight = bsdf.sample(ctx, si, rng.next_float32(),
                                      mi.Point2f(rng.next_float32(), rng.next_float32()), scatters)
        value = _channel_mean(bsdf_weight)
        goes_on = scatters & dr.isfinite(value) & (value > 0) & (depth < max_segments)
        ray = si.spawn_ray(dr.select(crossing, ray.d, si.to_world(bs.wo)))
        return goes_on | crossing, depth, steps + 1, ray, rng

    dr.while_loop((finite & (value > 0), mi.UInt32(0), mi.UInt32(0), ray, rng), alive, step)
    slots = np.array(store, dtype=np.float64).reshape(-1, 6)
    found = np.flatnonzero(np.isfinite(slots[:, 0]))
    weights = pmf[found // max_segments // per_emitter] / per_emitter
    return slots[found, :3], slots[found, 3:], weights


def density_radii(hits, hit_normals, points, normals, weights, need: float) -> np.ndarray:
    """Per camera hit, the radius whose disc holds light vertices (facing the hit's way) of total
    weight ``need`` in expectation: a nearest-neighbour density estimate from the smallest ball
    holding weight T = PROBE_NEIGHBOURS mean weights (or ``need``, if more; or all there is, if
    less), scaled as the area of a disc, r_T sqrt(need / T); inf where all of them hold less than
    ``need``."""
    radii = np.full(len(hits), np.inf)
    if len(points) == 0:
        return radii
    target = max(need, PROBE_NEIGHBOURS * float(weights.mean()))
    nearest = min(len(points), 4 * PROBE_NEIGHBOURS)
    for start in range(0, len(hits), _ROWS):
        h, hn = hits[start:start + _ROWS], hit_normals[start:start + _ROWS]
        # (coordinate by coordinate: no BLAS call, whose threads only wait on a busy machine)
        d2 = sum((h[:, k, None] - points[None, :, k]) ** 2 for k in range(3))
        d2[sum(hn[:, k, None] * normals[None, :, k] for k in range(3)) <= NORMAL_COS] = np.inf
        w = np.where(np.isfinite(d2), weights[None, :], 0.0)
        facing = w.sum(axis=1)                            # all the weight facing each hit's way
        held = np.minimum(target, facing)                 # T, or all of it
        # the nearest few vertices of each row in order (all of them where those hold less than ``held``)
        order = np.argpartition(d2, nearest - 1, axis=1)[:, :nearest] if nearest < len(points) else \
            np.tile(np.arange(len(points)), (len(h), 1))
        rows = np.arange(len(h))[:, None]
        order = np.take_along_axis(order, np.argsort(d2[rows, order], axis=1, kind="stable"), axis=1)
        total = np.cumsum(w[rows, order], axis=1)
        short = total[:, -1] < held * (1.0 - 1e-12)
        if short.any():
            full = np.argsort(d2[short], axis=1, kind="stable")
            r_short = np.zeros(int(short.sum()))
            cum = np.cumsum(np.take_along_axis(w[short], full, axis=1), axis=1)
            first = np.argmax(cum >= held[short, None] * (1.0 - 1e-12), axis=1)
            r_short = np.take_along_axis(d2[short], full[np.arange(len(full)), first][:, None], axis=1)[:, 0]
        first = np.argmax(total >= held[:, None] * (1.0 - 1e-12), axis=1)
        r2 = d2[rows[:, 0], order[rows[:, 0], first]]
        if short.any():
            r2[short] = r_short
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.sqrt(r2) * np.sqrt(need / held)
        radii[start:start + len(h)] = np.where(facing >= need * (1.0 - 1e-12), r, np.inf)
    return radii


def first_radius(scene: mi.Scene, sensor: mi.Sensor, light_subpaths: float, max_segments: int,
                 first_segment: int = 1, aim=None) -> FirstRadius:
    """The default r_1 (module docstring) for a render tracing ``light_subpaths`` light subpaths per
    iteration, each storing vertices from segment ``first_segment`` to ``max_segments``, emitted
    with ``aim`` (an ``aim.AimedEmission`` or None). In scenes with media, the footprint (r_density
    and the cap NaN: not probed)."""
    si, width = first_hits(scene, sensor)
    footprint = pixel_footprint(scene, sensor, (si, width))
    if SceneTraits.from_scene(scene).media:
        # (the probe does not trace media: in fog_lantern.xml the floor's photons after a bounce come
        # from the fog, and the probe would find none)
        return FirstRadius(footprint, footprint, math.nan, math.nan, 0)
    keep = np.array(si.is_valid() & mi.has_flag(si.bsdf().flags(), mi.BSDFFlags.Smooth))
    if not keep.any() or light_subpaths <= 0:
        return FirstRadius(footprint, footprint, 0.0, 0.0, 0)
    hits = np.array(si.p, dtype=np.float64).T[keep]
    hit_normals = np.array(si.n, dtype=np.float64).T[keep]
    cap = float(np.linalg.norm(hits.max(axis=0) - hits.min(axis=0))) / CAP_DIVISOR
    # every k-th of them, at most MEDIAN_PIXELS (the median needs no more; the count's cost is linear in them)
    step = -(-len(hits) // MEDIAN_PIXELS)
    hits, hit_normals = hits[::step], hit_normals[::step]
    subpaths = PROBE_LIGHT_SUBPATHS // 4
    while True:
        points, normals, weights = light_vertices(scene, min(max_segments, PROBE_SEGMENTS), first_segment, aim,
                                                  subpaths)
        density = float(np.median(density_radii(hits, hit_normals, points, normals, weights,
                                                 K_EXPECTED / light_subpaths)))
        # a quarter of the probe first: where it already finds r_density under half the footprint, the
        # footprint wins (the estimate's error is about 12% in r); otherwise the whole probe, and where
        # it puts no vertex near the median pixel, a larger one, to tell sparse from absent
        if math.isfinite(density) and (density < footprint / 2 or subpaths >= PROBE_LIGHT_SUBPATHS):
            break
        if subpaths >= PROBE_MAX_LIGHT_SUBPATHS:
            break
        subpaths *= 4
    return FirstRadius(max(footprint, min(density, cap)), footprint, density, cap, len(points))
