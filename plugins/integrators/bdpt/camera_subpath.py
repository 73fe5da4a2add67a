"""Camera subpaths and every strategy with t >= 2 camera vertices, in one symbolic loop.

A camera subpath x_k, x_{k-1}, .. (x_k on the sensor) is traced with BSDF sampling and the
lab's Russian roulette, as ``lab_mis`` traces its paths. At each camera vertex, with beta the
camera throughput and w the MIS weight of the strategy (``weights.BdptWeights``):

* s = 0, the vertex lies on an emitter:          L += beta w L_e
* s = 1, next-event estimation (one shadow ray): L += beta w f_s L_e G / p_nee
* s >= 2, a connection to each stored vertex y of the lane's own light subpath
  (``vertices.LightVertices``, walked from its end), one shadow ray each:
                                                 L += beta f_s(x) G(x, y) f_s*(y) beta_y w
  (lab_vcm's ``connections = one``: to one of them, picked uniformly from the n usable ones,
  counted n times)

f_s* is the adjoint BSDF at the light vertex (importance transport, with Veach's shading-normal
correction), and G = 1 / |x - y|^2 (the cosines are in f_s and f_s*). The t = 1 strategy is
traced on the light side (``light_subpath.py``). Camera lane i is paired with light subpath i
of the same pass: subpaths of different lanes are independent, so every strategy's estimate is
unbiased and the weights sum to 1 over the strategies of any path.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import spawn
from mitsuba_lab.plugins.integrators.common.counters import tally
from mitsuba_lab.plugins.integrators.common.adjoint import transported
from mitsuba_lab.plugins.integrators.common.direct import spectrum_or_zero
from mitsuba_lab.plugins.integrators.common.roulette import kept, russian_roulette

from .endpoints import EmitterTable, direction_is_delta, nee_density
from .light_subpath import carried, depth_bound, float_or_zero, reverse_pdf, strategy_mask
from .vertices import NONE, LightVertices
from .techniques import Strategy, Technique
from .weights import BdptWeights, SubpathMis


@dataclass
class CameraPass:
    """What the camera subpaths of one pass read: the pass's light vertices (``last``: each light
    lane's last stored slot), the weights, the emitter table and the sensor's constants
    (``inv_image_area``: 1 / A', its direction density on the optical axis; ``axis``: the
    optical axis in world space); ``light_count``: the pass's light subpaths."""
    vertices: LightVertices
    last: mi.UInt32
    weights: BdptWeights
    table: EmitterTable
    inv_image_area: float
    axis: tuple
    max_depth: int                       # (or a UInt32 per lane: lab_mmlt's, ``depth_bound``)
    rr_depth: int
    hide_emitters: bool
    offset_floor: float
    emitter_hits: bool
    only: Strategy | None = None
    light_count: int = 0                 # light subpaths of the pass (camera lane i uses i mod it)
    grid: object = None                  # lab_vcm: the light vertices' grid (``merge``), else None
    connect_share: float = 0.0           # lab_vcm: connections' Russian roulette (``connection_roulette``)
    connect_one: bool = False            # lab_vcm: one connection per camera vertex (``connect_to_one_light_vertex``)
    counters: object = None              # ``counters.RayCounters`` when counting rays (count_rays), else None
    sensor_delta: bool = False           # the sensor's direction is a delta (orthographic): no t = 1
    media: bool = False                  # the scene has (homogeneous) media: ``media_paths``' loops
    channel_key: int = 0                 # in media: the key of each light subpath's sampling channel
    sensor_medium: object = None         # in media: the sensor's medium (the camera subpaths start in it)
    camera_depth: object = None          # lab_mmlt: per lane, the last camera vertex its one strategy needs
    tracking: object = None              # heterogeneous media: ``subpath_media.Tracking``, else None
    equiangular: object = None           # in media: ``camera_flight.EquiangularMixture``, else None (off)


