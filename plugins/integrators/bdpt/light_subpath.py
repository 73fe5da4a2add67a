"""Light subpaths in one Dr.Jit symbolic loop, their stored vertices, and the t = 1 strategy.

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

The MIS running quantities of ``weights.py`` (``SubpathMis``) are carried per vertex, with the
exact densities of ``endpoints.py``: the emitted ray's position and direction densities, and
the emitter-sampling density of x_0, which is known once x_1 is (a sphere light's depends on
the reference point). All cosines in the weights are geometric (area measure), on both
subpaths, so every strategy's density of a vertex is computed the same way. With ``vertices``
given, the vertices a connection can end at (smooth BSDF, short enough for a camera vertex to
join) are stored for the camera subpaths (``vertices.LightVertices``).

Spectral variants: a pass has one set of wavelengths, the sensor's for the pass's sample
(``pass_spectrum``, set by the driver), and every light subpath is emitted at exactly those
(``spectral.emit``), so its vertices can be joined to camera vertices; a splat carries the
sensor's spectral weight that a camera ray's weight carries. lab_mmlt sets each lane's own
wavelengths and weight instead (its lane's camera ray's).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import spawn, spectral
from mitsuba_lab.plugins.integrators.common.adjoint import adjoint_correction, transported
from mitsuba_lab.plugins.integrators.common.counters import tally
from mitsuba_lab.plugins.integrators.common.roulette import russian_roulette

from . import splats
from .endpoints import EmitterTable, camera_direction_pdf, direction_is_delta, nee_density
from .vertices import NONE, LightVertices
from .techniques import Strategy, Technique
from .weights import BdptWeights, SubpathMis


def float_or_zero(x):
    """A float ``x`` where finite, else 0 (a 0 * inf density ratio must not turn a splat into
    NaN). ``direct.spectrum_or_zero`` is the same guard on a whole spectrum."""
    return dr.select(dr.isfinite(x), x, 0.0)


def check_variant(plugin: str = "lab_bdpt") -> None:
    """Refuse variants lab_bdpt (and ``plugin``, built on it) cannot render yet (one line)."""
    if mi.is_polarized:
        # Light and camera subpaths would need the same Stokes frames at every connection.
        variant = mi.variant()
        raise ValueError(f"{plugin}: variant '{variant}' is not supported: bidirectional paths carry "
                         f"unpolarized light; use {variant.replace('_polarized', '')}")


def carried(merging: bool, value, old):
    """``value`` with vertex merging, else ``old`` itself (dvm stays a constant 0 without it, so
    lab_bdpt's kernels do not carry it)."""
    return float_or_zero(value) if merging else old


def reverse_pdf(bsdf, ctx, si: mi.SurfaceInteraction3f, wo, active):
    """The density of sampling ``si.wi`` at ``si`` when arriving from ``wo`` (local): the
    direction back along a subpath, as the other side would sample it (``ctx``: its mode)."""
    si_rev = mi.SurfaceInteraction3f(si)
    si_rev.wi = wo
    return bsdf.pdf(ctx, si_rev, si.wi, active)


def strategy_mask(only: Strategy | None, s, t):
    """True where strategy (s, t) is kept: every strategy when ``only`` is None, else only ``only``
    (``s``, ``t``: Python ints or Dr.Jit UInt32 arrays)."""
    if only is None:
        return True
    keep = (s == only.s) & (t == only.t)
    return bool(keep) if isinstance(keep, bool) else keep


def depth_bound(max_depth):
    """``max_depth`` as the loops hold it: an int opaque (one kernel for every value), or a UInt32
    per lane as it is (lab_mmlt bounds each lane by the length its chain picked)."""
    return dr.opaque(mi.UInt32, max_depth) if isinstance(max_depth, int) else max_depth


def sensor_pdf(ds: mi.DirectionSample3f, importance):
    """The sensor's direction density (``endpoints.camera_direction_pdf``) of the direction from
    the sensor to the reference point of ``ds`` (``Sensor.sample_direction``'s result)."""
    return camera_direction_pdf(importance, dr.square(ds.dist))


class LightTracer:
    """Traces light subpaths for one scene and sensor and splats their t = 1 connections.

    ``max_depth``: longest path in segments, emitter to sensor (-1: unbounded; 1: emitters seen
    directly only; Mitsuba's meaning); ``rr_depth``: Russian roulette from this many light
    segments on; ``weights``: the MIS weights (default ``BdptWeights(strategies="light")``);
    ``plugin``: the plugin its errors name.
    """
    #: ``counters.RayCounters`` counting light subpaths' rays and light tracing's rays to the
    #: sensor (set by the integrator when it counts rays), else None
    counters = None
    #: a UInt32 per subpath bounding its path's length in place of ``max_depth`` (no longer than
    #: it; lab_mmlt's lanes, each of one length), else None
    lane_max_depth = None

    def __init__(self, scene: mi.Scene, sensor: mi.Sensor, max_depth: int = -1, rr_depth: int = 5,
                 weights: BdptWeights | None = None, offset_floor: float = 1.0, only: Strategy | None = None,
                 hide_emitters: bool = False, aim=None, plugin: str = "lab_bdpt", table: EmitterTable | None = None,
                 spectra: spectral.EmitterSpectra | None = None):
        if not isinstance(max_depth, int) or max_depth < -1 or max_depth == 0:
            raise ValueError(f"{plugin}: max_depth must be -1 (unbounded) or >= 1, got {max_depth!r}")
        if not isinstance(rr_depth, int) or rr_depth < 1:
            raise ValueError(f"{plugin}: rr_depth must be an integer >= 1, got {rr_depth!r}")
        check_variant(plugin)
        self.plugin = plugin
        self.scene, self.sensor = scene, sensor
        self.max_depth = max_depth
        self.rr_depth = rr_depth
        self.weights = weights if weights is not None else BdptWeights(strategies="light")
        self.floor = offset_floor
        # (aim: aim.AimedEmission, or None; ``table``: one the caller made once for many passes)
        self.table = table if table is not None else EmitterTable(scene, aim)
        self.only = only                     # None or the one strategy (s, t) to splat
        self.hide_emitters = hide_emitters   # camera rays pass through area emitters
        self.reaches_sensor = not direction_is_delta(sensor)   # (orthographic: t = 1 is impossible)
        # (``spectra``: one the caller made once for many traces, as ``table``)
        self.spectra = (spectra if spectra is not None else spectral.EmitterSpectra(scene, plugin)) \
            if mi.is_spectral else None
        #: spectral variants: (wavelengths, the sensor's spectral weight) of the pass: Python floats,
        #: or Dr.Jit arrays with each lane's own (lab_mmlt)
        self.pass_spectrum = None
        #: in a scene with (homogeneous) media, the loop that scatters the subpaths in them
        #: (``media_paths.trace_light``, set by the driver), else False
        self.media = False
        #: the pass's key of each light subpath's sampling channel in media (``media_paths.path_channel``)
        self.channel_key = 0
        #: heterogeneous media: delta tracking in them (``subpath_media.Tracking``), else None
        self.tracking = None
        #: in a scene with media, the medium each emitter sits in (``subpath_media.emitter_media``, set
        #: by the driver once per render), else None
        self.emitter_media = None

    @dr.syntax
    def _visible(self, it, ds, active):
        """The sensor sample is usable and not occluded from ``it`` (with ``hide_emitters``, area
        emitters on the way do not occlude: the camera sees through them)."""
        active = active & (ds.pdf > 0)
        tally(self.counters, "sensor", active)     # (once, even through hidden emitters)
        ray = spawn.spawn_ray_to(it, ds.p, self.floor)
        if dr.hint(not self.hide_emitters, mode="scalar"):
            return active & ~self.scene.ray_test(ray, active)
        pi = self.scene.ray_intersect_preliminary(ray, coherent=False, active=active)
        through = active & pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711 (pointer test)
        while dr.hint(through, max_iterations=-1, label="lab_bdpt through emitters"):
            si = pi.compute_surface_interaction(ray, mi.RayFlags.Minimal, through)
            ray = spawn.spawn_ray_to(si, ds.p, self.floor)
            pi = self.scene.ray_intersect_preliminary(ray, coherent=False, active=through)
            through &= pi.is_valid() & (pi.shape.emitter() != None)  # noqa: E711
        return active & ~pi.is_valid()

    @dr.syntax
    def trace(self, count: int, seed: int, block: mi.ImageBlock, sample_scale: float,
              vertices: LightVertices | None = None, store_lanes: int | None = None, rng=None):
        """Trace ``count`` light subpaths (PCG32 stream per lane from ``seed``, or ``rng``: any
        object of ``count`` lanes with ``next_float32()``, such as lab_mmlt's chain state), splat
        every t = 1 connection into ``block`` and, with ``vertices``, store the connectable
        vertices (of the first ``store_lanes`` subpaths only, when given: the ones camera
        subpaths read).

        Returns (surface vertices reached (UInt32[1]), stores attempted (UInt32[1]), each lane's
        last stored slot (``vertices.NONE`` when none))."""
        scene, sensor, table = self.scene, self.sensor, self.table
        index = dr.arange(mi.UInt32, count)
        w = self.weights.at_lanes(index)          # (lab_vcm: each lane's iteration's merging terms)
        s = dr.opaque(mi.UInt32, seed & 0xFFFFFFFF)
        if rng is None:
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
        if dr.hint(self.spectra is not None, mode="scalar"):
            if self.pass_spectrum is None:
                raise ValueError(f"{self.plugin}: a spectral variant's light subpaths need the pass's wavelengths")
            wavelengths, sensor_weight = self.pass_spectrum
            ray, ray_weight = self.spectra.emit(emitter, emitter_index, time, wavelengths, sample_pos, sample_dir)
            scale = scale * sensor_weight         # what a camera ray's weight carries
        else:
            ray, ray_weight = emitter.sample_ray(time, u_wav, sample_pos, sample_dir)
        # The same position sample gives x_0 again, with its area density and normal (an
        # emitter at infinity has no position: its x_0 is the direction, see endpoints.py).
        ps, pos_weight = emitter.sample_position(time, sample_pos)
        delta_pos = mi.has_flag(emitter.flags(), mi.EmitterFlags.DeltaPosition)
        infinite = table.at_infinity(emitter)
        on_surface = ~delta_pos & ~infinite
        if dr.hint(table.aim is not None, mode="scalar"):
            # an area light aims a share of its directions (aim.py): redrawn, weight corrected
            u_aim, u_cone = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
            ray.d, factor = table.aim.sample(ps.p, ps.n, ray.d, u_aim, u_cone, on_surface)
            ray_weight = ray_weight * factor
        cos_emit = dr.select(on_surface, dr.abs(dr.dot(ps.n, ray.d)), 1.0)
        pdf_pos, pdf_dir, delta = table.emission(emitter, cos_emit, None, True, ps.p, ray.d)
        pdf_pos = dr.select(on_surface, pmf * ps.pdf, pdf_pos)        # what sample_ray used, exactly
        if dr.hint(self.floor < 1.0 or table.aim is not None, mode="scalar"):
            # An area emitter's ray starts at Mitsuba's absolute offset (from the point, to the side
            # of its own direction): use the lab's instead.
            ray.o = dr.select(on_surface, spawn.offset_from_emitted(ps, ray.d, self.floor), ray.o)
        # x_0 as emitter sampling from x_1 would see it (its density needs x_1: set in the loop)
        ds_0 = dr.zeros(mi.DirectionSample3f)
        ds_0.p, ds_0.n, ds_0.uv, ds_0.time, ds_0.emitter = ps.p, ps.n, ps.uv, time, emitter

        if dr.hint(self.media, mode="scalar"):
            # a scene with media: the subpaths scatter in them too (``media_paths``)
            from types import SimpleNamespace

            emitted = SimpleNamespace(w=w, count=count, index=index, rng=rng, ray=ray, ray_weight=ray_weight,
                                      sel_weight=sel_weight, emitter=emitter, emitter_index=emitter_index, ps=ps, pos_weight=pos_weight, pmf=pmf,
                                      delta_pos=delta_pos, delta=delta, infinite=infinite, on_surface=on_surface,
                                      scale=scale, cos_emit=cos_emit, pdf_pos=pdf_pos, ds_0=ds_0)
            return self.media(self, emitted, block, vertices, store_lanes)

        # ---------------- s = 1, t = 1: the emitter point seen directly ----------------
        # (light tracing disabled, e.g. lab_vcm's bpm, or a sensor it cannot reach, orthographic:
        # nothing splatted, the same random numbers)
        tracing = Technique.LIGHT in w.techniques and self.reaches_sensor
        u0 = mi.Point2f(rng.next_float32(), rng.next_float32())
        if dr.hint(tracing, mode="scalar"):
            si0 = mi.SurfaceInteraction3f(ps, ray.wavelengths)
            active0 = on_surface & (pmf > 0) & strategy_mask(self.only, 1, 1) & (not self.hide_emitters)
            ds0, we0 = sensor.sample_direction(si0, u0, active0)
            active0 = self._visible(si0, ds0, active0)
            si0.wi = si0.to_local(ds0.d)
            cos0 = mi.Frame3f.cos_theta(si0.wi)
            active0 &= cos0 > 0
            le0 = emitter.eval(si0, active0)
            w0 = w.emitter_to_camera(sensor_pdf(ds0, we0), cos0, dr.square(ds0.dist), pdf_pos, delta_pos)
            value0 = le0 * cos0 * pos_weight * sel_weight * we0 * float_or_zero(w0) * scale
            splats.splat(block, ds0.uv, si0.wavelengths, value0, active0)

        # ---------------- x_1, x_2, ..: the light subpath ----------------
        beta = mi.Spectrum(ray_weight) * sel_weight
        beta_max0 = dr.max(mi.unpolarized_spectrum(beta))
        max_depth = depth_bound(self.max_depth if self.max_depth > 0 else 0xFFFFFFFF)
        if self.lane_max_depth is not None:
            max_depth = self.lane_max_depth
        rr_depth = dr.opaque(mi.UInt32, self.rr_depth)
        ctx = mi.BSDFContext(mi.TransportMode.Importance)
        storing = vertices is not None and bool(w.techniques & (Technique.CONNECT | Technique.MERGE))
        # a merge needs one camera segment after the light vertex, a connection two
        camera_segments = 1 if w.merging else 2
        stores = dr.zeros(mi.UInt32, 1)
        capacity = dr.opaque(mi.UInt32, vertices.capacity if storing else 0)
        last = dr.full(mi.UInt32, NONE, count)
        dvcm, dvc, first = mi.Float(0), mi.Float(0), mi.Float(1)
        dvm = mi.Float(0) if w.merging else 0.0
        merges = mi.Float(w.start_merges()) if w.caustic else 1.0   # (caustic_merges: after a delta lobe)
        depth = mi.UInt32(0)
        vertices_reached = mi.UInt32(0)
        active = (beta_max0 > 0) & dr.isfinite(beta_max0) & (max_depth > 1)
        while dr.hint(active, max_iterations=-1, label="lab_bdpt light subpath"):
            si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False, active=active)
            tally(self.counters, "light", active)
            active &= si.is_valid()
            vertices_reached += dr.select(active, 1, 0)
            cos_in = dr.abs(dr.dot(si.n, ray.d))
            dist2 = dr.square(si.t)
            if depth == 0:
                # x_0's emitter-sampling density, from x_1 (exact for any shape's sampling)
                ds_0.d = dr.select(infinite, -ray.d, dr.normalize(ds_0.p - si.p))
                ds_0.dist = dr.select(infinite, dr.inf, dr.norm(ds_0.p - si.p))
                pdf_nee = dr.select(delta, pmf, nee_density(scene, si, ds_0, infinite, active & ~delta))
                pdf_dir_0 = table.emission(emitter, cos_emit, pdf_nee, active, ds_0.p, ray.d)[1]
                start = w.start_light(pdf_pos * pdf_dir_0, pdf_nee, cos_emit, delta)
                dvcm, dvc, first = mi.Float(start.dvcm), mi.Float(start.dvc), mi.Float(start.first)
                dvm = carried(w.merging, start.dvm, dvm)
                dist2 = dr.select(infinite, 1.0, dist2)    # x_0 is a direction: no distance
            depth += 1
            mis = w.after_hit(SubpathMis(dvcm, dvc, first, dvm, merges), dist2, cos_in)
            bsdf = si.bsdf()
            wi_world = -ray.d
            smooth = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            splat_on = smooth & strategy_mask(self.only, depth + 1, 1)
            if dr.hint(self.hide_emitters, mode="scalar"):
                splat_on &= si.emitter(scene) == None  # noqa: E711 (the camera sees through emitters)

            # ---------- store x_depth for connections with camera vertices ----------
            if dr.hint(storing, mode="scalar"):
                store = smooth & (depth + camera_segments <= max_depth)
                if dr.hint(store_lanes is not None and store_lanes < count, mode="scalar"):
                    store &= index < dr.opaque(mi.UInt32, store_lanes)
                slot = dr.scatter_inc(stores, mi.UInt32(0), store)
                kept = store & (slot < capacity)
                vertices.store(slot, si, -ray.d, beta, mis, depth, last, kept,
                               self.weights.lane_iteration(index))
                last = dr.select(kept, slot, last)

            # ---------- t = 1: join x_depth to the sensor ----------
            u_sensor = mi.Point2f(rng.next_float32(), rng.next_float32())
            if dr.hint(tracing, mode="scalar"):
                ds, we = sensor.sample_direction(si, u_sensor, splat_on)
                connect = self._visible(si, ds, splat_on)
                wo_cam = si.to_local(ds.d)
                f_cam, pdf_rev_cam = transported(bsdf, si, wo_cam, connect)
                w_cam = w.light_to_camera(mis, sensor_pdf(ds, we), dr.abs(dr.dot(si.n, ds.d)),
                                          dr.square(ds.dist), pdf_rev_cam)
                value = beta * f_cam * we * float_or_zero(w_cam) * scale
                splats.splat(block, ds.uv, si.wavelengths, value, connect)

            # ---------- adjoint BSDF sampling ----------
            active &= depth + 1 < max_depth
            bs, bsdf_weight = bsdf.sample(ctx, si, rng.next_float32(),
                                          mi.Point2f(rng.next_float32(), rng.next_float32()), active)
            wo_world = si.to_world(bs.wo)
            # smooth lobes: the exact transported value over the density; a delta lobe has no
            # value to evaluate, and its sample weight with the correction is exact without maps
            delta_lobe = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            sent, pdf_rev = transported(bsdf, si, bs.wo, active & ~delta_lobe)    # (0 for delta lobes)
            smooth_weight = sent / dr.maximum(bs.pdf, 1e-30)
            beta *= dr.select(delta_lobe, bsdf_weight * adjoint_correction(si, wi_world, bs.wo),
                              dr.select(bs.pdf > 0, smooth_weight, 0.0))
            mis = w.scatter_light(mis, bs.pdf, pdf_rev, dr.abs(dr.dot(si.n, wo_world)), delta_lobe)
            dvcm, dvc, first = float_or_zero(mis.dvcm), float_or_zero(mis.dvc), mi.Float(mis.first)
            dvm = carried(w.merging, mis.dvm, dvm)
            if dr.hint(w.caustic, mode="scalar"):
                merges = mi.Float(mis.merges)
            ray = spawn.spawn_ray(si, wo_world, self.floor)

            beta_max = dr.max(mi.unpolarized_spectrum(beta))
            active &= (beta_max > 0) & dr.isfinite(beta_max)
            beta, survives = russian_roulette(beta, rng.next_float32(), depth >= rr_depth, start=beta_max0)
            active &= survives
        reached = dr.zeros(mi.UInt32, 1)              # summed lazily: dr.sum would launch the loop alone
        dr.scatter_reduce(dr.ReduceOp.Add, reached, vertices_reached, 0, mode=dr.ReduceMode.Local)
        return reached, stores, last


