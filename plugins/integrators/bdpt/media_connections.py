"""lab_bdpt's connections in participating media (s >= 2, t >= 2): a camera vertex, on a surface or
in a medium, joined to each stored vertex of its light subpath through the media between them,
with the segment's transmittance in the contribution and, in the weights, its T_c and (where the
camera subpaths mix in equi-angular flights) the camera's density ratio of the segment
(``camera_flight``). ``media_paths`` explains the densities."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import media
from mitsuba_lab.plugins.integrators.common.adjoint import transported
from mitsuba_lab.plugins.integrators.common.counters import tally
from mitsuba_lab.plugins.integrators.common.direct import spectrum_or_zero
from mitsuba_lab.plugins.integrators.common.subpath_media import phase_reverse_pdf, sigma_t_channel, vertex_eval
from mitsuba_lab.plugins.integrators.common.subpath_media import transmittance as through

from . import camera_flight
from .vertices import NONE
from .weights import SubpathMis


def connection(scene, cp, x, si, bsdf, mei, phase, scattered, sides, beta, mis: SubpathMis, depth, slot, on,
               sampler, channel, phase_ctx):
    """(weighted contribution, previous slot) of the connection from camera vertex ``x`` (``si``
    at a surface, ``mei`` where ``scattered``; ``depth`` segments from the sensor) to the light
    vertex at ``slot``, through the media between them."""
    from .light_subpath import float_or_zero, strategy_mask

    w, floor = cp.weights, cp.offset_floor
    ctx = mi.BSDFContext(mi.TransportMode.Radiance)
    ctx_imp = mi.BSDFContext(mi.TransportMode.Importance)
    max_depth = dr.opaque(mi.UInt32, cp.max_depth)
    y, bsdf_y, beta_y, mis_y, depth_y, prev = cp.vertices.load(slot, si.wavelengths, on)
    medium_y, _, wi_y = cp.vertices.load_media(slot, on)
    y_in_medium = on & (y.n.x == 0) & (y.n.y == 0) & (y.n.z == 0)
    use = on & (depth_y + 1 + depth <= max_depth) & strategy_mask(cp.only, depth_y + 1, depth + 1)
    d = y.p - x.p
    dist2 = dr.squared_norm(d)
    d = d * dr.rsqrt(dist2)
    # the camera vertex
    f_x, pdf_x_fwd, pdf_x_rev = vertex_eval(ctx, ctx_imp, phase_ctx, si, bsdf, mei, phase, scattered, d, use)
    g_x = dr.select(scattered, media.channel_value(mei.sigma_t, channel), dr.abs(dr.dot(si.n, d)))
    # the light vertex: its adjoint BSDF, or its medium's phase function
    wo_y = y.to_local(-d)
    f_ys, pdf_y_rev_s = transported(bsdf_y, y, wo_y, use & ~y_in_medium)
    pdf_y_fwd_s = bsdf_y.pdf(ctx_imp, y, wo_y, use & ~y_in_medium)
    mei_y = dr.zeros(mi.MediumInteraction3f)
    mei_y.p, mei_y.wi, mei_y.sh_frame, mei_y.wavelengths = y.p, wi_y, mi.Frame3f(wi_y), si.wavelengths
    mei_y.medium, mei_y.t = medium_y, mi.Float(1.0)
    phase_y = medium_y.phase_function()
    at_y = use & y_in_medium
    f_yp, pdf_y_fwd_p = phase_y.eval_pdf(phase_ctx, mei_y, -d, at_y)
    pdf_y_rev_p = phase_reverse_pdf(phase_y, phase_ctx, mei_y, -d, at_y)
    f_y = dr.select(y_in_medium, mi.Spectrum(f_yp), f_ys)
    g_y = dr.select(y_in_medium, sigma_t_channel(medium_y, mei_y, channel, at_y), dr.abs(dr.dot(y.n, d)))
    value = spectrum_or_zero(beta * f_x * f_y * beta_y / dist2)
    use &= dr.max(mi.unpolarized_spectrum(value)) > 0
    tally(cp.counters, "connection", use)
    T, T_c = through(scene, sides.toward(d), x, y.p, sampler, channel, floor, use, cp.tracking)
    mix = cp.equiangular
    r = camera_flight.segment_ratio(scene, mix, sides.toward(d), x, y.p, y_in_medium, floor, channel, use)
    rho = None
    if mix is not None and mix.nee_all and cp.grid is None:   # (equi-angular NEE's, at a light subpath's first vertex)
        rho = camera_flight.rho_towards(scene, mix, sides.toward(d), x, y.p, r, floor, x.wavelengths, channel,
                                        use & y_in_medium & (depth_y == 1))
    weight = w.connect(mis_y, mis, dr.select(y_in_medium, pdf_y_fwd_p, pdf_y_fwd_s),
                       dr.select(y_in_medium, pdf_y_rev_p, pdf_y_rev_s), pdf_x_fwd, pdf_x_rev,
                       g_y * T_c * r, g_x * T_c, dist2, depth, y_in_medium, scattered, rho=rho)
    value = spectrum_or_zero(value * mi.Spectrum(T) * float_or_zero(weight))
    return dr.select(use, value, 0.0), prev


@dr.syntax
def connect_to_light_subpath(scene, cp, x, si, bsdf, mei, phase, scattered, sides, beta, mis, depth, head,
                             active, sampler, channel, phase_ctx):
    """The s >= 2 strategies at camera vertex ``x``: its connections to every stored vertex of
    its light subpath (the list ending at ``head``)."""
    L = dr.zeros(mi.Spectrum, dr.width(head))
    slot = dr.select(active, head, NONE)
    while dr.hint(slot != NONE, max_iterations=-1, label="lab_bdpt connections in media"):
        on = slot != NONE
        value, prev = connection(scene, cp, x, si, bsdf, mei, phase, scattered, sides, beta, mis, depth,
                                 slot, on, sampler, channel, phase_ctx)
        L += value
        slot = dr.select(on, prev, NONE)
    return L




# ------------------------------------------------------------------------------------------
# Light tracing's joins to the sensor (``media_paths.trace_light``)
# ------------------------------------------------------------------------------------------
def splat_emitter(tracer, st, block, ps, medium, u0, aux, channel, mix, scale):
    """s = 1, t = 1: the emitted point ``ps`` (in ``medium``) seen directly by the sensor through
    the media, splatted with its weight."""
    from . import splats
    from .light_subpath import float_or_zero, sensor_pdf, strategy_mask

    scene, sensor, w, floor = tracer.scene, tracer.sensor, st.w, tracer.floor
    si0 = mi.SurfaceInteraction3f(ps, st.ray.wavelengths)
    active0 = st.on_surface & (st.pmf > 0) & strategy_mask(tracer.only, 1, 1)
    ds0, we0 = sensor.sample_direction(si0, u0, active0)
    active0 &= ds0.pdf > 0
    tally(tracer.counters, "sensor", active0)
    si0.wi = si0.to_local(ds0.d)
    cos0 = mi.Frame3f.cos_theta(si0.wi)
    active0 &= cos0 > 0
    T0, T0_c = through(scene, medium, si0, ds0.p, aux, channel, floor, active0, tracer.tracking)
    active0 &= dr.max(T0) > 0
    le0 = st.emitter.eval(si0, active0)
    T0_c *= camera_flight.from_sensor(scene, mix, tracer, ds0.p, si0.p, False, si0.wavelengths, channel, active0)
    w0 = w.emitter_to_camera(sensor_pdf(ds0, we0), cos0 * T0_c, dr.square(ds0.dist), st.pdf_pos, st.delta_pos)
    value0 = le0 * cos0 * st.pos_weight * st.sel_weight * we0 * mi.Spectrum(T0) * float_or_zero(w0) * scale
    splats.splat(block, ds0.uv, si0.wavelengths, value0, active0)


def splat_vertex(tracer, w, block, v, si, bsdf, mei, phase, scattered, sides, beta, mis, sigma_c, u_sensor, splat_on,
                 aux, channel, mix, scale, at):
    """t = 1: the light vertex ``v`` (``si`` at a surface, ``mei`` where ``scattered``; ``at``
    segments from the emitter) joined to the sensor through the media, splatted with its weight
    (with equi-angular NEE's rho at a first vertex in a medium, ``camera_flight``)."""
    from . import splats
    from .light_subpath import float_or_zero, sensor_pdf

    scene, sensor, floor = tracer.scene, tracer.sensor, tracer.floor
    phase_ctx = mi.PhaseFunctionContext(None, mi.TransportMode.Importance)
    ds, we = sensor.sample_direction(v, u_sensor, splat_on)
    connect = splat_on & (ds.pdf > 0)
    tally(tracer.counters, "sensor", connect)
    T, T_c = through(scene, sides.toward(ds.d), v, ds.p, aux, channel, floor, connect, tracer.tracking)
    connect &= dr.max(T) > 0
    r = camera_flight.from_sensor(scene, mix, tracer, ds.p, v.p, scattered, v.wavelengths, channel, connect)
    rho = None
    if mix is not None and mix.nee and not w.merging:
        at_first = connect & scattered & (at == 1)
        eye = dr.zeros(mi.Interaction3f)
        eye.p, eye.wavelengths = ds.p, v.wavelengths
        rho = camera_flight.rho_towards(scene, mix, tracer.sensor_medium, eye, v.p, r, floor, v.wavelengths,
                                        channel, at_first)
    f_surface, rev_surface = transported(bsdf, si, si.to_local(ds.d), connect & ~scattered)
    f_phase, _ = phase.eval_pdf(phase_ctx, mei, ds.d, connect & scattered)
    rev_phase = phase_reverse_pdf(phase, phase_ctx, mei, ds.d, connect & scattered)
    f_cam = dr.select(scattered, mi.Spectrum(f_phase), f_surface)
    g_cam = dr.select(scattered, sigma_c, dr.abs(dr.dot(si.n, ds.d)))
    w_cam = w.light_to_camera(mis, sensor_pdf(ds, we), g_cam * T_c * r, dr.square(ds.dist),
                              dr.select(scattered, rev_phase, rev_surface), scattered, rho=rho)
    value = beta * f_cam * we * mi.Spectrum(T) * float_or_zero(w_cam) * scale
    splats.splat(block, ds.uv, v.wavelengths, value, connect)
