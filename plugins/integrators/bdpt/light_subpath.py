"""Light subpaths in one Dr.Jit symbolic loop, and the t = 1 strategy (light tracing).

Each lane traces one light subpath x_0, x_1, .. from an emitter (chosen with the scene's
emitter-sampling distribution, position and direction from ``Emitter.sample_ray``) with
adjoint BSDF sampling (``TransportMode.Importance``, Veach's shading-normal correction as in
``lab_photon``) and the lab's Russian roulette relative to the emitted throughput. Every vertex
is joined to the sensor (t = 1): ``Sensor.sample_direction`` gives the film position and the
importance W_e G / p, a shadow ray tests visibility, and

    splat = beta * f_s(x_i, x_{i-1} -> sensor) * W_e G / p * w_mis * sample_scale

is added to an ``ImageBlock`` at that film position. The emitter point itself (s = 1, t = 1) is
joined the same way with L_e(x_0 -> sensor) |cos| / p(x_0) in place of beta * f_s (a delta
position cannot be seen and is skipped, as Mitsuba's ``ptracer`` does).

``sample_scale`` = crop pixels / (spp * film pixels): with N = film pixels * spp light subpaths,
each carrying an estimate of the total emitted power, the splats of all N sum to spp times the
image, so each is scaled by 1 / spp (Mitsuba's ``AdjointIntegrator`` normalisation).

The MIS running quantities of ``weights.py`` (``SubpathMis``) are carried per vertex, and the
splat is multiplied by ``light_to_camera`` / ``emitter_to_camera``. With
``BdptWeights(strategies="light")`` every weight is 1; the plumbing is there for the full BDPT.
Densities the light-only weights do not depend on are simplified (see ``_emission_pdfs`` and
``_camera_pdf``); they must be made exact before other strategies are enabled.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators import spawn
from mitsuba_lab.plugins.integrators.photon.tracer import adjoint_correction
from mitsuba_lab.plugins.integrators.roulette import russian_roulette

from .weights import BdptWeights, SubpathMis


def _finite_or_zero(x):
    """x where finite, else 0 (a 0 * inf density ratio must not turn a splat into NaN)."""
    return dr.select(dr.isfinite(x), x, 0.0)


def _emission_pdfs(emitter, ps, pmf, cos_light):
    """(pdf_emit, pdf_nee, delta) of an emitted ray, as ``BdptWeights.start_light`` wants them.

    Exact for area emitters (cosine-weighted directions) and point lights (uniform sphere);
    other emitters get the cosine density too (only other strategies than "light" use it).
    """
    delta = mi.has_flag(emitter.flags(), mi.EmitterFlags.DeltaPosition)
    pdf_pos = dr.select(delta, 1.0, ps.pdf)
    pdf_nee = pmf * pdf_pos
    pdf_dir = dr.select(delta, 1.0 / (4.0 * math.pi), cos_light / math.pi)
    return pdf_nee * pdf_dir, pdf_nee, delta


def _camera_pdf(sensor_weight, dist2):
    """The sensor's direction density towards a vertex, up to a constant (W_e cos / 1, from the
    splat weight W_e cos / dist^2); only the light-only weights use it, where it cancels."""
    return dr.max(mi.unpolarized_spectrum(sensor_weight)) * dist2


class LightTracer:
    """Traces light subpaths for one scene and sensor and splats their t = 1 connections.

    ``max_depth``: longest path in segments, emitter to sensor (-1: unbounded; 1: emitters seen
    directly only; Mitsuba's meaning); ``rr_depth``: Russian roulette from this many light
    segments on; ``weights``: the MIS weights (default ``BdptWeights(strategies="light")``).
    """

    def __init__(self, scene: mi.Scene, sensor: mi.Sensor, max_depth: int = -1, rr_depth: int = 5,
                 weights: BdptWeights | None = None, offset_floor: float = 1.0):
        if not isinstance(max_depth, int) or max_depth < -1 or max_depth == 0:
            raise ValueError(f"lab_bdpt: max_depth must be -1 (unbounded) or >= 1, got {max_depth!r}")
        if not isinstance(rr_depth, int) or rr_depth < 1:
            raise ValueError(f"lab_bdpt: rr_depth must be an integer >= 1, got {rr_depth!r}")
        if mi.is_spectral or mi.is_polarized:
            # The s = 1 splat evaluates L_e at the subpath's wavelengths without their density.
            raise ValueError(f"lab_bdpt: light tracing supports RGB and mono variants only so far, "
                             f"not {mi.variant()}")
        if any(mi.has_flag(e.flags(), mi.EmitterFlags.Infinite) for e in scene.emitters()):
            raise ValueError("lab_bdpt: light tracing does not support infinite emitters (envmap, "
                             "constant, directional) yet")
        self.scene, self.sensor = scene, sensor
        self.max_depth = max_depth
        self.rr_depth = rr_depth
        self.weights = weights if weights is not None else BdptWeights(strategies="light")
        self.floor = offset_floor

    @staticmethod
    def _splat(block, ds, wavelengths, value, active):
        """Add ``value`` to ``block`` at the sensor sample's film position (weight channel 0:
        splats are not normalised per pixel, as in Mitsuba's ``ptracer``)."""
        pos = ds.uv + mi.Vector2f(block.offset())
        block.put(pos, wavelengths, value, dr.select(active, 1.0, 0.0), 0.0, active)

    def _visible(self, it, ds, active):
        """The sensor sample is usable and not occluded from ``it``."""
        active = active & (ds.pdf > 0)
        return active & ~self.scene.ray_test(spawn.spawn_ray_to(it, ds.p, self.floor), active)

    @dr.syntax
    def trace(self, count: int, seed: int, block: mi.ImageBlock, sample_scale: float):
        """Trace ``count`` light subpaths (PCG32 stream per lane from ``seed``) and splat every
        t = 1 connection into ``block``. Returns the number of surface vertices reached."""
        scene, sensor, w = self.scene, self.sensor, self.weights
        index = dr.arange(mi.UInt32, count)
        s = dr.opaque(mi.UInt32, seed & 0xFFFFFFFF)
        rng = mi.PCG32(count)
        rng.seed(mi.sample_tea_64(s, index), mi.sample_tea_64(index, s ^ 0x9E3779B9))
        scale = dr.opaque(mi.Float, sample_scale)

        # ---------------- x_0: emitter, position, direction ----------------
        emitter_index, sel_weight, _ = scene.sample_emitter(rng.next_float32())
        emitter = dr.gather(mi.EmitterPtr, scene.emitters_dr(), emitter_index)
        pmf = dr.select(sel_weight > 0, dr.rcp(sel_weight), 0.0)
        time = mi.Float(sensor.shutter_open())
        u_wav = rng.next_float32()
        sample_pos = mi.Point2f(rng.next_float32(), rng.next_float32())
        sample_dir = mi.Point2f(rng.next_float32(), rng.next_float32())
        ray, ray_weight = emitter.sample_ray(time, u_wav, sample_pos, sample_dir)
        # The same position sample gives x_0 again, with its area density and normal.
        ps, pos_weight = emitter.sample_position(time, sample_pos)
        delta_pos = mi.has_flag(emitter.flags(), mi.EmitterFlags.DeltaPosition)
        cos_emit = dr.select(delta_pos, 1.0, dr.abs(dr.dot(ps.n, ray.d)))
        pdf_emit, pdf_nee, delta = _emission_pdfs(emitter, ps, pmf, cos_emit)
        mis0 = w.start_light(pdf_emit, pdf_nee, cos_emit, delta)
        if dr.hint(self.floor < 1.0, mode="scalar"):
            # An area emitter's ray starts at Mitsuba's absolute offset: use the lab's instead.
            it0 = dr.zeros(mi.Interaction3f)
            it0.p, it0.n = ps.p, ps.n
            ray.o = dr.select(delta_pos, ray.o, spawn.offset_point(it0, ray.d, self.floor))

        # ---------------- s = 1, t = 1: the emitter point seen directly ----------------
        si0 = mi.SurfaceInteraction3f(ps, ray.wavelengths)
        active0 = ~delta_pos & (pmf > 0)
        ds0, we0 = sensor.sample_direction(si0, mi.Point2f(rng.next_float32(), rng.next_float32()), active0)
        active0 = self._visible(si0, ds0, active0)
        si0.wi = si0.to_local(ds0.d)
        cos0 = mi.Frame3f.cos_theta(si0.wi)
        active0 &= cos0 > 0
        le0 = emitter.eval(si0, active0)
        w0 = w.emitter_to_camera(_camera_pdf(we0, dr.square(ds0.dist)), cos0, dr.square(ds0.dist),
                                 pmf * ps.pdf, delta)
        value0 = le0 * cos0 * pos_weight * sel_weight * we0 * _finite_or_zero(w0) * scale
        self._splat(block, ds0, si0.wavelengths, value0, active0)

        # ---------------- x_1, x_2, ..: the light subpath ----------------
        beta = mi.Spectrum(ray_weight) * sel_weight
        beta_max0 = dr.max(mi.unpolarized_spectrum(beta))
        max_depth = dr.opaque(mi.UInt32, self.max_depth if self.max_depth > 0 else 0xFFFFFFFF)
        rr_depth = dr.opaque(mi.UInt32, self.rr_depth)
        ctx = mi.BSDFContext(mi.TransportMode.Importance)
        ctx_rad = mi.BSDFContext(mi.TransportMode.Radiance)
        dvcm, dvc, first = mi.Float(mis0.dvcm), mi.Float(mis0.dvc), mi.Float(mis0.first)
        depth = mi.UInt32(0)
        vertices = mi.UInt32(0)
        active = (beta_max0 > 0) & dr.isfinite(beta_max0) & (max_depth > 1)
        while dr.hint(active, max_iterations=-1, label="lab_bdpt light subpath"):
            si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False, active=active)
            active &= si.is_valid()
            depth += 1
            vertices += dr.select(active, 1, 0)
            cos_in = dr.abs(dr.dot(si.n, ray.d))
            mis = w.after_hit(SubpathMis(dvcm, dvc, first), dr.square(si.t), cos_in)
            bsdf = si.bsdf()
            wi_world = -ray.d

            # ---------- t = 1: join x_depth to the sensor ----------
            smooth = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            ds, we = sensor.sample_direction(si, mi.Point2f(rng.next_float32(), rng.next_float32()), smooth)
            connect = self._visible(si, ds, smooth)
            wo_cam = si.to_local(ds.d)
            f_cam = bsdf.eval(ctx, si, wo_cam, connect) * adjoint_correction(si, wi_world, wo_cam)
            si_rev = mi.SurfaceInteraction3f(si)
            si_rev.wi = wo_cam
            pdf_rev_cam = bsdf.pdf(ctx_rad, si_rev, si.wi, connect)
            dist2 = dr.square(ds.dist)
            w_cam = w.light_to_camera(mis, _camera_pdf(we, dist2), dr.abs(dr.dot(si.n, ds.d)),
                                      dist2, pdf_rev_cam)
            value = beta * f_cam * we * _finite_or_zero(w_cam) * scale
            self._splat(block, ds, si.wavelengths, value, connect)

            # ---------- adjoint BSDF sampling ----------
            active &= depth + 1 < max_depth
            bs, bsdf_weight = bsdf.sample(ctx, si, rng.next_float32(),
                                          mi.Point2f(rng.next_float32(), rng.next_float32()), active)
            beta *= bsdf_weight * adjoint_correction(si, wi_world, bs.wo)
            si_rev = mi.SurfaceInteraction3f(si)
            si_rev.wi = bs.wo
            pdf_rev = bsdf.pdf(ctx_rad, si_rev, si.wi, active)
            mis = w.scatter_light(mis, bs.pdf, pdf_rev, dr.abs(mi.Frame3f.cos_theta(bs.wo)),
                                  mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta))
            dvcm, dvc, first = _finite_or_zero(mis.dvcm), _finite_or_zero(mis.dvc), mi.Float(mis.first)
            ray = spawn.spawn_ray(si, si.to_world(bs.wo), self.floor)

            beta_max = dr.max(mi.unpolarized_spectrum(beta))
            active &= (beta_max > 0) & dr.isfinite(beta_max)
            beta, survives = russian_roulette(beta, rng.next_float32(), depth >= rr_depth, start=beta_max0)
            active &= survives
        return dr.sum(vertices)


