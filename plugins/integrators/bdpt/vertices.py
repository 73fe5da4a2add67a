"""Light-subpath vertices in flat Dr.Jit arrays: one compacted buffer, one list per lane.

Only vertices a connection can end at are stored (those with a smooth BSDF component). Each
stored vertex goes to the next free slot (``dr.scatter_inc``), so memory follows the vertices
actually traced, whatever ``max_depth``; ``prev`` links a vertex to the lane's previous stored
one and the light tracer returns each lane's last slot, so a camera subpath walks its own
light subpath from the end (``NONE`` ends the list). When more vertices arrive than the
buffer holds, the extra ones are dropped and the caller traces the pass again with a larger
buffer (the same seed gives the same subpaths) or splits it (``integrator.py``).

A vertex keeps what evaluating its BSDF towards a camera vertex needs: the normals, texture
coordinates, the direction it was reached from, the BSDF pointer, and, only in scenes whose
BSDFs need them (``tangents``: anisotropic lobes, normal and bump maps), the shading frame's
tangent and dp/du, dp/dv, which otherwise cost more to compute and store than the rest (a
mesh's tangents are derived per hit); and what the estimate needs: the throughput (emitted
power over the subpath's density), the MIS quantities (``weights.SubpathMis``; ``first`` is
depth == 1, not stored; ``dvm`` only with vertex merging, ``merging``, which also keeps the
lane's iteration: lab_vcm merges within an iteration) and its depth. Under ``caustic_merges``
(``caustic``) a vertex where merging is no technique stores dvm = -1 (``NO_MERGE``; merging
never reads it, and a real dvm is >= 0), which tells connections its ``merges`` flag and the
grid to leave it out.

The fields are packed into fixed-width records of floats (integers by their bits), one flat
array per record kind (``POINT``, ``RECORD``, ``TANGENTS``): Dr.Jit reads a power-of-two run of
floats in one packet load, so a connection or a merge reads a vertex in two or three loads
instead of some twenty gathers (``benchmarks/bench_vcm.py`` measures the light pass and merging).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common.spectral import spectrum_channels

from .weights import SubpathMis

#: End of a lane's list.
NONE = 0xFFFFFFFF
#: The dvm of a light vertex that merging skips (``caustic_merges``).
NO_MERGE = -1.0

#: A vertex's *point* record (floats): position, geometric normal, then its depth and (with
#: merging) its iteration as integer bits. What merging tests first, and a connection too.
POINT = {"p": 0, "n": 3, "depth": 6, "iteration": 7}
POINT_WIDTH = 8
#: Its *record* (floats): shading normal, uv, the direction it was reached from (world), the MIS
#: quantities, the previous stored slot (integer bits) and the throughput's channels (1, 3 or 4).
RECORD = {"sh_n": 0, "uv": 3, "wi": 5, "dvcm": 8, "dvc": 9, "dvm": 10, "prev": 11, "beta": 12}
RECORD_WIDTH = 16
#: Only in scenes whose BSDFs need the tangent frame: shading tangent, dp/du, dp/dv.
TANGENTS = {"sh_s": 0, "dp_du": 3, "dp_dv": 6}
TANGENT_WIDTH = 16


def vertex_bytes(tangents: bool = False, media: bool = False) -> int:
    """Bytes per stored vertex (``tangents``: with the tangent record; ``media``: with the two
    medium pointers of a scene with media; merging's iteration and dvm have their places in
    every record)."""
    return 4 * (POINT_WIDTH + RECORD_WIDTH + 1 + TANGENT_WIDTH * tangents + 2 * media)


def bits(value) -> mi.Float:
    """An integer field stored in a float record (its bits, unchanged)."""
    return dr.reinterpret_array(mi.Float, mi.UInt32(value))


def unbits(value) -> mi.UInt32:
    return dr.reinterpret_array(mi.UInt32, value)


def read(buffer, width: int, slot, active=True):
    """Records ``slot`` of a flat buffer of ``width``-float records, in one packet load each."""
    return dr.gather(mi.ArrayXf, buffer, slot, active, shape=(width, dr.width(slot)))


def write(buffer, columns, width: int, slot, active):
    """Scatter records (``columns``: Floats, at most ``width``; the rest left as they are)."""
    columns = list(columns) + [mi.Float(0.0)] * (width - len(columns))
    dr.scatter(buffer, mi.ArrayXf(columns), slot, active)


def vector(record, offset: int, kind=mi.Vector3f):
    return kind(record[offset], record[offset + 1], record[offset + 2])


def channels_of(value) -> list:
    """A Spectrum's channels as Floats (1, 3 or 4)."""
    return [value[i] for i in range(spectrum_channels())]


def spectrum_at(record, offset: int) -> mi.Spectrum:
    return mi.Spectrum(*[record[offset + i] for i in range(spectrum_channels())])


