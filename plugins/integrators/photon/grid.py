"""The photon map of one pass: photon records sorted into the hashed grid of
``common.grid`` (its build and queries are described there).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common.grid import cell_of, counting_sort, hash_cell, table_size_for

from .records import PhotonRecords


class PhotonGrid:
    """Photon records sorted by bucket, with each bucket's range.

    Attributes: ``records`` (sorted), ``start`` and ``count`` (UInt32, one per
    bucket), ``radius``, ``inv_cell_size``, ``mask`` (T - 1), ``photon_count``.
    Scalars used inside kernels are opaque Dr.Jit values, so a new grid with
    another radius or size reuses the compiled gather kernel.
    """

    def __init__(self, records: PhotonRecords, radius: float, table_size: int | None = None):
        if not radius > 0:
            raise ValueError(f"grid radius must be > 0, got {radius}")
        n = records.count
        size = table_size or table_size_for(n)
        if size & (size - 1):
            raise ValueError(f"table size must be a power of two, got {size}")
        self.radius = float(radius)
        self.photon_count = n
        self.table_size = size
        self.inv_cell_size = dr.opaque(mi.Float, 1.0 / radius)
        self.radius2 = dr.opaque(mi.Float, radius * radius)
        self.inv_volume = dr.opaque(mi.Float, 1.0 / radius ** 3)       # (the ball's 1 / r^3)
        self.mask = dr.opaque(mi.UInt32, size - 1)
        if n == 0:
            self.records = records
            self.start = dr.zeros(mi.UInt32, size)
            self.count = dr.zeros(mi.UInt32, size)
            self.bucket = mi.UInt32()
            self.slot = mi.UInt32()
            return
        bucket = hash_cell(cell_of(records.p, self.inv_cell_size), self.mask)
        slot, start, count = counting_sort(bucket, size)
        self.records = records.scattered(slot).eval()
        self.start, self.count = start, count
        self.bucket, self.slot = bucket, slot            # kept for tests and statistics
