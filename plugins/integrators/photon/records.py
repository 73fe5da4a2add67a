"""Photon records: one structure of arrays per photon map (or per batch of one).

A record is what the density estimate needs at a stored interaction:

============ ========= ===================================================
p            Point3f   position of the interaction
wi           Vector3f  direction towards where the photon came from (world)
n            Normal3f  geometric normal at the interaction; 0 at a collision
                       in a participating medium (a volumetric photon)
power        Spectrum  flux carried by the photon, already divided by the
                       number of photons emitted in the pass (watts; in
                       spectral variants at the pass's wavelengths)
depth        UInt32    segments from the emitter to here (1 = no bounce yet)
============ ========= ===================================================
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common.spectral import spectrum_channels

FIELDS = ("p", "wi", "n", "power", "depth")


def record_bytes() -> int:
    """Bytes per record in the current variant (3 vectors + the power's channels + depth)."""
    return 4 * (3 * 3 + spectrum_channels()) + 4


class PhotonRecords:
    """Photon records as Dr.Jit arrays of equal width (``count`` photons)."""

    def __init__(self, p, wi, n, power, depth):
        self.p, self.wi, self.n, self.power, self.depth = p, wi, n, power, depth

    @classmethod
    def allocate(cls, capacity: int) -> "PhotonRecords":
        return cls(dr.zeros(mi.Point3f, capacity), dr.zeros(mi.Vector3f, capacity),
                   dr.zeros(mi.Normal3f, capacity), dr.zeros(mi.Spectrum, capacity),
                   dr.zeros(mi.UInt32, capacity))

    @property
    def count(self) -> int:
        return dr.width(self.depth)

    def store(self, slot, p, wi, n, power, depth, active):
        """Scatter one record per active lane to index ``slot``."""
        dr.scatter(self.p, p, slot, active)
        dr.scatter(self.wi, wi, slot, active)
        dr.scatter(self.n, n, slot, active)
        dr.scatter(self.power, power, slot, active)
        dr.scatter(self.depth, depth, slot, active)

    def take(self, count: int) -> "PhotonRecords":
        """The first ``count`` records (a gather: the rest of the buffer is released)."""
        index = dr.arange(mi.UInt32, count)
        return self.permuted(index)

    def permuted(self, index) -> "PhotonRecords":
        """Records reordered so that record i of the result is record ``index[i]``."""
        return PhotonRecords(*(dr.gather(type(getattr(self, f)), getattr(self, f), index) for f in FIELDS))

    def scattered(self, destination) -> "PhotonRecords":
        """Records reordered so that record i goes to ``destination[i]`` (a permutation)."""
        out = PhotonRecords.allocate(self.count)
        out.store(destination, self.p, self.wi, self.n, self.power, self.depth, True)
        return out

    def split_media(self) -> tuple["PhotonRecords", "PhotonRecords"]:
        """(surface photons, volumetric photons): the records whose normal is 0 lie in a medium."""
        if self.count == 0:     # (no photon stored: an environment in unbounded fog sends none)
            return self, PhotonRecords.allocate(0)
        in_medium = dr.squared_norm(self.n) == 0
        return (self.permuted(dr.compress(~in_medium)).eval(), self.permuted(dr.compress(in_medium)).eval())

    def arrays(self) -> tuple:
        return tuple(getattr(self, f) for f in FIELDS)

    def eval(self):
        dr.eval(*self.arrays())
        return self

    def total_power(self):
        """Sum of the stored flux, per channel (a Python list)."""
        channels = len(self.power)
        if self.count == 0:
            return [0.0] * channels
        return [float(dr.sum(mi.Float64(self.power[i]))[0]) for i in range(channels)]
