"""Light carried the adjoint way: from emitters towards the camera, with shading normals.

Mitsuba's BSDFs in ``TransportMode.Importance`` only drop the 1/eta^2 radiance scaling at
refractions; the asymmetry that shading normals add to adjoint transport is left to the
integrator (Mitsuba's ``ptracer`` applies it itself). A light path scattered from direction wi
(towards where it came from) into wo is weighted by Veach's correction (Veach 1997, sec. 5.3,
eq. 5.19)

    |wi . n_s| |wo . n_g| / (|wi . n_g| |wo . n_s|)

with n_s the shading normal and n_g the geometric one. ``adjoint_correction`` builds it from
``si.sh_frame`` after an importance-mode BSDF sample (lab_photon's photons); ``transported``
evaluates the whole adjoint factor through a radiance-mode BSDF evaluation with the directions
swapped, so that n_s is the BSDF's own, a normal or bump map's perturbed one included
(lab_bdpt's and lab_vcm's light subpaths, which also need the reverse density it returns).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi


def adjoint_correction(si: mi.SurfaceInteraction3f, wi_world, wo_local):
    """|wi.n_s| |wo.n_g| / (|wi.n_g| |wo.n_s|) for a photon arriving from ``wi_world`` (towards
    its origin) and leaving along ``wo_local`` (shading frame); 0 where a cosine is 0."""
    wo_world = si.to_world(wo_local)
    num = dr.abs(mi.Frame3f.cos_theta(si.wi) * dr.dot(si.n, wo_world))
    den = dr.abs(mi.Frame3f.cos_theta(wo_local) * dr.dot(si.n, wi_world))
    return dr.select(den > 0, num / dr.maximum(den, 1e-30), 0.0)


def transported(bsdf, si: mi.SurfaceInteraction3f, wo, active):
    """(value, reverse density) of a light-subpath vertex sending flux along ``wo`` (local).

    value: what goes out along ``wo`` per unit of the flux that reached the vertex from
    ``si.wi``, the shading-normal correction included (Veach 1997, sec. 5.3):

        f(wi -> wo) |wi . n_s| |wo . n_g| / |wi . n_g|

    The first two factors are the radiance-mode BSDF evaluated with the directions swapped
    (``si.wi`` = wo), so n_s is whatever normal the BSDF itself uses, a normal or bump map's
    perturbed one included; an importance-mode evaluation times a correction built from
    ``si.sh_frame`` would use the unperturbed normal there (2% too dark a floor under a bump
    map, as Mitsuba's ptracer renders it). The same call gives the reverse density: that of
    sampling ``si.wi`` from ``wo`` (what ``reverse_pdf`` would return in radiance mode)."""
    swapped = mi.SurfaceInteraction3f(si)
    swapped.wi = wo
    value, pdf_rev = bsdf.eval_pdf(mi.BSDFContext(mi.TransportMode.Radiance), swapped, si.wi, active)
    cos_in = dr.abs(dr.dot(si.n, si.to_world(si.wi)))
    ratio = dr.abs(dr.dot(si.n, si.to_world(wo))) / cos_in
    return dr.select(cos_in > 0, value * ratio, 0.0), pdf_rev