def sensor_constants(sensor: mi.Sensor, plugin: str = "lab_bdpt") -> tuple[float, tuple]:
    """(1 / A', optical axis) of a pinhole sensor, from ``sample_direction`` at a point on its
    axis, where the direction density 1 / (A' cos^3) is 1 / A' (errors name ``plugin``). An
    orthographic sensor has no direction density (its direction is a delta,
    ``CameraPass.sensor_delta``): 1 in its place."""
    to_world = sensor.world_transform()
    if direction_is_delta(sensor):
        return 1.0, _axis(to_world)
    near = float(sensor.near_clip()) if hasattr(sensor, "near_clip") else 1e-2
    far = float(sensor.far_clip()) if hasattr(sensor, "far_clip") else 1e4
    z = (near * far) ** 0.5
    it = dr.zeros(mi.Interaction3f)
    it.p = to_world @ mi.Point3f(0, 0, z)
    ds, importance = sensor.sample_direction(it, mi.Point2f(0.5, 0.5))
    value = float(dr.max(mi.unpolarized_spectrum(importance))[0]) * z * z
    if not value > 0:
        raise ValueError(f"{plugin}: the sensor's principal point lies outside its crop window, which is "
                         "not supported")
    return value, _axis(to_world)


def _axis(to_world) -> tuple:
    """The sensor's optical axis (its local +z) in world space."""
    axis = dr.normalize(to_world @ mi.Vector3f(0, 0, 1))
    return (float(axis.x[0]), float(axis.y[0]), float(axis.z[0]))


def connection_roulette(value, estimate, share: float, u, depth_y):
    """(whether a connection of unoccluded contribution ``value`` runs; the factor it then
    counts): below ``share`` of the lane's ``estimate`` so far it runs with probability
    value / (share x estimate), decided by a hash of the uniform ``u`` and the light vertex's
    depth ``depth_y`` (one per vertex of a light subpath; not its slot, which the light pass's
    atomics number differently from run to run), and counts 1 / that probability (unbiased;
    its shadow ray is skipped otherwise). Connections that could only add a sliver to the pixel
    seldom pay for their shadow ray."""
    scale = dr.max(mi.unpolarized_spectrum(estimate)) * share
    probability = dr.select(scale > 0, dr.minimum(1.0, dr.max(mi.unpolarized_spectrum(value)) / scale), 1.0)
    return kept(probability, mi.sample_tea_float32(dr.reinterpret_array(mi.UInt32, u), depth_y))


def connection(scene, cp: CameraPass, si, bsdf, beta, mis: SubpathMis, depth, slot, on, estimate, u, scale=1.0):
    """(weighted contribution, light vertex's previous slot) of the connection from camera vertex
    ``si`` (``depth`` segments from the sensor) to the stored light vertex at ``slot`` (lanes
    ``on``), counted ``scale`` times; with ``cp.connect_share`` > 0, under ``connection_roulette``
    against the lane's ``estimate`` so far, for the uniform ``u``."""
    w, floor = cp.weights, cp.offset_floor
    ctx = mi.BSDFContext(mi.TransportMode.Radiance)
    ctx_imp = mi.BSDFContext(mi.TransportMode.Importance)
    max_depth = depth_bound(cp.max_depth)
    y, bsdf_y, beta_y, mis_y, depth_y, prev = cp.vertices.load(slot, si.wavelengths, on)
    use = on & (depth_y + 1 + depth <= max_depth) & strategy_mask(cp.only, depth_y + 1, depth + 1)
    d = y.p - si.p
    dist2 = dr.squared_norm(d)
    d = d * dr.rsqrt(dist2)
    wo_x, wo_y = si.to_local(d), y.to_local(-d)
    f_x, pdf_x_fwd = bsdf.eval_pdf(ctx, si, wo_x, use)
    pdf_x_rev = reverse_pdf(bsdf, ctx_imp, si, wo_x, use)
    f_y, pdf_y_rev = transported(bsdf_y, y, wo_y, use)
    pdf_y_fwd = bsdf_y.pdf(ctx_imp, y, wo_y, use)
    weight = w.connect(mis_y, mis, pdf_y_fwd, pdf_y_rev, pdf_x_fwd, pdf_x_rev,
                       dr.abs(dr.dot(y.n, d)), dr.abs(dr.dot(si.n, d)), dist2, depth)
    value = spectrum_or_zero(beta * f_x * f_y * beta_y * (float_or_zero(weight) * scale / dist2))
    use &= dr.max(mi.unpolarized_spectrum(value)) > 0
    if cp.connect_share > 0:
        taken, factor = connection_roulette(value, estimate, cp.connect_share, u, depth_y)
        use &= taken
        value *= factor
    tally(cp.counters, "connection", use)
    use &= ~scene.ray_test(spawn.spawn_ray_to(si, y.p, floor), use)
    return dr.select(use, value, 0.0), prev


