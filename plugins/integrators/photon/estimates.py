"""lab_photon's density estimates: the photons within the radius of a camera vertex, summed
with the Epanechnikov kernel, on surfaces (the disc) and in media (the ball); ``gather`` and
``media_camera`` call them."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common.grid import NEIGHBOURS, cell_of, hash_cell, neighbour_cell
from mitsuba_lab.plugins.integrators.common.kernels import NORMAL_COS, kernel

from .grid import PhotonGrid

#: BSDFContext type mask of the delta lobes alone (null pass-through, delta reflection and
#: transmission, with every side and property flag).
DELTA_MASK = int(mi.BSDFFlags.All) & ~int(mi.BSDFFlags.Smooth)


@dr.syntax
def kernel_sum(grid: PhotonGrid, x, evaluate, max_photon_depth, active, dimension: int = 2):
    """sum_p evaluate(p) K(|x - x_p| / r) over the photons p of ``grid`` within its radius r of
    ``x`` whose depth is at most ``max_photon_depth`` (per lane); ``evaluate(j, ok)`` gives (the
    photon's term, whether it counts) for the photon record at index ``j``; K the Epanechnikov
    kernel over the disc (``dimension`` 2) or the ball (3), not yet divided by r^dimension."""
    rec = grid.records
    radius2 = grid.radius2
    inv_r2 = dr.rcp(radius2)
    inv_cell = grid.inv_cell_size
    home = cell_of(x, inv_cell)
    result = mi.Spectrum(0)
    k = mi.UInt32(0)
    active = mi.Bool(active)
    while dr.hint(active & (k < NEIGHBOURS), label="lab_photon gather cells"):
        cell = neighbour_cell(home, k)
        bucket = hash_cell(cell, grid.mask)
        j = dr.gather(mi.UInt32, grid.start, bucket, active)
        end = j + dr.gather(mi.UInt32, grid.count, bucket, active)
        while dr.hint(j < end, label="lab_photon gather photons"):
            p = dr.gather(mi.Point3f, rec.p, j)
            dist2 = dr.squared_norm(p - x)
            ok = dist2 < radius2
            ok &= dr.gather(mi.UInt32, rec.depth, j, ok) <= max_photon_depth
            ok &= dr.all(cell_of(p, inv_cell) == cell)
            value, ok = evaluate(j, ok)
            weight = kernel("epanechnikov", dist2 * inv_r2, dimension)
            result += dr.select(ok, value * weight, 0.0)
            j += 1
        k += 1
    return result


def density_estimate(grid: PhotonGrid, si: mi.SurfaceInteraction3f, bsdf: mi.BSDF, max_photon_depth,
                     active):
    """sum_p f Phi_p K / r^2 for each lane's interaction ``si``; ``max_photon_depth`` per lane."""
    ctx = mi.BSDFContext()
    rec = grid.records

    def surface_photon(j, ok):
        n_p = dr.gather(mi.Normal3f, rec.n, j, ok)
        ok &= dr.dot(n_p, si.n) > NORMAL_COS
        wi_world = dr.gather(mi.Vector3f, rec.wi, j, ok)
        f_cos = bsdf.eval(ctx, si, si.to_local(wi_world), ok)       # f |wi . n_s|
        cos_g = dr.abs(dr.dot(wi_world, n_p))                      # the flux's |wi . n_g|
        power = dr.gather(mi.Spectrum, rec.power, j, ok)
        return f_cos * power / dr.maximum(cos_g, 1e-30), ok & (cos_g > 0)

    return kernel_sum(grid, si.p, surface_photon, max_photon_depth, active) * dr.rcp(grid.radius2)


def volume_estimate(grid: PhotonGrid, mei: mi.MediumInteraction3f, phase: mi.PhaseFunction, max_photon_depth,
                    active):
    """The in-scattered radiance at the camera's medium vertex ``mei`` over its sigma_s, from the
    volumetric photons of ``grid`` (its radius r_v): sum_p p(wo, wi_p) Phi_p K3 / (sigma_s(x) r_v^3)
    (``vcm.volume_merging``'s estimate: a photon's power holds sigma_s at its own collision, the
    camera's throughput at ``mei`` holds sigma_s(x), so one is divided out; K3 the Epanechnikov
    kernel over the unit ball)."""
    ctx = mi.PhaseFunctionContext(None, mi.TransportMode.Radiance)
    rec = grid.records

    def medium_photon(j, ok):
        wi_world = dr.gather(mi.Vector3f, rec.wi, j, ok)
        f, _ = phase.eval_pdf(ctx, mei, wi_world, ok)
        return mi.Spectrum(f) * dr.gather(mi.Spectrum, rec.power, j, ok), ok

    total = kernel_sum(grid, mei.p, medium_photon, max_photon_depth, active, dimension=3)
    sigma_s = mi.Spectrum(mei.sigma_s)
    # (a Spectrum again: in spectral variants the comparison's select gives a plain 4-vector)
    return mi.Spectrum(dr.select(sigma_s > 0, total * grid.inv_volume / dr.maximum(sigma_s, 1e-30), 0.0))
