"""Vertex merging: the light vertices near a camera vertex, found through a hashed grid.

Merging a camera vertex x (smooth BSDF, camera throughput beta) with the light vertices y
within radius r of it, out of the N light subpaths of its iteration, estimates the light x
reflects towards the camera as a density estimate with the constant kernel 1 / (pi r^2)
(Georgiev et al. 2012; SmallVCM's normalisation):

    L += beta / (pi r^2 N) * sum_y w_merge f(x, wo, wi_y) (|wi_y . n_s| / |wi_y . n_y|) beta_y

beta_y is the light subpath's throughput on arrival at y (its flux over the subpath's density:
a photon's power times N); f |wi_y . n_s| is Mitsuba's ``BSDF.eval`` at x with the light
vertex's incoming direction, divided by y's geometric cosine as ``lab_photon`` does (the flux
is per unit of geometric area). The kernel is constant so that its density is the pi r^2 of
the MIS weights (``weights.BdptWeights.merge``, merge_area = pi r^2 N). A light vertex counts
only when its normal is within ``NORMAL_COS`` of x's (not the far side of a thin wall) and the
merged path, light depth + camera depth segments, is no longer than ``max_depth``.

A pass holds K iterations (camera lane i and light subpath i belong to iteration
``BdptWeights.lane_iteration(i)``: blocks of 64 lanes in turn), each with its own radius: a vertex is bucketed by its cell at its
iteration's radius with the iteration mixed into the hash (``photon.grid``'s counting sort),
and a camera vertex looks only in its own iteration's cells. The grid holds each bucket's range
of an index array (``order``) into the vertex buffer, which keeps its own order, so connections
still walk each lane's list.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.bdpt.light_subpath import finite_or_zero, reverse_pdf
from mitsuba_lab.plugins.integrators.bdpt.weights import SubpathMis
from mitsuba_lab.plugins.integrators.photon.gather import NORMAL_COS
from mitsuba_lab.plugins.integrators.photon.grid import cell_of, counting_sort, hash_cell, table_size_for


def table(values) -> mi.Float:
    """One value per iteration, in memory (a kernel reads it, whatever the values)."""
    out = mi.Float(values)
    dr.make_opaque(out)
    return out


#: The light-vertex fields a merge reads (``vertices.LightVertices``).
MERGE_FIELDS = (("p", "Point3f"), ("n", "Normal3f"), ("wi", "Vector3f"), ("beta", "Spectrum"), ("dvcm", "Float"),
                ("dvc", "Float"), ("dvm", "Float"), ("depth", "UInt32"), ("iteration", "UInt32"))


class VertexGrid:
    """The first ``count`` vertices of a ``LightVertices`` buffer, bucketed per iteration.

    ``radii``: each iteration's merging radius; ``light_subpaths``: N_k, each iteration's light
    subpaths (the estimate's normalisation). Per-iteration values are opaque arrays, so another
    radius or pass size reuses the compiled camera kernel."""

    #: Merge at the first camera vertex with a smooth lobe only, then follow delta lobes alone
    #: (lab_vcm's ppm mode; set by the integrator).
    first_only = False

    def __init__(self, vertices, count: int, radii, light_subpaths: int):
        if not all(r > 0 for r in radii):
            raise ValueError(f"lab_vcm: merging radii must be > 0, got {list(radii)}")
        self.vertices = vertices
        self.count = count
        self.radii = [float(r) for r in radii]
        size = table_size_for(count)
        self.inv_cell_size = table([1.0 / (2.0 * r) for r in self.radii])     # cells of 2r: 8 per query
        self.radius2 = table([r * r for r in self.radii])
        self.normalisation = table([1.0 / (math.pi * r * r * n) for r, n in zip(self.radii, light_subpaths)])
        self.mask = dr.opaque(mi.UInt32, size - 1)
        if count == 0:                 # (every bucket empty: no merge reads a vertex)
            self.start, self.size, self.order = dr.zeros(mi.UInt32, size), dr.zeros(mi.UInt32, size), mi.UInt32(0)
            self.sorted = {name: dr.zeros(getattr(mi, kind), 1) for name, kind in MERGE_FIELDS}
            return
        index = dr.arange(mi.UInt32, count)
        iteration = dr.gather(mi.UInt32, vertices.iteration, index)
        points = dr.gather(mi.Point3f, vertices.p, index)
        inv_cell = dr.gather(mi.Float, self.inv_cell_size, iteration)
        slot, self.start, self.size = counting_sort(hash_cell(cell_of(points, inv_cell), self.mask, iteration), size)
        self.order = dr.zeros(mi.UInt32, count)
        dr.scatter(self.order, index, slot)
        # what a merge reads, in bucket order: a bucket's vertices lie together in memory
        self.sorted = {}
        for name, kind in MERGE_FIELDS:
            self.sorted[name] = dr.gather(getattr(mi, kind), getattr(vertices, name), self.order)
        dr.eval(self.order, *self.sorted.values())

    @dr.syntax
    def merge(self, cp, si, bsdf, beta, mis: SubpathMis, depth, iteration, active):
        """The weighted merging estimate at camera vertex ``si`` (``depth`` segments from the
        sensor, MIS state ``mis`` after ``after_hit``, in ``iteration`` of the pass), per lane."""
        w, vertices = cp.weights, self.sorted
        ctx_imp = mi.BSDFContext(mi.TransportMode.Importance)
        ctx = mi.BSDFContext(mi.TransportMode.Radiance)
        max_depth = dr.opaque(mi.UInt32, cp.max_depth)
        inv_cell = dr.gather(mi.Float, self.inv_cell_size, iteration)
        radius2 = dr.gather(mi.Float, self.radius2, iteration)
        # the disc of radius r around x lies in the 2 x 2 x 2 cells of size 2r on x's side of
        # its cell's middle, on each axis
        scaled = si.p * inv_cell
        corner = mi.Vector3i(dr.floor(scaled) + dr.select(scaled - dr.floor(scaled) >= 0.5, 0.0, -1.0))
        result = mi.Spectrum(0)
        k = mi.UInt32(0)
        active = mi.Bool(active)
        while dr.hint(active & (k < 8), label="lab_vcm merge cells"):
            cell = corner + mi.Vector3i(mi.Int32(k & 1), mi.Int32((k >> 1) & 1), mi.Int32(k >> 2))
            bucket = hash_cell(cell, self.mask, iteration)
            j = dr.gather(mi.UInt32, self.start, bucket, active)
            end = j + dr.gather(mi.UInt32, self.size, bucket, active)
            while dr.hint(j < end, label="lab_vcm merge vertices"):
                slot = mi.UInt32(j)
                p = dr.gather(mi.Point3f, vertices["p"], slot)
                n_y = dr.gather(mi.Normal3f, vertices["n"], slot)
                ok = (dr.squared_norm(p - si.p) < radius2) & (dr.dot(n_y, si.n) > NORMAL_COS)
                ok &= dr.all(cell_of(p, inv_cell) == cell) & (dr.gather(mi.UInt32, vertices["iteration"], slot) == iteration)
                depth_y = dr.gather(mi.UInt32, vertices["depth"], slot, ok)
                ok &= depth_y + depth <= max_depth
                wi_world = dr.gather(mi.Vector3f, vertices["wi"], slot, ok)
                wi = si.to_local(wi_world)
                f_cos, pdf_fwd = bsdf.eval_pdf(ctx, si, wi, ok)             # f |wi . n_s|
                pdf_rev = reverse_pdf(bsdf, ctx_imp, si, wi, ok)
                light = SubpathMis(dr.gather(mi.Float, vertices["dvcm"], slot, ok),
                                   dr.gather(mi.Float, vertices["dvc"], slot, ok),
                                   dr.select(depth_y == 1, 1.0, 0.0),
                                   dr.gather(mi.Float, vertices["dvm"], slot, ok))
                weight = finite_or_zero(w.merge(light, mis, pdf_fwd, pdf_rev))
                cos_g = dr.abs(dr.dot(wi_world, n_y))
                beta_y = dr.gather(mi.Spectrum, vertices["beta"], slot, ok)
                ok &= cos_g > 0
                result += dr.select(ok, f_cos * beta_y * (weight / dr.maximum(cos_g, 1e-30)), 0.0)
                j += 1
            k += 1
        return beta * result * dr.gather(mi.Float, self.normalisation, iteration)