class LightVertices:
    """A buffer of ``capacity`` light vertices: per vertex a point record, a record, its BSDF
    pointer and, with ``tangents``, a tangent record, each record in one flat array so that a
    vertex is read in a few packet loads (Dr.Jit gathers power-of-two runs of floats at once)."""

    def __init__(self, capacity: int, tangents: bool = False, merging: bool = False, caustic: bool = False,
                 media: bool = False):
        self.capacity = capacity
        self.media = media
        self.merging = merging
        self.caustic = caustic and merging
        self.tangents = tangents
        size = max(capacity, 1)
        self.points = dr.empty(mi.Float, POINT_WIDTH * size)   # (only slots below the store count are read)
        self.records = dr.empty(mi.Float, RECORD_WIDTH * size)
        self.bsdf = dr.empty(mi.BSDFPtr, size)
        self.frames = dr.empty(mi.Float, TANGENT_WIDTH * size) if tangents else None
        # in scenes with media (``media_paths``): the medium a vertex was reached in, and the one
        # beyond it (across a medium transition; else the same); a medium vertex has normal 0
        self.medium_in = dr.empty(mi.MediumPtr, size) if media else None
        self.medium_beyond = dr.empty(mi.MediumPtr, size) if media else None

    def arrays(self) -> tuple:
        return tuple(a for a in (self.points, self.records, self.bsdf, self.frames, self.medium_in,
                                 self.medium_beyond) if a is not None)

    def store(self, slot, si: mi.SurfaceInteraction3f, wi_world, beta, mis: SubpathMis, depth, prev, active,
              iteration=0, bsdf=None):
        """Scatter one vertex per active lane to ``slot`` (``wi_world``: the direction it was
        reached from, in world space: converting ``si.wi`` would need the tangent frame)."""
        write(self.points, [*si.p, *si.n, bits(depth), bits(iteration)], POINT_WIDTH, slot, active)
        dvm = mis.dvm if self.merging else 0.0
        if self.caustic:
            dvm = dr.select(mis.merges > 0, dvm, NO_MERGE)
        write(self.records, [*si.sh_frame.n, *si.uv, *wi_world, mi.Float(mis.dvcm), mi.Float(mis.dvc),
                             mi.Float(dvm), bits(prev), *channels_of(beta)], RECORD_WIDTH, slot, active)
        dr.scatter(self.bsdf, si.bsdf() if bsdf is None else bsdf, slot, active)
        if self.tangents:
            write(self.frames, [*si.sh_frame.s, *si.dp_du, *si.dp_dv], TANGENT_WIDTH, slot, active)

    def depth_and_prev(self, slot, active):
        """(depth, previous stored slot) of the vertices at ``slot``: what walking a lane's list
        needs, in two gathers."""
        depth = dr.gather(mi.Float, self.points, slot * POINT_WIDTH + POINT["depth"], active)
        prev = dr.gather(mi.Float, self.records, slot * RECORD_WIDTH + RECORD["prev"], active)
        return unbits(depth), unbits(prev)

    def load(self, slot, wavelengths, active):
        """(SurfaceInteraction3f, BSDFPtr, beta, SubpathMis, depth, prev) of the vertices at
        ``slot``; the interaction carries the camera lane's ``wavelengths``."""
        point, record = read(self.points, POINT_WIDTH, slot, active), read(self.records, RECORD_WIDTH, slot, active)
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.p, si.n = vector(point, POINT["p"], mi.Point3f), vector(point, POINT["n"], mi.Normal3f)
        si.uv = mi.Point2f(record[RECORD["uv"]], record[RECORD["uv"] + 1])
        sh_n = vector(record, RECORD["sh_n"], mi.Normal3f)
        if self.tangents:
            frame = read(self.frames, TANGENT_WIDTH, slot, active)
            sh_s = vector(frame, TANGENTS["sh_s"])
            si.sh_frame = mi.Frame3f(sh_s, dr.cross(sh_n, sh_s), sh_n)
            si.dp_du, si.dp_dv = vector(frame, TANGENTS["dp_du"]), vector(frame, TANGENTS["dp_dv"])
        else:                                    # isotropic BSDFs: any tangent will do
            si.sh_frame = mi.Frame3f(sh_n)
        si.wi = si.to_local(vector(record, RECORD["wi"]))          # stored in world space
        si.wavelengths = wavelengths
        si.t = mi.Float(1.0)                     # a valid hit
        depth = unbits(point[POINT["depth"]])
        dvm = record[RECORD["dvm"]] if self.merging else 0.0
        merges = dr.select(dvm >= 0, 1.0, 0.0) if self.caustic else 1.0
        mis = SubpathMis(record[RECORD["dvcm"]], record[RECORD["dvc"]], dr.select(depth == 1, 1.0, 0.0), dvm,
                         merges)
        return (si, dr.gather(mi.BSDFPtr, self.bsdf, slot, active), spectrum_at(record, RECORD["beta"]), mis,
                depth, unbits(record[RECORD["prev"]]))

    def store_media(self, slot, medium_in, medium_beyond, active):
        """The media of the vertices at ``slot`` (scenes with media)."""
        dr.scatter(self.medium_in, medium_in, slot, active)
        dr.scatter(self.medium_beyond, medium_beyond, slot, active)

    def load_media(self, slot, active):
        """(medium reached in, medium beyond, direction reached from in world space) of the vertices
        at ``slot`` (a medium vertex has no frame to hold that direction locally)."""
        record = read(self.records, RECORD_WIDTH, slot, active)
        return (dr.gather(mi.MediumPtr, self.medium_in, slot, active),
                dr.gather(mi.MediumPtr, self.medium_beyond, slot, active), vector(record, RECORD["wi"]))
