"""Vertex merging: the light vertices near a camera vertex, found through a hashed grid.

Merging a camera vertex x (smooth BSDF, camera throughput beta) with the light vertices y
within radius r of it, out of the N light subpaths of its iteration, estimates the light x
reflects towards the camera as a kernel density estimate (Georgiev et al. 2012; SmallVCM's
normalisation, with a kernel K of ``kernels``):

    L += beta / (r^2 N) * sum_y w_merge K(|x - y| / r) f(x, wo, wi_y) (|wi_y . n_s| / |wi_y . n_y|) beta_y

beta_y is the light subpath's throughput on arrival at y (its flux over the subpath's density:
a photon's power times N); f |wi_y . n_s| is Mitsuba's ``BSDF.eval`` at x with the light
vertex's incoming direction, divided by y's geometric cosine as ``lab_photon`` does (the flux
is per unit of geometric area). The MIS weights count merging with the disc's area, density
pi r^2 N (``weights.BdptWeights.merge``), whatever the kernel: the constant kernel 1 / pi is
that density exactly (SmallVCM); any kernel that integrates to 1 gives the same expected
estimate as r shrinks, so the weights of every technique of a path still sum to 1 in the
limit, which is all consistency asks, and the Epanechnikov kernel (lab_vcm's default) blurs
less for finite r (``kernels``). A light vertex counts only when its normal is within
``NORMAL_COS`` of x's (not the far side of a thin wall) and the merged path, light depth +
camera depth segments, is no longer than ``max_depth``.

A pass holds K iterations (camera lane i and light subpath i belong to iteration
``BdptWeights.lane_iteration(i)``, i mod K: a pixel's K samples in a pass use K iterations),
each with its own radius: a vertex is bucketed by its cell at its iteration's radius with the
iteration mixed into the hash (``photon.grid``'s counting sort), and a camera vertex looks
only in its own iteration's cells. The grid holds each bucket's range of an index array
(``order``) into the vertex buffer, which keeps its own order, so connections still walk each
lane's list.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.bdpt.light_subpath import float_or_zero, reverse_pdf
from mitsuba_lab.plugins.integrators.bdpt.vertices import (NO_MERGE, POINT, POINT_WIDTH, RECORD, RECORD_WIDTH,
                                                           read, spectrum_at, unbits, vector)
from mitsuba_lab.plugins.integrators.bdpt.weights import SubpathMis
from mitsuba_lab.plugins.integrators.common.counters import tally
from mitsuba_lab.plugins.integrators.common.grid import cell_of, counting_sort, hash_cell, table_size_for
from mitsuba_lab.plugins.integrators.common.kernels import NORMAL_COS, kernel
from mitsuba_lab.plugins.integrators.common.roulette import kept


#: Merging's Russian roulette: at a camera vertex whose merge weight cannot exceed a bound b
#: (``BdptWeights.merge_bound``), the merge runs with probability min(1, b / MERGE_ROULETTE) and
#: counts 1 / that probability, so no merge that runs carries more than MERGE_ROULETTE's share
#: of its estimate. Unbiased; it skips the lookups of merges that MIS would mostly discard (with
#: few light vertices per camera subpath, in diffuse scenes).
MERGE_ROULETTE = 0.5


def merge_roulette(weights, camera: SubpathMis, u, medium=None):
    """(whether the merge at a camera vertex with MIS state ``camera`` runs, for the uniform
    ``u``; the factor it then counts, 1 / its probability). ``u`` None: every merge runs (no
    technique with fewer camera vertices competes, so every bound is 1). ``medium``: at medium
    vertices."""
    if u is None:
        return True, 1.0
    return kept(dr.minimum(1.0, float_or_zero(weights.merge_bound(camera, medium)) * (1.0 / MERGE_ROULETTE)), u)


def table(values) -> mi.Float:
    """One value per iteration, in memory (a kernel reads it, whatever the values)."""
    out = mi.Float(values)
    dr.make_opaque(out)
    return out


class VertexGrid:
    """The first ``count`` vertices of a ``LightVertices`` buffer, bucketed per iteration.

    ``radii``: each iteration's merging radius; ``light_subpaths``: N_k, each iteration's light
    subpaths (the estimate's normalisation); ``kernel``: the density kernel's name
    (``kernels``). Per-iteration values are opaque arrays, so another radius or pass size
    reuses the compiled camera kernel. In a scene with media (``vertices.media``) it holds the
    surface vertices only (a medium vertex has normal 0): ``volume_merging.MediumGrid`` holds
    the others, and ``volume`` is that grid (None without media)."""

    #: Merge at the first camera vertex with a smooth lobe only, then follow delta lobes alone
    #: (lab_vcm's ppm mode; set by the integrator).
    first_only = False
    #: The dimension merging blurs over: discs on surfaces (``MediumGrid``: balls in media).
    DIMENSION = 2
    #: Whether the camera vertices it merges with are medium vertices (``BdptWeights.merge``).
    IN_MEDIUM = None
    #: The grid of medium vertices (``volume_merging.MediumGrid``), in scenes with media.
    volume = None

    def __init__(self, vertices, count: int, radii, light_subpaths: int, kernel: str = "epanechnikov"):
        if not all(r > 0 for r in radii):
            raise ValueError(f"lab_vcm: merging radii must be > 0, got {list(radii)}")
        self.vertices = vertices
        index = dr.arange(mi.UInt32, count)       # (the stored slots that merge)
        if vertices.caustic and count > 0:
            # (caustic_merges: only the vertices reached through a delta lobe merge)
            dvm = dr.gather(mi.Float, vertices.records, index * RECORD_WIDTH + RECORD["dvm"])
            index = dr.compress(dvm != NO_MERGE)
            count = dr.width(index)
        if vertices.media and count > 0:
            # (surfaces and media have a grid each: a vertex is kept by the one of its kind)
            n = vector(read(vertices.points, POINT_WIDTH, index), POINT["n"])
            in_medium = dr.squared_norm(n) == 0
            index = dr.gather(mi.UInt32, index, dr.compress(in_medium if self.IN_MEDIUM else ~in_medium))
            count = dr.width(index)
        self.count = count
        self.radii = [float(r) for r in radii]
        self.kernel = kernel
        size = table_size_for(2 * count)       # (>= 4 buckets per vertex: fewer foreign ones per query)
        self.inv_cell_size = table([1.0 / (2.0 * r) for r in self.radii])     # cells of 2r: 8 per query
        self.radius2 = table([r * r for r in self.radii])
        self.normalisation = table([1.0 / (r ** self.DIMENSION * n) for r, n in zip(self.radii, light_subpaths)])
        self.mask = dr.opaque(mi.UInt32, size - 1)
        if count == 0:                 # (every bucket empty: no merge reads a vertex)
            self.buckets, self.order = dr.zeros(mi.UInt32, 2 * size), mi.UInt32(0)
            self.points, self.records = dr.zeros(mi.Float, POINT_WIDTH), dr.zeros(mi.Float, RECORD_WIDTH)
            return
        point = read(vertices.points, POINT_WIDTH, index)
        iteration = unbits(point[POINT["iteration"]])
        points = vector(point, POINT["p"], mi.Point3f)
        inv_cell = dr.gather(mi.Float, self.inv_cell_size, iteration)
        slot, start, length = counting_sort(hash_cell(cell_of(points, inv_cell), self.mask, iteration), size)
        # each bucket's [start, end) side by side: a query reads both in one packet load
        self.buckets = dr.zeros(mi.UInt32, 2 * size)
        dr.scatter(self.buckets, mi.ArrayXu([start, start + length]), dr.arange(mi.UInt32, size))
        self.order = dr.zeros(mi.UInt32, count)
        dr.scatter(self.order, index, slot)
        # what a merge reads, in bucket order: a bucket's vertices lie together in memory
        self.points = dr.zeros(mi.Float, POINT_WIDTH * count)
        self.records = dr.zeros(mi.Float, RECORD_WIDTH * count)
        position = dr.arange(mi.UInt32, count)
        dr.scatter(self.points, read(vertices.points, POINT_WIDTH, self.order), position)
        dr.scatter(self.records, read(vertices.records, RECORD_WIDTH, self.order), position)
        dr.eval(self.order, self.buckets, self.points, self.records)

    def merge(self, cp, si, bsdf, beta, mis: SubpathMis, depth, iteration, active, u):
        """The weighted merging estimate at camera vertex ``si`` (``depth`` segments from the
        sensor, MIS state ``mis`` after ``after_hit``, in ``iteration`` of the pass), per lane;
        ``u`` (uniform or None) decides its Russian roulette (``merge_roulette``)."""
        return self.gather(cp, si.p, (si, bsdf), beta, mis, depth, iteration, active, u)

    def accepts(self, site, n_y):
        """Whether a light vertex of normal ``n_y`` merges at the camera vertex ``site`` (facing
        the same way: not the far side of a thin wall)."""
        si, _ = site
        return dr.dot(n_y, si.n) > NORMAL_COS

    def evaluate(self, site, record, n_y, ok):
        """(f beta_y over the light vertex's cosine, forward and reverse densities) at the
        camera vertex ``site`` for the light vertex ``record`` (``RECORD``)."""
        si, bsdf = site
        wi_world = vector(record, RECORD["wi"])
        wi = si.to_local(wi_world)
        f_cos, pdf_fwd = bsdf.eval_pdf(mi.BSDFContext(mi.TransportMode.Radiance), si, wi, ok)   # f |wi . n_s|
        pdf_rev = reverse_pdf(bsdf, mi.BSDFContext(mi.TransportMode.Importance), si, wi, ok)
        cos_g = dr.abs(dr.dot(wi_world, n_y))
        value = dr.select(cos_g > 0, f_cos * spectrum_at(record, RECORD["beta"]) / dr.maximum(cos_g, 1e-30), 0.0)
        return value, pdf_fwd, pdf_rev

    def finish(self, site, total):
        """The estimate from the kernel-weighted sum (a medium divides by sigma_s)."""
        return total

    @dr.syntax
    def gather(self, cp, x, site, beta, mis: SubpathMis, depth, iteration, active, u):
        """``merge`` at the camera vertices at ``x`` (``site``: what ``evaluate`` needs there)."""
        w = cp.weights
        max_depth = dr.opaque(mi.UInt32, cp.max_depth)
        inv_cell = dr.gather(mi.Float, self.inv_cell_size, iteration)
        radius2 = dr.gather(mi.Float, self.radius2, iteration)
        inv_radius2 = dr.rcp(radius2)
        # the disc of radius r around x lies in the 2 x 2 x 2 cells of size 2r on x's side of
        # its cell's middle, on each axis
        scaled = x * inv_cell
        corner = mi.Vector3i(dr.floor(scaled) + dr.select(scaled - dr.floor(scaled) >= 0.5, 0.0, -1.0))
        taken, scale = merge_roulette(w, mis, u, self.IN_MEDIUM)
        result = mi.Spectrum(0)
        k = mi.UInt32(0)
        active = mi.Bool(active) & taken
        reads = mi.UInt32(0)                        # light vertices this merge reads (count_rays)
        while dr.hint(active & (k < 8), label="lab_vcm merge cells"):
            cell = corner + mi.Vector3i(mi.Int32(k & 1), mi.Int32((k >> 1) & 1), mi.Int32(k >> 2))
            bucket = hash_cell(cell, self.mask, iteration)
            # (a cell of the block beyond the disc's reach is skipped: 1.1 of 8, on average)
            lo = mi.Vector3f(cell) / inv_cell
            gap = dr.maximum(0.0, dr.maximum(lo - x, x - (lo + 1.0 / inv_cell)))
            reach = active & (dr.squared_norm(gap) < radius2)
            bounds = dr.gather(mi.ArrayXu, self.buckets, bucket, reach, shape=(2, dr.width(bucket)))
            j, end = mi.UInt32(bounds[0]), mi.UInt32(bounds[1])
            if dr.hint(cp.counters is not None, mode="scalar"):
                reads += dr.select(j < end, end - j, 0)
            while dr.hint(j < end, label="lab_vcm merge vertices"):
                slot = mi.UInt32(j)
                point = read(self.points, POINT_WIDTH, slot)
                p, n_y = vector(point, POINT["p"], mi.Point3f), vector(point, POINT["n"], mi.Normal3f)
                d2 = dr.squared_norm(p - x)
                ok = (d2 < radius2) & self.accepts(site, n_y)
                ok &= dr.all(cell_of(p, inv_cell) == cell) & (unbits(point[POINT["iteration"]]) == iteration)
                depth_y = unbits(point[POINT["depth"]])
                ok &= depth_y + depth <= max_depth
                if ok:     # (a branch: a packet without a light vertex in reach skips the rest)
                    record = read(self.records, RECORD_WIDTH, slot, ok)
                    value, pdf_fwd, pdf_rev = self.evaluate(site, record, n_y, ok)
                    light = SubpathMis(record[RECORD["dvcm"]], record[RECORD["dvc"]],
                                       dr.select(depth_y == 1, 1.0, 0.0), record[RECORD["dvm"]])
                    weight = float_or_zero(w.merge(light, mis, pdf_fwd, pdf_rev, self.IN_MEDIUM))
                    result += value * (weight * kernel(self.kernel, d2 * inv_radius2, self.DIMENSION))
                j += 1
            k += 1
        tally(cp.counters, "merge", taken, reads)
        return beta * self.finish(site, result) * (scale * dr.gather(mi.Float, self.normalisation, iteration))