@dr.syntax
def connect_to_light_subpath(scene, cp: CameraPass, si, bsdf, beta, mis: SubpathMis, depth, head, active,
                             estimate=None, u=None):
    """The s >= 2 strategies at camera vertex ``si`` (``depth`` segments from the sensor): the
    weighted contributions of its connections to every stored vertex of the light subpath that
    ends at slot ``head`` (``connection``)."""
    L = dr.zeros(mi.Spectrum, dr.width(head))
    slot = dr.select(active, head, NONE)
    while dr.hint(slot != NONE, max_iterations=-1, label="lab_bdpt connections"):
        on = slot != NONE
        value, prev = connection(scene, cp, si, bsdf, beta, mis, depth, slot, on, estimate, u)
        L += value
        slot = dr.select(on, prev, NONE)
    return L


@dr.syntax
def pick_light_vertex(cp: CameraPass, head, depth, active, u):
    """(slot, n): one of the n stored vertices of the light subpath ending at ``head`` that a
    connection from a camera vertex ``depth`` segments from the sensor may use, each with
    probability 1 / n (reservoir sampling along the list, hashing the uniform ``u`` with the
    count so far); NONE where n = 0. Walking the list reads two numbers per vertex."""
    max_depth = depth_bound(cp.max_depth)
    key = dr.reinterpret_array(mi.UInt32, u)
    chosen = dr.full(mi.UInt32, NONE, dr.width(head))
    n = dr.zeros(mi.UInt32, dr.width(head))
    slot = dr.select(active, head, NONE)
    while dr.hint(slot != NONE, max_iterations=-1, label="lab_vcm pick a light vertex"):
        on = slot != NONE
        depth_y, prev = cp.vertices.depth_and_prev(slot, on)
        ok = on & (depth_y + 1 + depth <= max_depth) & strategy_mask(cp.only, depth_y + 1, depth + 1)
        n += dr.select(ok, 1, 0)
        take = ok & (mi.sample_tea_float32(key, n) * mi.Float(n) < 1.0)
        chosen = dr.select(take, slot, chosen)
        slot = dr.select(on, prev, NONE)
    return chosen, n


def connect_to_one_light_vertex(scene, cp: CameraPass, si, bsdf, beta, mis: SubpathMis, depth, head, active,
                                estimate, u, u_pick):
    """lab_vcm's ``connections = one``: the connection to one vertex of the lane's light subpath,
    picked uniformly from the n it may use (``pick_light_vertex``) and counted n times, so its
    expectation is the sum over all n (unbiased; the weights count each connection technique
    1 / L times, L the mean stored vertices per light subpath: ``BdptWeights`` connect_count)."""
    slot, n = pick_light_vertex(cp, head, depth, active, u_pick)
    on = slot != NONE
    value, _ = connection(scene, cp, si, bsdf, beta, mis, depth, dr.select(on, slot, 0), on, estimate, u,
                          mi.Float(n))
    return value