def render_light_tracing(scene: mi.Scene, sensor: mi.Sensor | int = 0, seed: int = 0, spp: int = 1,
                         max_depth: int = -1, rr_depth: int = 5, weights: BdptWeights | None = None):
    """Light tracing alone: film pixels x ``spp`` light subpaths, developed into the sensor's film.

    Returns the film's developed image (``TensorXf``), comparable to ``mi.render`` of Mitsuba's
    ``ptracer`` with the same ``max_depth`` / ``rr_depth`` (emitters seen directly included).
    """
    from mitsuba_lab.scene import SceneTraits

    if isinstance(sensor, int):
        sensor = scene.sensors()[sensor]
    if not isinstance(spp, int) or spp < 1:
        raise ValueError(f"lab_bdpt: spp must be an integer >= 1, got {spp!r}")
    floor = spawn.offset_floor(SceneTraits.from_scene(scene))
    film = sensor.film()
    film.prepare([])
    block = film.create_block(mi.ScalarVector2u(0), True, False)
    block.set_offset(film.crop_offset())
    block.set_coalesce(False)
    if scene.emitters():
        tracer = LightTracer(scene, sensor, max_depth, rr_depth, weights, floor)
        film_size, crop_size = film.size(), film.crop_size()
        count = film_size[0] * film_size[1] * spp
        sample_scale = crop_size[0] * crop_size[1] / count
        tracer.trace(count, seed, block, sample_scale)
    film.put_block(block)
    return film.develop()
