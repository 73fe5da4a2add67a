"""The photon pass: light paths from emitters chosen by power, stored at smooth vertices.

A photon starts at an emitter chosen with probability P_e proportional to the
emitter's power Phi_e, with an emission ray from ``Emitter.sample_ray``, whose weight
is Phi_e per sample for that emitter. Its flux is

    Phi_p = weight / (P_e N)

for N photons emitted in the pass, so that E[sum of first-hit flux] = total emitted
power (minus what escapes). It is then traced with BSDF sampling in importance
(adjoint) transport mode and Russian roulette relative to its emitted flux
(``roulette``), and stored at every interaction whose BSDF has a smooth (non-delta)
component. Every photon has its own PCG32 stream,
seeded from (pass seed, global photon index), so a batch split in two reproduces
exactly the photons of the unsplit batch.

**Shading normals.** A photon scattered from wi into the sampled direction wo is weighted by
Veach's adjoint correction (``common.adjoint.adjoint_correction``), built from the
interaction's shading frame (the interpolated vertex normal: a ``normalmap`` / ``bumpmap``
perturbs it inside the BSDF, where the integrator cannot see it, so there the correction uses
the unperturbed one, as ``ptracer`` does). No photon is dropped for lying on the "wrong" side
of one normal and not the other, so photon paths cover what the path tracers' camera paths
cover.

**Participating media** (``media``: the scene has them). Photons travel as lab_bdpt's light
subpaths do (``bdpt.media_paths``, from ``common.subpath_media``): they start in their emitter's
medium (``subpath_media.emitter_media``, decided once per render for each emitter), take a free
flight in the medium they are in (``subpath_media.flight``: the analytic one in homogeneous media,
delta tracking in heterogeneous ones, in one sampling channel per photon, weighted T / p_c and
sigma_s at a collision), scatter at a collision by the medium's phase function, and pass null
boundaries (a ``null`` BSDF, a mask's clear part) without a vertex (volpath's counting of
``max_depth``). A collision stores a *volumetric photon*: its normal is 0 (``records``), and its
power holds sigma_s there, which the gather divides out at the camera's vertex (``gather``).

In spectral variants every photon of a pass is emitted at the pass's wavelengths
(``spectral.emit``). Rays leave surfaces at the lab's scale-robust offsets (``spawn``); in a
scene smaller than 1 unit an area emitter's own offset (Mitsuba's, absolute) is replaced too.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import spawn, spectral
from mitsuba_lab.plugins.integrators.common.adjoint import adjoint_correction
from mitsuba_lab.plugins.integrators.common.roulette import russian_roulette
from mitsuba_lab.plugins.integrators.common.subpath_media import flight
from mitsuba_lab.plugins.integrators.common.subpath_media import RngSampler, medium_vertex, path_channel, start_medium

from .records import PhotonRecords

#: A key mixed into a pass's seed for the photons' sampling channel (``subpath_media.path_channel``)
#: and one for their second random stream (delta tracking's draws in heterogeneous media).
_CHANNEL_KEY = 0x51ED270B
_TRACKING_KEY = 0x3C6EF372

#: Emission samples per emitter for the power estimate that drives emitter selection.
POWER_SAMPLES = 1 << 14
#: Every emitter keeps at least this share of the mean selection probability, so an
#: emitter whose power estimate came out (near) zero can still be chosen: unbiased.
MIN_SHARE = 1e-3


def emitter_powers(scene: mi.Scene, seed: int = 0) -> list[float]:
    """Power of each emitter (mean of the RGB channels), estimated from emission samples.

    ``Emitter.sample_ray`` returns Phi_e as its weight for a uniform emitter, so the
    estimate is exact for point lights and uniform area lights and unbiased otherwise.
    Only the selection probabilities depend on it: any estimate keeps the photon
    map unbiased.
    """
    powers = []
    n = POWER_SAMPLES
    for index, emitter in enumerate(scene.emitters()):
        rng = mi.PCG32(n)
        rng.seed(mi.sample_tea_64(mi.UInt32(seed), dr.arange(mi.UInt32, n) + index * n),
                 mi.UInt64(index * 2 + 1))
        _, weight = emitter.sample_ray(mi.Float(0), rng.next_float32(),
                                       mi.Point2f(rng.next_float32(), rng.next_float32()),
                                       mi.Point2f(rng.next_float32(), rng.next_float32()))
        value = channel_mean(weight)
        mean = dr.mean(dr.select(dr.isfinite(value), value, 0.0))
        powers.append(max(float(mean[0]), 0.0))
    return powers


def channel_mean(spectrum):
    """Mean over the channels of a (unpolarized) spectrum: RGB, mono or 4 wavelengths."""
    value = mi.unpolarized_spectrum(spectrum)
    n = len(value)
    total = value[0]
    for i in range(1, n):
        total = total + value[i]
    return total * (1.0 / n)


def area_origin_fixes(scene: mi.Scene, floor: float) -> list:
    """Per emitter, a function (time, sample2, ray) -> ray origin. An area emitter's
    ``sample_ray`` starts its ray at Mitsuba's absolute offset from the point it sampled with
    ``sample2``; ``sample_position`` with the same sample gives that point again, and the ray
    starts at the lab's offset from it instead. Other emitters start their rays on no surface."""
    def fixed(emitter):
        def origin(time, sample2, ray):
            ps, _ = emitter.sample_position(time, sample2)
            return spawn.offset_from_emitted(ps, ray.d, floor)
        return origin

    def unchanged(time, sample2, ray):
        return ray.o

    return [fixed(e) if e.get_shape() is not None else unchanged for e in scene.emitters()]