@dr.syntax
def trace_camera_subpaths(scene: mi.Scene, cp: CameraPass, sampler: mi.Sampler, ray: mi.Ray3f, active):
    """(L, valid) of the camera subpaths of the lanes of ``ray``: every strategy with t >= 2."""
    lanes = dr.width(ray)
    lane = dr.arange(mi.UInt32, lanes)
    iteration = cp.weights.lane_iteration(lane)              # (lab_vcm: the lane's merging iteration)
    cp = replace(cp, weights=cp.weights.at_lanes(lane))
    w, table, floor = cp.weights, cp.table, cp.offset_floor
    ctx = mi.BSDFContext(mi.TransportMode.Radiance)
    ctx_imp = mi.BSDFContext(mi.TransportMode.Importance)
    max_depth = depth_bound(cp.max_depth)
    rr_depth = dr.opaque(mi.UInt32, cp.rr_depth)
    emitter_hits, hide = cp.emitter_hits and Technique.HIT in w.techniques, cp.hide_emitters

    if dr.hint(cp.light_count < lanes, mode="scalar"):
        lane = lane % dr.opaque(mi.UInt32, cp.light_count)   # fewer light subpaths: shared
    head = dr.gather(mi.UInt32, cp.last, lane)
    active = mi.Bool(active) & dr.full(mi.Bool, True, lanes)
    cos_cam = dr.dot(ray.d, mi.Vector3f(*cp.axis))
    start = w.start_camera(dr.opaque(mi.Float, cp.inv_image_area) / (cos_cam * dr.square(cos_cam)), cp.sensor_delta)
    dvcm, dvc, first = mi.Float(start.dvcm), mi.Float(start.dvc), mi.Float(start.first)
    merging = cp.grid is not None
    dvm = mi.Float(start.dvm) if merging else 0.0
    pending = mi.Float(0) if w.caustic else 0.0      # (caustic_merges: the last vertex's merge term)
    L = mi.Spectrum(0)
    beta = mi.Spectrum(1)
    eta = mi.Float(1)
    depth = mi.UInt32(0)
    prev_it = dr.zeros(mi.Interaction3f)
    prev_it.p = ray.o                          # the sensor: where a textured light seen directly is seen from
    # Mitsuba's meaning: with an environment every pixel is valid, unless hide_emitters
    valid_ray = active & ((scene.environment() is not None) and not hide)
    prev_p = mi.Point3f(ray.o)                 # where the segment to the next vertex starts
    pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)
    tally(cp.counters, "camera", active)
    if dr.hint(hide and emitter_hits, mode="scalar"):
        ray, pi = spawn.pass_through_emitters(scene, ray, pi, active, floor)

    if dr.hint(not w.techniques & (Technique.HIT | Technique.NEE | Technique.CONNECT | Technique.MERGE), mode="scalar"):
        # light tracing alone: the camera ray only tells which pixels see something (alpha)
        return mi.Spectrum(0), valid_ray | (active & pi.is_valid())

    while dr.hint(active, max_iterations=-1, label="lab_bdpt camera subpath"):
        si = pi.compute_surface_interaction(ray, ray_flags=mi.RayFlags.All, active=active)
        depth += dr.select(active, 1, 0)       # an escaped ray's segment ends at the environment
        escaped = active & ~si.is_valid()
        # (the segment's length from its start: a camera ray that passed through emitters began
        # at the sensor, not where it last left an emitter; to the environment: 1, see endpoints)
        mis = w.after_hit(SubpathMis(dvcm, dvc, first, dvm, 1.0, pending),
                          dr.select(escaped, 1.0, dr.squared_norm(si.p - prev_p)),
                          dr.select(escaped, 1.0, dr.abs(dr.dot(si.n, ray.d))))

        # ---------------- s = 0: the camera subpath hits an emitter ----------------
        if dr.hint(emitter_hits, mode="scalar"):
            emitter = si.emitter(scene)        # the environment for an escaped ray
            hit = active & (emitter != None) & strategy_mask(cp.only, 0, depth + 1)  # noqa: E711 (pointer test)
            if dr.hint(hide, mode="scalar"):
                hit &= depth > 1               # the environment seen directly is hidden too
            infinite = table.at_infinity(emitter, hit)
            ds = mi.DirectionSample3f(scene, si=si, ref=prev_it)
            # at depth 1 a textured area light still needs its position density (light tracing's
            # emission density of x_0, the competitor of a direct hit; ``table.emission``)
            pdf_nee = nee_density(scene, prev_it, ds, infinite, hit & ((depth > 1) | ~infinite))
            cos_light = dr.select(infinite, 1.0, dr.abs(dr.dot(si.n, ray.d)))
            pdf_pos, pdf_dir, _ = table.emission(emitter, cos_light, pdf_nee, hit, si.p, -ray.d)
            # (light tracing never splats an emitter at infinity: no competitor for x_0 there)
            w_hit = w.hit(mis, pdf_nee, pdf_pos * pdf_dir, dr.select(infinite, 0.0, pdf_pos))
            L += beta * float_or_zero(w_hit) * emitter.eval(si, hit)
        active &= si.is_valid()

        bsdf = si.bsdf(ray)
        smooth = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)

        # ---------------- s = 1: next-event estimation (+ the BSDF sample, one call) ----------------
        active_next = active & (depth < max_depth)
        nee_on = smooth & active_next & strategy_mask(cp.only, 1, depth + 1) & (Technique.NEE in w.techniques)
        ds, em_weight = spawn.sample_visible_emitter(scene, si, sampler.next_2d(), floor, nee_on)
        tally(cp.counters, "shadow", nee_on)
        nee_on &= ds.pdf > 0
        wo = si.to_local(ds.d)
        f, pdf_fwd, bs, bsdf_weight = bsdf.eval_pdf_sample(ctx, si, wo, sampler.next_1d(), sampler.next_2d(),
                                                           active_next)
        pdf_rev = reverse_pdf(bsdf, ctx_imp, si, wo, nee_on)
        infinite = table.at_infinity(ds.emitter, nee_on)
        dist2 = dr.select(infinite, 1.0, dr.square(ds.dist))
        cos_light = dr.select(ds.delta | infinite, 1.0, dr.abs(dr.dot(ds.n, ds.d)))
        pdf_nee = dr.select(ds.delta, ds.pdf, ds.pdf * cos_light / dist2)   # area (at infinity: solid angle)
        pdf_pos, pdf_dir, delta = table.emission(ds.emitter, cos_light, pdf_nee, nee_on, ds.p, -ds.d)
        w_nee = w.nee(mis, pdf_nee, pdf_pos * pdf_dir, cos_light, dr.abs(dr.dot(si.n, ds.d)), dist2,
                      pdf_fwd, pdf_rev, delta, depth)
        L += dr.select(nee_on, spectrum_or_zero(beta * f * em_weight * float_or_zero(w_nee)), 0.0)

        # ---------------- s >= 2: connections to the light subpath ----------------
        if dr.hint(Technique.CONNECT in w.techniques, mode="scalar"):
            u_connect = sampler.next_1d() if cp.connect_share > 0 else None
            if dr.hint(cp.connect_one, mode="scalar"):
                L += connect_to_one_light_vertex(scene, cp, si, bsdf, beta, mis, depth, head,
                                                 smooth & (depth + 2 <= max_depth), L, u_connect,
                                                 sampler.next_1d())
            else:
                L += connect_to_light_subpath(scene, cp, si, bsdf, beta, mis, depth, head,
                                              smooth & (depth + 2 <= max_depth), L, u_connect)

        # ---------------- merging with the light vertices around (lab_vcm) ----------------
        if dr.hint(merging, mode="scalar"):
            u_merge = sampler.next_1d() if w.merge_bounded else None     # (merging's roulette)
            L += cp.grid.merge(cp, si, bsdf, beta, mis, depth, iteration,
                               smooth & (depth < max_depth) & w.merges_at(depth), u_merge)

        # ---------------- BSDF sampling (sampled above) ----------------
        wo_world = si.to_world(bs.wo)
        pdf_rev = reverse_pdf(bsdf, ctx_imp, si, bs.wo, active_next)
        mis = w.scatter_camera(mis, bs.pdf, pdf_rev, dr.abs(dr.dot(si.n, wo_world)),
                               mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta), depth)
        dvcm, dvc, first = float_or_zero(mis.dvcm), float_or_zero(mis.dvc), mi.Float(mis.first)
        dvm = carried(merging, mis.dvm, dvm)
        if dr.hint(w.caustic, mode="scalar"):
            pending = float_or_zero(mis.pending)
        valid_ray |= active & ~mi.has_flag(bs.sampled_type, mi.BSDFFlags.Null)
        prev_it = dr.zeros(mi.Interaction3f)
        prev_it.p, prev_it.n, prev_it.t, prev_it.time = si.p, si.n, si.t, si.time
        prev_it.wavelengths = si.wavelengths
        prev_p = mi.Point3f(si.p)
        ray = spawn.spawn_ray(si, wo_world, floor)
        beta *= bsdf_weight
        eta *= bs.eta

        beta_max = dr.max(mi.unpolarized_spectrum(beta))
        active_next &= (beta_max != 0) & dr.isfinite(beta_max)
        beta, survives = russian_roulette(beta, sampler.next_1d(), depth >= rr_depth, eta=eta)
        active_next &= survives
        if dr.hint(merging and cp.grid.first_only, mode="scalar"):
            # lab_vcm's ppm: the merge took the smooth lobes' light; only a delta lobe goes on
            active_next &= ~smooth | mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        if dr.hint(cp.camera_depth is not None, mode="scalar"):
            active_next &= depth < cp.camera_depth
        pi = scene.ray_intersect_preliminary(ray, coherent=False, active=active_next)
        tally(cp.counters, "extension", active_next)
        active = active_next
    return L, valid_ray
