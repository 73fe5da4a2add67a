"""lab_bdpt in participating media: both subpaths scatter in media, every strategy carries the
transmittance of its connecting segment, and the MIS weights see the densities of distance
sampling (exact in homogeneous media, deterministic stand-ins in heterogeneous ones).

Compiled only for scenes with media (``LightTracer.media``, ``CameraPass.media``); scenes
without keep the surface-only loops of ``light_subpath`` and ``camera_subpath`` unchanged.

**Subpaths.** A ray in a medium takes a free flight (``homogeneous_flight``: the analytic
inversion in the path's sampling channel c, as ``common.media.free_flight`` does in a
homogeneous medium): it collides at distance t with density sigma_t,c T_c(t), making a medium
vertex whose phase function stands in for the BSDF, or reaches the next surface with
probability T_c. The throughput is weighted per channel as the path family weights it, T / p_c
at the flight and sigma_s at a collision. A surface whose BSDF samples its null lobe (a ``null``
boundary, a mask's clear part) is passed without a vertex (Mitsuba's ``volpath`` counting of
``max_depth``), with probability P_null (the null lobe's sampling probability, 1 for ``null``),
and the medium is tracked across medium transitions. A surface with a smooth lobe is nonetheless
a vertex for the strategies that end there (NEE, connections, splats, merges) on every arrival,
as ``volpath`` samples emitters at a mask before its lobe is chosen: its f holds the opacity,
and only how the subpath goes on depends on the lobe sampled. A light subpath starts in its
emitter's medium, decided once per render for each emitter (``subpath_media.emitter_media``):
the one the scene names for it, else the one its emitted rays find behind the first medium
transition they meet through surfaces that transmit (an opaque lamp housing around a point light
hides the fog beyond it); an emitter at infinity in a homogeneous medium sends nothing (T = 0
over the infinite distance), and so does next-event estimation towards one whose shadow ray ends
in unbounded homogeneous fog (``common.media.transmittance``'s ``unbounded``; Mitsuba's ``volpath``
instead puts the emitter 2 bounding-sphere radii away). A heterogeneous medium is empty outside its
grid: light from infinity crosses it with the grid's transmittance, a ray that leaves the scene in
it flies only to the grid's far side (``media.within_grid``), and the weights' stand-in covers the
part of a piece inside the grid (``subpath_media.stand_in``). The camera subpath starts in the
sensor's medium.

**Densities.** A vertex x_i reached from x_{i-1} has the area density

    p_A(x_i) = p_W(x_{i-1} -> x_i) g(x_i) T_c(x_{i-1}, x_i) / |x_i - x_{i-1}|^2,

g = |cos| at a surface vertex and g = sigma_t,c at a medium vertex (no cosine there), T_c the
probability of passing the segment in channel c (the product of the flights' escape
probabilities T_c and of the P_null of the boundaries passed on the way); the reverse density
likewise with the other end's p_W. In Georgiev's recursion (``recursion.py``) a vertex's
reverse density and the next vertex's forward density cross the same segment, so T_c cancels in
``dvc`` and ``dvm`` and enters only ``dvcm`` (``Recursion.after_hit``'s ``transmittance``) and
the connecting segment of each strategy (passed with its cosines: ``g T_c`` at both ends of a
connection, at the camera vertex and the emitter of NEE, at a light vertex and the emitter
point joined to the sensor). Emitter sampling's density of x_0 has no T_c (no flight samples it).

**One channel per sample.** The sampling channel c is drawn per light subpath (uniform over
RGB's three; the hero wavelength in spectral variants; the only one in mono) by a hash of the
pass's light seed and the light lane, and the camera lanes paired with that light subpath use
the same c (``path_channel``). Given c every strategy samples with c's densities and every MIS
weight above is computed with them, so the weights sum to 1 over the strategies of each path for
each c, and each strategy's estimate, weighted per channel T / p_c, is unbiased for all channels
given c: the estimator is unbiased with c random. A connection's contribution carries the whole
spectrum's T (exact: Beer-Lambert in homogeneous media through null boundaries,
``common.media.transmittance``), its weight only T_c.

**Equi-angular sampling** (``camera_flight``): equi-angular NEE along each camera segment's first
flight, a second s = 1 technique whose density ratio rho enters the sums that hold s = 1's term, and
optionally a mixture of equi-angular and free flights, whose density ratio r enters ``after_hit``
(camera: ``forward``; light: ``backward``) and each connecting segment.

**Heterogeneous media** (``subpath_media.Tracking``, compiled only where the scene has one).
The subpaths' flights there are the path family's delta tracking (``common.media.free_flight``,
global majorants or ``majorants = grid``) and every connection's T is ratio tracking
(``common.media.transmittance``); the distance densities are then unknown. The weights instead
use, for every strategy alike, g = sigma_t,c(x) at a medium vertex and ``subpath_media.stand_in``
for each piece of a segment in a heterogeneous medium (exp of minus its length times sigma_t,c at
its midpoint, capped), deterministic and symmetric in the piece's ends. Unbiased: the weights of
a path's strategies, computed from the same positive values, still sum to 1 (tests/plugins/
test_bdpt_hetero_weights.py), and each strategy's contribution stays an unbiased estimate of f / p
with its own true density (delta tracking's weight and ratio tracking's T are), so their sum
estimates f. ``hide_emitters`` with media is refused.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import media, spawn
from mitsuba_lab.plugins.integrators.common.adjoint import adjoint_correction, transported
from mitsuba_lab.plugins.integrators.common.counters import tally
from mitsuba_lab.plugins.integrators.common.direct import spectrum_or_zero
from mitsuba_lab.plugins.integrators.common.roulette import russian_roulette
from mitsuba_lab.plugins.integrators.common.subpath_media import (
    _AUX_KEY, RngSampler, Sides, flight, medium_vertex, path_channel,
    phase_reverse_pdf, sigma_t_channel, start_medium, vertex_eval)
from mitsuba_lab.plugins.integrators.common.subpath_media import transmittance as through

from . import camera_flight, splats
from .endpoints import nee_density
from .media_connections import connect_to_light_subpath, splat_emitter, splat_vertex
from .techniques import Technique
from .vertices import NONE
from .weights import SubpathMis

@dr.syntax
def trace_light(tracer, st, block, vertices, store_lanes):
    """The light subpaths of ``LightTracer.trace`` in a scene with media, from the emitted
    ``st`` (its state after x_0 is sampled): the s = 1, t = 1 splat, then x_1, x_2, .. with
    their t = 1 splats and stored vertices. Returns what ``trace`` returns."""
    from .light_subpath import carried, float_or_zero, sensor_pdf, strategy_mask

    scene, sensor, table, w = tracer.scene, tracer.sensor, tracer.table, st.w
    floor, only = tracer.floor, tracer.only
    count, index, rng, ray = st.count, st.index, st.rng, mi.Ray3f(st.ray)
    emitter, ps, pmf, delta, infinite, on_surface = st.emitter, st.ps, st.pmf, st.delta, st.infinite, st.on_surface
    scale, cos_emit, pdf_pos, ds_0 = st.scale, st.cos_emit, st.pdf_pos, st.ds_0
    channel = path_channel(index, tracer.channel_key)
    aux_rng = mi.PCG32(count)
    aux_rng.seed(mi.sample_tea_64(index, dr.opaque(mi.UInt32, (tracer.channel_key ^ _AUX_KEY) & 0xFFFFFFFF)), index)
    aux = RngSampler(aux_rng)
    medium, extinguished = start_medium(tracer.emitter_media, st.emitter_index, infinite)
    phase_ctx = mi.PhaseFunctionContext(None, mi.TransportMode.Importance)
    tracing = Technique.LIGHT in w.techniques and tracer.reaches_sensor
    mix = camera_flight.mixture(tracer)      # (equi-angular camera flights: their densities here)

    # ---------------- s = 1, t = 1: the emitter point seen directly, through the media ----------------
    u0 = mi.Point2f(rng.next_float32(), rng.next_float32())
    if dr.hint(tracing, mode="scalar"):
        splat_emitter(tracer, st, block, ps, medium, u0, aux, channel, mix, scale)

    # ---------------- x_1, x_2, ..: the light subpath ----------------
    beta = mi.Spectrum(st.ray_weight) * st.sel_weight
    beta[extinguished] = 0.0
    beta_max0 = dr.max(mi.unpolarized_spectrum(beta))
    max_depth = dr.opaque(mi.UInt32, tracer.max_depth if tracer.max_depth > 0 else 0xFFFFFFFF)
    rr_depth = dr.opaque(mi.UInt32, tracer.rr_depth)
    ctx = mi.BSDFContext(mi.TransportMode.Importance)
    storing = vertices is not None and bool(w.techniques & (Technique.CONNECT | Technique.MERGE))
    camera_segments = 1 if w.merging else 2
    stores = dr.zeros(mi.UInt32, 1)
    capacity = dr.opaque(mi.UInt32, vertices.capacity if storing else 0)
    last = dr.full(mi.UInt32, NONE, count)
    dvcm, dvc, first = mi.Float(0), mi.Float(0), mi.Float(1)
    dvm = mi.Float(0) if w.merging else 0.0
    depth = mi.UInt32(0)
    vertices_reached = mi.UInt32(0)
    seg = mi.Float(1.0)                       # T_c of the segment since the last vertex
    prev_p = mi.Point3f(ps.p)
    d_0 = mi.Vector3f(ray.d)                  # the emitted direction (null boundaries keep it)
    # equi-angular camera flights: where the camera's first flight back along the segment ends
    # (the start of the light's last flight) and whether that is a collision (``camera_flight``)
    piece_o = mi.Point3f(ps.p) if mix is not None else 0.0
    piece_collides = mi.Bool(False) if mix is not None else False
    # equi-angular NEE: s = 1's term folded at the first vertex, until rho is known at the second
    eq_nee = mix is not None and mix.nee_all and not w.merging
    e_dvc, e_dvm, e_beyond = (mi.Float(0), mi.Float(0), mi.Float(dr.inf)) if eq_nee else (0.0, 0.0, 0.0)
    active = (beta_max0 > 0) & dr.isfinite(beta_max0) & (max_depth > 1)
    while dr.hint(active, max_iterations=-1, label="lab_bdpt light subpath in media"):
        si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=False, active=active)
        si = spawn.behind_null_face(scene, ray, si, floor, active)
        tally(tracer.counters, "light", active)
        in_medium = active & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
        mei, scattered, w_flight, p_flight = flight(medium, ray, si.t, rng.next_float32(), aux, channel, in_medium,
                                                    tracer.tracking)
        beta[in_medium] *= w_flight
        seg[in_medium] *= p_flight
        surface = active & ~scattered & si.is_valid()
        bsdf = si.bsdf()
        u_lobe, u_dir = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
        bs, bsdf_weight = bsdf.sample(ctx, si, u_lobe, u_dir, surface)
        passing = surface & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        vertex = scattered | (surface & ~passing)
        vertices_reached += dr.select(vertex, 1, 0)
        # A surface with a smooth lobe is x_at for the strategies that end here (splat, stored for
        # connections) whichever lobe was sampled: a mask's f holds its opacity, and the pass
        # (null lobe) only decides how the subpath goes on.
        smooth = scattered | (surface & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth))
        at = depth + 1

        # ---------- the vertex x_at: a surface point or a medium point ----------
        v = mi.SurfaceInteraction3f(si)
        v[scattered] = medium_vertex(mei, ray.wavelengths)
        phase = mei.medium.phase_function()
        phase[~scattered] = dr.zeros(mi.PhaseFunctionPtr)
        sigma_c = media.channel_value(mei.sigma_t, channel)
        g_in = dr.select(scattered, sigma_c, dr.abs(dr.dot(si.n, ray.d)))
        dist2 = dr.squared_norm(v.p - prev_p)
        start_here = (vertex | smooth) & (depth == 0)
        # x_0's emitter-sampling density, from x_1 (no transmittance: emitter sampling picks it)
        ds_0.d = dr.select(infinite, -d_0, dr.normalize(ds_0.p - v.p))
        ds_0.dist = dr.select(infinite, dr.inf, dr.norm(ds_0.p - v.p))
        pdf_nee = dr.select(delta, pmf, nee_density(scene, v, ds_0, infinite, start_here & ~delta))
        pdf_dir_0 = table.emission(emitter, cos_emit, pdf_nee, start_here, ds_0.p, d_0)[1]
        start = w.start_light(pdf_pos * pdf_dir_0, pdf_nee, cos_emit, delta)
        dvcm = dr.select(start_here, start.dvcm, dvcm)
        dvc = dr.select(start_here, start.dvc, dvc)
        dist2 = dr.select(start_here & infinite, 1.0, dist2)    # x_0 is a direction: no distance
        depth[vertex] = at
        if dr.hint(mix is None, mode="scalar"):
            mis = w.after_hit(SubpathMis(dvcm, dvc, first, dvm), dist2, g_in, seg)
        else:                                  # the camera's density of the previous vertex
            back = camera_flight.ratio(mix, medium, v.p, piece_o, piece_collides, ray.wavelengths, channel,
                                       in_medium & ~(start_here & infinite))
            mis = w.after_hit(SubpathMis(dvcm, dvc, first, dvm), dist2, g_in, seg, backward=back)
        if dr.hint(eq_nee, mode="scalar"):
            second = in_medium & piece_collides & (at == 2)
            rho = camera_flight.rho(mix, medium, v.p, piece_o, dr.norm(v.p - piece_o) + e_beyond, back,
                                    ray.wavelengths, channel, second)
            e_after = w.after_hit(SubpathMis(0.0 * e_dvc, e_dvc, first, e_dvm), dist2, g_in, seg, backward=back)
            mis = w.add_equiangular(mis, e_after, dr.select(second, rho, 0.0))
        splat_on = smooth & strategy_mask(only, at + 1, 1)
        # the medium on the far side of a surface vertex (a medium transition's other side)
        beyond = dr.select(surface & si.is_medium_transition(), si.target_medium(ray.d), medium)

        # ---------- store x_at for connections with camera vertices ----------
        if dr.hint(storing, mode="scalar"):
            store = smooth & (at + camera_segments <= max_depth)
            if dr.hint(store_lanes is not None and store_lanes < count, mode="scalar"):
                store &= index < dr.opaque(mi.UInt32, store_lanes)
            slot = dr.scatter_inc(stores, mi.UInt32(0), store)
            kept = store & (slot < capacity)
            vertices.store(slot, v, -ray.d, beta, mis, at, last, kept, tracer.weights.lane_iteration(index),
                           bsdf=dr.select(scattered, dr.zeros(mi.BSDFPtr), bsdf))
            vertices.store_media(slot, medium, beyond, kept)
            last = dr.select(kept, slot, last)

        # ---------- t = 1: join x_at to the sensor, through the media ----------
        u_sensor = mi.Point2f(rng.next_float32(), rng.next_float32())
        if dr.hint(tracing, mode="scalar"):
            sides = Sides(si.n, dr.dot(si.n, ray.d), scattered, medium, beyond)
            splat_vertex(tracer, w, block, v, si, bsdf, mei, phase, scattered, sides, beta, mis, sigma_c, u_sensor,
                         splat_on, aux, channel, mix, scale, at)

        # ---------- the next direction: adjoint BSDF sampling, or the phase function ----------
        going = vertex & (depth + 1 < max_depth)
        wo_phase, phase_weight, phase_pdf = phase.sample(phase_ctx, mei, u_lobe, u_dir, going & scattered)
        rev_phase = phase_reverse_pdf(phase, phase_ctx, mei, wo_phase, going & scattered)
        wo_world = dr.select(scattered, wo_phase, si.to_world(bs.wo))
        delta_lobe = ~scattered & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        sent, rev_surface = transported(bsdf, si, bs.wo, going & ~scattered & ~delta_lobe)
        smooth_weight = sent / dr.maximum(bs.pdf, 1e-30)
        surface_weight = dr.select(delta_lobe, bsdf_weight * adjoint_correction(si, -ray.d, bs.wo),
                                   dr.select(bs.pdf > 0, smooth_weight, 0.0))
        beta[going] *= dr.select(scattered, mi.Spectrum(phase_weight), surface_weight)
        scattered_mis = w.scatter_light(mis, dr.select(scattered, phase_pdf, bs.pdf),
                                        dr.select(scattered, rev_phase, rev_surface),
                                        dr.select(scattered, sigma_c, dr.abs(dr.dot(si.n, wo_world))), delta_lobe,
                                        scattered)
        if dr.hint(eq_nee, mode="scalar"):
            e_first = going & scattered & (at == 1)
            e_term = w.equiangular_term(mis, phase_pdf, sigma_c)
            e_dvc, e_dvm = dr.select(e_first, e_term.dvc, 0.0), dr.select(e_first, e_term.dvm, 0.0)
            e_beyond = dr.select(e_first, camera_flight.beyond(scene, v.p, -wo_phase, e_first), dr.inf)
        dvcm = dr.select(vertex, float_or_zero(scattered_mis.dvcm), dvcm)
        dvc = dr.select(vertex, float_or_zero(scattered_mis.dvc), dvc)
        first = dr.select(vertex, mi.Float(scattered_mis.first), first)
        dvm = carried(w.merging, dr.select(vertex, scattered_mis.dvm, dvm), dvm)
        prev_p[vertex] = v.p
        seg[vertex] = 1.0
        if dr.hint(mix is not None, mode="scalar"):
            piece_o[vertex | passing] = v.p
            piece_collides = dr.select(vertex | passing, scattered, piece_collides)
        # ---------- a null boundary: passed, no vertex ----------
        seg[passing] *= bs.pdf
        beta[passing] *= bsdf_weight
        direction = dr.select(passing, ray.d, wo_world)
        medium[surface & si.is_medium_transition()] = si.target_medium(direction)
        ray = spawn.spawn_ray(v, direction, floor)

        active = going | passing
        beta_max = dr.max(mi.unpolarized_spectrum(beta))
        active &= (beta_max > 0) & dr.isfinite(beta_max)
        beta, survives = russian_roulette(beta, rng.next_float32(), vertex & (depth >= rr_depth), start=beta_max0)
        active &= survives
    reached = dr.zeros(mi.UInt32, 1)
    dr.scatter_reduce(dr.ReduceOp.Add, reached, vertices_reached, 0, mode=dr.ReduceMode.Local)
    return reached, stores, last


# ------------------------------------------------------------------------------------------
# Camera subpaths
# ------------------------------------------------------------------------------------------
@dr.syntax
def trace_camera(scene: mi.Scene, cp, sampler: mi.Sampler, ray: mi.Ray3f, medium, active):
    """(L, valid) of the camera subpaths in a scene with media (``camera_subpath.
    trace_camera_subpaths``'s strategies, t >= 2), starting in the sensor's ``medium``."""
    from dataclasses import replace

    from .light_subpath import carried, float_or_zero, reverse_pdf, strategy_mask

    lanes = dr.width(ray)
    lane = dr.arange(mi.UInt32, lanes)
    # (lab_vcm: the lane's merging iteration, from the pass's tables, which ``at_lanes`` drops)
    iteration = cp.weights.lane_iteration(lane)
    cp = replace(cp, weights=cp.weights.at_lanes(lane))
    w, table, floor = cp.weights, cp.table, cp.offset_floor
    ctx = mi.BSDFContext(mi.TransportMode.Radiance)
    ctx_imp = mi.BSDFContext(mi.TransportMode.Importance)
    phase_ctx = mi.PhaseFunctionContext(sampler)
    max_depth = dr.opaque(mi.UInt32, cp.max_depth)
    rr_depth = dr.opaque(mi.UInt32, cp.rr_depth)
    emitter_hits = cp.emitter_hits and Technique.HIT in w.techniques
    merging = cp.grid is not None                      # (lab_vcm: surface and medium vertices merge)

    if dr.hint(cp.light_count < lanes, mode="scalar"):
        lane = lane % dr.opaque(mi.UInt32, cp.light_count)
    head = dr.gather(mi.UInt32, cp.last, lane)
    channel = path_channel(lane, cp.channel_key)       # the light subpath's channel
    medium = mi.MediumPtr(medium) if medium is not None else dr.zeros(mi.MediumPtr, lanes)
    medium = dr.select(dr.full(mi.Bool, True, lanes), medium, medium)
    active = mi.Bool(active) & dr.full(mi.Bool, True, lanes)
    cos_cam = dr.dot(ray.d, mi.Vector3f(*cp.axis))
    start = w.start_camera(dr.opaque(mi.Float, cp.inv_image_area) / (cos_cam * dr.square(cos_cam)), cp.sensor_delta)
    dvcm, dvc, first = mi.Float(start.dvcm), mi.Float(start.dvc), mi.Float(start.first)
    dvm = mi.Float(start.dvm) if merging else 0.0
    L = mi.Spectrum(0)
    beta = mi.Spectrum(1)
    eta = mi.Float(1)
    depth = mi.UInt32(0)
    prev_it = dr.zeros(mi.Interaction3f)
    prev_it.p = ray.o
    valid_ray = active & (scene.environment() is not None)
    prev_p = mi.Point3f(ray.o)
    seg = mi.Float(1.0)
    # equi-angular flights (``camera_flight``): on a segment's first flight (``fresh``); ``r_first``
    # its density ratio once that flight ended at a null surface
    mix = cp.equiangular if cp.equiangular is not None and cp.equiangular.on else None
    fresh = dr.full(mi.Bool, True, lanes) if mix is not None else True
    r_first = dr.full(mi.Float, 1.0, lanes) if mix is not None else 1.0
    eq_nee = mix is not None and mix.nee and not merging     # equi-angular NEE, and rho of the last vertex
    rho_prev = dr.zeros(mi.Float, lanes) if eq_nee else None
    pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
    tally(cp.counters, "camera", active)

    if dr.hint(not w.techniques & (Technique.HIT | Technique.NEE | Technique.CONNECT | Technique.MERGE), mode="scalar"):
        return mi.Spectrum(0), valid_ray | (active & pi.is_valid())

    while dr.hint(active, max_iterations=-1, label="lab_bdpt camera subpath in media"):
        si = pi.compute_surface_interaction(ray, ray_flags=mi.RayFlags.All, active=active)
        si = spawn.behind_null_face(scene, ray, si, floor, active)
        in_medium = active & (medium != None)  # noqa: E711 (Dr.Jit pointer test)
        if dr.hint(eq_nee, mode="scalar"):
            L += camera_flight.equiangular_nee(scene, cp, mix, sampler, ray, si, medium, beta,
                                               SubpathMis(dvcm, dvc, first, dvm), prev_p, depth + 1, channel, phase_ctx,
                                               in_medium & fresh & medium.is_homogeneous() & (depth + 1 < max_depth)
                                               & camera_flight.nee_segment(mix, depth))
        u_flight = sampler.next_1d()
        flown = flight(medium, ray, si.t, u_flight, sampler, channel, in_medium, cp.tracking)
        if dr.hint(mix is not None and mix.mixes, mode="scalar"):
            flown = camera_flight.flight(mix, medium, ray, si.t, u_flight, sampler.next_1d(), channel,
                                         in_medium & fresh & medium.is_homogeneous(), flown)
        mei, scattered, w_flight, p_flight = flown
        beta[in_medium] *= w_flight
        seg[in_medium] *= p_flight
        arrived = active & ~scattered
        escaped = arrived & ~si.is_valid()
        surface = arrived & si.is_valid()
        here = depth + 1                          # segments from the sensor to this vertex
        bsdf = si.bsdf(ray)
        bs, bsdf_weight = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), surface)
        passing = surface & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        vertex = scattered | (surface & ~passing)
        v = mi.SurfaceInteraction3f(si)
        v[scattered] = medium_vertex(mei, ray.wavelengths)
        phase = mei.medium.phase_function()
        phase[~scattered] = dr.zeros(mi.PhaseFunctionPtr)
        sigma_c = media.channel_value(mei.sigma_t, channel)
        g_in = dr.select(scattered, sigma_c, dr.select(escaped, 1.0, dr.abs(dr.dot(si.n, ray.d))))
        dist2 = dr.select(escaped, 1.0, dr.squared_norm(v.p - prev_p))
        if dr.hint(mix is None, mode="scalar"):
            mis = w.after_hit(SubpathMis(dvcm, dvc, first, dvm), dist2, g_in, seg)
        else:                                  # the mixture's density of this vertex (``camera_flight``)
            r_here = camera_flight.ratio(mix, medium, prev_p, v.p, scattered, ray.wavelengths, channel,
                                         in_medium & fresh & ~escaped)
            r_here = dr.select(fresh, r_here, r_first)
            mis = w.after_hit(SubpathMis(dvcm, dvc, first, dvm), dist2, g_in, seg, forward=r_here)
        rho_here = None
        if dr.hint(eq_nee, mode="scalar"):
            t_s = dr.select(si.is_valid(), dr.norm(si.p - prev_p), dr.inf)
            rho_here = camera_flight.rho(mix, medium, prev_p, v.p, t_s, r_here, ray.wavelengths, channel,
                                         scattered & fresh & camera_flight.nee_segment(mix, depth))

        # ---------------- s = 0: the camera subpath reaches an emitter ----------------
        if dr.hint(emitter_hits, mode="scalar"):
            emitter = si.emitter(scene)
            hit = arrived & (emitter != None) & strategy_mask(cp.only, 0, here + 1)  # noqa: E711
            infinite = table.at_infinity(emitter, hit)
            ds = mi.DirectionSample3f(scene, si=si, ref=prev_it)
            pdf_nee = nee_density(scene, prev_it, ds, infinite, hit & ((here > 1) | ~infinite))
            cos_light = dr.select(infinite, 1.0, dr.abs(dr.dot(si.n, ray.d)))
            pdf_pos, pdf_dir, _ = table.emission(emitter, cos_light, pdf_nee, hit, si.p, -ray.d)
            w_hit = w.hit(mis, pdf_nee, pdf_pos * pdf_dir, dr.select(infinite, 0.0, pdf_pos),
                          **({"rho": rho_prev} if eq_nee else {}))    # (lab_vcm's ppm weights take none)
            L += beta * float_or_zero(w_hit) * emitter.eval(si, hit)

        # a surface with a smooth lobe is x_here for NEE, connections and merges whichever lobe
        # was sampled (as at a light vertex: the mask's f holds its opacity)
        smooth = scattered | (surface & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth))
        going = vertex & (here < max_depth)
        beyond = dr.select(surface & si.is_medium_transition(), si.target_medium(ray.d), medium)
        sides = Sides(si.n, dr.dot(si.n, ray.d), scattered, medium, beyond)

        # ---------------- s = 1: next-event estimation, through the media ----------------
        nee_on = smooth & (here < max_depth) & strategy_mask(cp.only, 1, here + 1) & (Technique.NEE in w.techniques)
        ds, em_weight = scene.sample_emitter_direction(v, sampler.next_2d(), False, nee_on)
        tally(cp.counters, "shadow", nee_on)
        nee_on &= ds.pdf > 0
        # an emitter at infinity seen through unbounded fog sends nothing (T = 0 over the infinite
        # distance), as its light subpaths carry nothing (``trace_light``)
        infinite = table.at_infinity(ds.emitter, nee_on)
        T, T_c = through(scene, sides.toward(ds.d), v, ds.p, sampler, channel, floor, nee_on, cp.tracking,
                         unbounded=infinite)
        f, pdf_fwd, pdf_rev = vertex_eval(ctx, ctx_imp, phase_ctx, si, bsdf, mei, phase, scattered, ds.d, nee_on)
        dist2 = dr.select(infinite, 1.0, dr.square(ds.dist))
        cos_light = dr.select(ds.delta | infinite, 1.0, dr.abs(dr.dot(ds.n, ds.d)))
        pdf_nee = dr.select(ds.delta, ds.pdf, ds.pdf * cos_light / dist2)
        pdf_pos, pdf_dir, delta = table.emission(ds.emitter, cos_light, pdf_nee, nee_on, ds.p, -ds.d)
        g_cam = dr.select(scattered, sigma_c, dr.abs(dr.dot(si.n, ds.d)))
        r = camera_flight.segment_ratio(scene, mix, sides.toward(ds.d), v, ds.p, False, floor, channel, nee_on)
        w_nee = w.nee(mis, pdf_nee, pdf_pos * pdf_dir, cos_light * T_c * r, g_cam * T_c, dist2, pdf_fwd, pdf_rev,
                      delta, here, scattered, rho=rho_here)
        L += dr.select(nee_on, spectrum_or_zero(beta * f * em_weight * mi.Spectrum(T) * float_or_zero(w_nee)), 0.0)

        # ---------------- s >= 2: connections to the light subpath ----------------
        if dr.hint(Technique.CONNECT in w.techniques, mode="scalar"):
            L += connect_to_light_subpath(scene, cp, v, si, bsdf, mei, phase, scattered, sides, beta, mis, here,
                                          head, smooth & (here + 2 <= max_depth), sampler, channel, phase_ctx)

        # ---------------- merging: light vertices on the surface or in the ball around (lab_vcm) ----------------
        if dr.hint(merging, mode="scalar"):
            merge_on = smooth & (here < max_depth) & w.merges_at(here)
            u_merge = sampler.next_1d() if w.merge_bounded else None
            L += cp.grid.merge(cp, si, bsdf, beta, mis, here, iteration, merge_on & ~scattered, u_merge)
            L += cp.grid.volume.merge(cp, mei, phase, beta, mis, here, iteration, merge_on & scattered, u_merge)

        # ---------------- the next direction: the BSDF sample, or the phase function ----------------
        wo_phase, phase_weight, phase_pdf = phase.sample(phase_ctx, mei, sampler.next_1d(), sampler.next_2d(),
                                                         going & scattered)
        rev_phase = phase_reverse_pdf(phase, phase_ctx, mei, wo_phase, going & scattered)
        wo_world = dr.select(scattered, wo_phase, si.to_world(bs.wo))
        rev_surface = reverse_pdf(bsdf, ctx_imp, si, bs.wo, going & ~scattered)
        delta_lobe = ~scattered & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        scattered_mis = w.scatter_camera(mis, dr.select(scattered, phase_pdf, bs.pdf),
                                         dr.select(scattered, rev_phase, rev_surface),
                                         dr.select(scattered, sigma_c, dr.abs(dr.dot(si.n, wo_world))),
                                         delta_lobe, here, scattered)
        dvcm = dr.select(vertex, float_or_zero(scattered_mis.dvcm), dvcm)
        dvc = dr.select(vertex, float_or_zero(scattered_mis.dvc), dvc)
        first = dr.select(vertex, mi.Float(scattered_mis.first), first)
        dvm = carried(merging, dr.select(vertex, scattered_mis.dvm, dvm), dvm)
        beta[going] *= dr.select(scattered, mi.Spectrum(phase_weight), bsdf_weight)
        eta[going & ~scattered] *= bs.eta
        valid_ray |= vertex
        prev_it[vertex] = v
        prev_p[vertex] = v.p
        seg[vertex] = 1.0
        depth[vertex] = here
        if dr.hint(mix is not None, mode="scalar"):
            r_first = dr.select(vertex, 1.0, dr.select(passing & fresh, r_here, r_first))
            fresh = vertex | (fresh & ~passing)
        if dr.hint(eq_nee, mode="scalar"):
            rho_prev = dr.select(vertex, rho_here, rho_prev)
        # ---------------- a null boundary: passed, no vertex ----------------
        seg[passing] *= bs.pdf
        beta[passing] *= bsdf_weight
        direction = dr.select(passing, ray.d, wo_world)
        medium[surface & si.is_medium_transition()] = si.target_medium(direction)
        ray = spawn.spawn_ray(v, direction, floor)

        active_next = going | passing
        beta_max = dr.max(mi.unpolarized_spectrum(beta))
        active_next &= (beta_max != 0) & dr.isfinite(beta_max)
        beta, survives = russian_roulette(beta, sampler.next_1d(), vertex & (depth >= rr_depth), eta=eta)
        active_next &= survives
        if dr.hint(merging and cp.grid.first_only, mode="scalar"):
            # lab_vcm's ppm: the merge took the smooth lobes' (and the phase function's) light
            active_next &= passing | ~smooth | delta_lobe
        pi = scene.ray_intersect_preliminary(ray, coherent=False, active=active_next)
        tally(cp.counters, "extension", active_next)
        active = active_next
    return L, valid_ray
