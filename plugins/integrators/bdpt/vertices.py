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
lane's iteration: lab_vcm merges within an iteration) and its depth.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .weights import SubpathMis

#: End of a lane's list.
NONE = 0xFFFFFFFF

_FIELDS = (("p", "Point3f"), ("n", "Normal3f"), ("sh_n", "Normal3f"), ("uv", "Point2f"), ("wi", "Vector3f"),
           ("beta", "Spectrum"), ("dvcm", "Float"), ("dvc", "Float"), ("depth", "UInt32"), ("prev", "UInt32"),
           ("bsdf", "BSDFPtr"))
_TANGENT_FIELDS = (("sh_s", "Vector3f"), ("dp_du", "Vector3f"), ("dp_dv", "Vector3f"))
_MERGE_FIELDS = (("dvm", "Float"), ("iteration", "UInt32"))


def vertex_bytes(tangents: bool = False, merging: bool = False) -> int:
    """Bytes per stored vertex in the current variant (``tangents``: with the tangent fields;
    ``merging``: with dvm)."""
    channels = dr.size_v(mi.Spectrum) if not mi.is_polarized else 16
    return 4 * (3 * 4 + 2 + channels + 2 + 3 + 9 * tangents + 2 * merging)


class LightVertices:
    """A buffer of ``capacity`` light vertices (structure of arrays)."""

    def __init__(self, capacity: int, tangents: bool = False, merging: bool = False):
        self.capacity = capacity
        self.merging = merging
        self.fields = _FIELDS + (_TANGENT_FIELDS if tangents else ()) + (_MERGE_FIELDS if merging else ())
        for name, kind in self.fields:   # (only slots below the store count are ever read)
            setattr(self, name, dr.empty(getattr(mi, kind), max(capacity, 1)))

    @property
    def tangents(self) -> bool:
        return _TANGENT_FIELDS[0] in self.fields

    def arrays(self) -> tuple:
        return tuple(getattr(self, name) for name, _ in self.fields)

    def store(self, slot, si: mi.SurfaceInteraction3f, wi_world, beta, mis: SubpathMis, depth, prev, active,
              iteration=0):
        """Scatter one vertex per active lane to ``slot`` (``wi_world``: the direction it was
        reached from, in world space: converting ``si.wi`` would need the tangent frame)."""
        values = {"p": si.p, "n": si.n, "sh_n": si.sh_frame.n, "uv": si.uv, "wi": wi_world, "beta": beta,
                  "dvcm": mis.dvcm, "dvc": mis.dvc, "depth": depth, "prev": prev, "bsdf": si.bsdf()}
        if self.tangents:
            values.update(sh_s=si.sh_frame.s, dp_du=si.dp_du, dp_dv=si.dp_dv)
        if self.merging:
            values.update(dvm=mis.dvm, iteration=mi.UInt32(iteration))
        for name, _ in self.fields:
            dr.scatter(getattr(self, name), values[name], slot, active)

    def load(self, slot, wavelengths, active):
        """(SurfaceInteraction3f, BSDFPtr, beta, SubpathMis, depth, prev) of the vertices at
        ``slot``; the interaction carries the camera lane's ``wavelengths``."""
        def get(name, kind):
            return dr.gather(getattr(mi, kind), getattr(self, name), slot, active)

        si = dr.zeros(mi.SurfaceInteraction3f)
        si.p, si.n, si.uv = get("p", "Point3f"), get("n", "Normal3f"), get("uv", "Point2f")
        sh_n = get("sh_n", "Normal3f")
        if self.tangents:
            sh_s = get("sh_s", "Vector3f")
            si.sh_frame = mi.Frame3f(sh_s, dr.cross(sh_n, sh_s), sh_n)
            si.dp_du, si.dp_dv = get("dp_du", "Vector3f"), get("dp_dv", "Vector3f")
        else:                                    # isotropic BSDFs: any tangent will do
            si.sh_frame = mi.Frame3f(sh_n)
        si.wi = si.to_local(get("wi", "Vector3f"))          # stored in world space
        si.wavelengths = wavelengths
        si.t = mi.Float(1.0)                     # a valid hit
        depth = get("depth", "UInt32")
        mis = SubpathMis(get("dvcm", "Float"), get("dvc", "Float"), dr.select(depth == 1, 1.0, 0.0),
                         get("dvm", "Float") if self.merging else 0.0)
        return si, get("bsdf", "BSDFPtr"), get("beta", "Spectrum"), mis, depth, get("prev", "UInt32")