def aimed_ray(aim, emitter, time, sample2, ray, weight, rng, floor: float):
    """``sample_ray``'s (ray, weight) with its direction redrawn by ``aim`` (``aim.py``) where the
    emitter is an area light (the same ``sample2`` gives its point again); the ray starts at the
    lab's offset from that point."""
    ps, _ = emitter.sample_position(time, sample2)
    area = mi.has_flag(emitter.flags(), mi.EmitterFlags.Surface)
    u_choice = rng.next_float32()
    u_cone = mi.Point2f(rng.next_float32(), rng.next_float32())
    d, factor = aim.sample(ps.p, ps.n, ray.d, u_choice, u_cone, area)
    ray.o = dr.select(area, spawn.offset_from_emitted(ps, d, floor), ray.o)
    ray.d = d
    return ray, weight * factor


def selection_pmf(powers: list[float]) -> list[float]:
    """Probabilities proportional to power, with the MIN_SHARE floor; sums to 1."""
    k = len(powers)
    total = sum(powers)
    if total <= 0:
        return [1.0 / k] * k
    floor = MIN_SHARE * total / k
    raw = [max(p, floor) for p in powers]
    s = sum(raw)
    return [r / s for r in raw]


class PhotonTracer:
    """Traces batches of photons for one scene.

    ``max_segments``: the longest light subpath stored (segments from the emitter);
    ``min_segments``: photons are stored from this depth on (1 = at the first hit,
    2 = only after at least one bounce); ``rr_depth``: Russian roulette from this depth.
    """

    def __init__(self, scene: mi.Scene, max_segments: int, min_segments: int, rr_depth: int,
                 offset_floor: float = 1.0, aim=None, media: bool = False, tracking=None, emitter_media=None):
        if not scene.emitters():
            raise ValueError("lab_photon: the scene has no emitter")
        self.spectra = spectral.EmitterSpectra(scene) if mi.is_spectral else None
        self.scene = scene
        self.offset_floor = offset_floor
        # Mitsuba's offsets equal the lab's for floor = 1: only smaller scenes need the fix.
        self.origin_fixes = area_origin_fixes(scene, offset_floor) if offset_floor < 1.0 else None
        self.max_segments = max_segments
        self.min_segments = min_segments
        self.rr_depth = rr_depth
        self.powers = emitter_powers(scene)
        self.pmf = selection_pmf(self.powers)
        self.distribution = mi.DiscreteDistribution(mi.Float(self.pmf))
        self.emitters = scene.emitters_dr()
        #: ``aim.AimedEmission`` when a share of area lights' directions is aimed at shapes
        self.aim = aim if aim is not None and aim.enabled else None
        #: the scene has media (photons fly through them); ``tracking``: ``subpath_media.Tracking``
        #: where some medium is heterogeneous, else None; ``emitter_media``: the medium of each
        #: emitter (``subpath_media.emitter_media``), gathered by emitter index
        self.media = media
        self.tracking = tracking
        self.emitter_media = emitter_media

    @dr.syntax
    def trace(self, first: int, count: int, pass_seed: int, emitted_in_pass: int, capacity: int,
              wavelengths: list | None = None):
        """Trace photons [first, first + count) of a pass into a buffer of ``capacity`` records.

        ``wavelengths``: in spectral variants, the pass's wavelengths (nm, one per channel),
        at which every photon is emitted and traced.

        Returns (records buffer, stores attempted (UInt32[1]), segments traced (UInt32[1])).
        When stores attempted > capacity, the records past the capacity were dropped and
        the caller must split the batch.
        """
        scene = self.scene
        index = dr.arange(mi.UInt32, count) + dr.opaque(mi.UInt32, first)
        seed = dr.opaque(mi.UInt32, pass_seed & 0xFFFFFFFF)
        rng = mi.PCG32(count)
        rng.seed(mi.sample_tea_64(seed, index), mi.sample_tea_64(index, seed ^ 0x9E3779B9))

        # --------------------- Emission ----------------------
        emitter_index, p_emitter = self.distribution.sample_pmf(rng.next_float32())
        emitter = dr.gather(mi.EmitterPtr, self.emitters, emitter_index)
        time = mi.Float(0)
        u_wavelength = rng.next_float32()
        sample2 = mi.Point2f(rng.next_float32(), rng.next_float32())
        sample3 = mi.Point2f(rng.next_float32(), rng.next_float32())
        if dr.hint(wavelengths is not None, mode="scalar"):
            ray, weight = self.spectra.emit(emitter, emitter_index, time, wavelengths, sample2, sample3)
        else:
            ray, weight = emitter.sample_ray(time, u_wavelength, sample2, sample3)
        if dr.hint(self.aim is not None, mode="scalar"):
            ray, weight = aimed_ray(self.aim, emitter, time, sample2, ray, weight, rng, self.offset_floor)
        elif dr.hint(self.origin_fixes is not None, mode="scalar"):
            ray.o = dr.switch(emitter_index, self.origin_fixes, time, sample2, ray)
        n_emitted = dr.opaque(mi.Float, float(emitted_in_pass))
        beta = mi.Spectrum(weight) * dr.select(p_emitter > 0, dr.rcp(p_emitter * n_emitted), 0.0)
        beta_max0 = dr.max(mi.unpolarized_spectrum(beta))
        records = PhotonRecords.allocate(capacity)
        stores = dr.zeros(mi.UInt32, 1)
        segments = dr.zeros(mi.UInt32, 1)
        cap = dr.opaque(mi.UInt32, capacity)
        floor = self.offset_floor
        max_segments = dr.opaque(mi.UInt32, self.max_segments)
        min_segments = dr.opaque(mi.UInt32, self.min_segments)
        rr_depth = dr.opaque(mi.UInt32, self.rr_depth)
        ctx = mi.BSDFContext(mi.TransportMode.Importance)

        depth = mi.UInt32(0)
        n_seg = mi.UInt32(0)
        active = (beta_max0 > 0) & dr.isfinite(beta_max0) & (max_segments > 0)
        media = self.media
        if dr.hint(media, mode="scalar"):
            medium, extinguished = start_medium(self.emitter_media, emitter_index,
                                                mi.has_flag(emitter.flags(), mi.EmitterFlags.Infinite))
            active &= ~extinguished
            channel = path_channel(index, pass_seed ^ _CHANNEL_KEY)
            aux = mi.PCG32(count)
            aux.seed(mi.sample_tea_64(index, seed ^ _TRACKING_KEY), index)
            tracker = RngSampler(aux)
            phase_ctx = mi.PhaseFunctionContext(None, mi.TransportMode.Importance)
        else:       # (defined on both branches: the symbolic loop carries what it finds defined)
            medium = channel = tracker = phase_ctx = None
        while dr.hint(active, max_iterations=-1, label="lab_photon photon loop"):
            si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False, active=active)
            n_seg += dr.select(active, 1, 0)
            if dr.hint(media, mode="scalar"):
                # ---------- a free flight: a collision in the medium, or the surface ----------
                si = spawn.behind_null_face(scene, ray, si, floor, active)
                in_medium = active & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
                mei, scattered, w_flight, _ = flight(medium, ray, si.t, rng.next_float32(), tracker, channel,
                                                     in_medium, self.tracking)
                beta[in_medium] *= mi.Spectrum(w_flight)
                surface = active & ~scattered & si.is_valid()
                active = scattered | surface
            else:
                active &= si.is_valid()
                scattered, surface = mi.Bool(False), active
            at = depth + 1
            bsdf = si.bsdf()

            # ------------------- Store the photon -------------------
            # (a medium photon: its collision, normal 0, unless it carries nothing, absorbed in a
            # medium of albedo 0; a surface photon: a smooth lobe's hit)
            store = (scattered | (surface & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth))) & (at >= min_segments)
            if dr.hint(media, mode="scalar"):
                store &= dr.max(mi.unpolarized_spectrum(beta)) > 0
            slot = dr.scatter_inc(stores, mi.UInt32(0), store)
            if dr.hint(media, mode="scalar"):
                records.store(slot, dr.select(scattered, mei.p, si.p), -ray.d,
                              dr.select(scattered, mi.Normal3f(0), si.n), beta, at, store & (slot < cap))
            else:
                records.store(slot, si.p, -ray.d, si.n, beta, at, store & (slot < cap))

            # ------------------- BSDF (or phase function) sampling ----------------------
            u_lobe, u_dir = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
            if dr.hint(media, mode="scalar"):
                bs, bsdf_weight = bsdf.sample(ctx, si, u_lobe, u_dir, surface)
                passing = surface & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
                depth[~passing] = at                     # (a null boundary is no vertex)
                going = active & ~passing & (depth < max_segments)
                phase = mei.medium.phase_function()
                phase[~scattered] = dr.zeros(mi.PhaseFunctionPtr)
                wo_phase, phase_weight, _ = phase.sample(phase_ctx, mei, u_lobe, u_dir, going & scattered)
                direction = dr.select(scattered, wo_phase, si.to_world(bs.wo))
                weight = dr.select(scattered, mi.Spectrum(phase_weight),
                                   bsdf_weight * adjoint_correction(si, -ray.d, bs.wo))
                beta[going | passing] *= weight
                medium[surface & si.is_medium_transition()] = si.target_medium(direction)
                v = mi.SurfaceInteraction3f(si)
                v[scattered] = medium_vertex(mei, ray.wavelengths)
                ray = spawn.spawn_ray(v, direction, floor)
                active = going | passing
                vertex = ~passing
            else:
                depth = at
                active &= depth < max_segments
                bs, bsdf_weight = bsdf.sample(ctx, si, u_lobe, u_dir, active)
                beta *= bsdf_weight * adjoint_correction(si, -ray.d, bs.wo)
                ray = spawn.spawn_ray(si, si.to_world(bs.wo), floor)
                vertex = mi.Bool(True)

            # ------------------- Stopping criterion -----------------
            beta_max = dr.max(mi.unpolarized_spectrum(beta))
            active &= (beta_max > 0) & dr.isfinite(beta_max)
            beta, survives = russian_roulette(beta, rng.next_float32(), vertex & (depth >= rr_depth), start=beta_max0)
            active &= survives

        dr.scatter_reduce(dr.ReduceOp.Add, segments, n_seg, 0, mode=dr.ReduceMode.Local)
        return records, stores, segments