def render_light_tracing(scene: mi.Scene, sensor: mi.Sensor | int = 0, seed: int = 0, spp: int = 1,
                         max_depth: int = -1, rr_depth: int = 5, weights: BdptWeights | None = None):
    """Light tracing alone: film pixels x ``spp`` light subpaths, developed into the sensor's film.

    Returns the film's developed image (``TensorXf``), comparable to ``mi.render`` of Mitsuba's
    ``ptracer`` with the same ``max_depth`` / ``rr_depth`` (emitters seen directly included).
    """
    from mitsuba_lab.plugins.scene_traits import SceneTraits

    if isinstance(sensor, int):
        sensor = scene.sensors()[sensor]
    if not isinstance(spp, int) or spp < 1:
        raise ValueError(f"lab_bdpt: spp must be an integer >= 1, got {spp!r}")
    floor = spawn.offset_floor(SceneTraits.from_scene(scene))
    film = sensor.film()
    block = splats.new_block(film)
    if scene.emitters():
        tracer = LightTracer(scene, sensor, max_depth, rr_depth, weights, floor)
        film_size, crop_size = film.size(), film.crop_size()
        count = film_size[0] * film_size[1] * spp
        sample_scale = crop_size[0] * crop_size[1] / count
        tracer.trace(count, seed, block, sample_scale)
    return splats.develop(film, block)
