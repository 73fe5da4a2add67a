"""A hashed uniform grid over points (photons, light vertices), built by a counting sort in Dr.Jit.

Build (Teschner et al. 2003 hash; a counting sort as in GPU particle grids):

1. cell c = floor(p / cell_size) (three int32), bucket h = hash(c) mod T, with T a
   power of two >= 2 x photons;
2. counts[h] += 1 by ``scatter_reduce`` (atomic adds);
3. start = exclusive prefix sum of counts;
4. each photon takes slot start[h] + (its rank inside the bucket, from ``scatter_inc``)
   and the records are scattered there, so every bucket is one contiguous range
   [start[h], start[h] + counts[h]).

Every photon lands in exactly one bucket. Distinct cells can share a bucket (hash
collisions), so a query compares the photon's own cell with the cell it asked for
and never counts a photon twice. Nothing loops over photons in Python.

With cell_size = r, the photons within distance r of x lie in the 3 x 3 x 3 cells
around x's cell: a query visits those 27 buckets.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

HASH_PRIMES = (73856093, 19349663, 83492791)
#: Mixes a separate index (lab_vcm's iteration) into a cell's hash.
SALT_PRIME = 2654435761
#: Neighbour cells visited by a query (cell size = radius).
NEIGHBOURS = 27


def cell_of(p, inv_cell_size):
    """Integer cell coordinates of points ``p`` (Point3f) as an Array3i."""
    return mi.Vector3i(dr.floor(p * inv_cell_size))


def neighbour_cell(home, k):
    """The k-th (0 .. NEIGHBOURS - 1) of the 3 x 3 x 3 cells around integer cell ``home``."""
    return home + mi.Vector3i(mi.Int32(k % 3) - 1, mi.Int32((k // 3) % 3) - 1, mi.Int32(k // 9) - 1)


def hash_cell(cell, mask, salt=None):
    """Bucket index of an integer cell: XOR of the coordinates times large primes, mod T
    (``salt``: a UInt32 mixed in the same way, so equal cells of different grids differ)."""
    u = [dr.reinterpret_array(mi.UInt32, cell[i]) for i in range(3)]
    h = (u[0] * HASH_PRIMES[0]) ^ (u[1] * HASH_PRIMES[1]) ^ (u[2] * HASH_PRIMES[2])
    if salt is not None:
        h ^= mi.UInt32(salt) * SALT_PRIME
    return h & mask


def table_size_for(count: int) -> int:
    """Smallest power of two >= 2 x count (at least 1024)."""
    size = 1024
    while size < 2 * count:
        size *= 2
    return size


def counting_sort(bucket, size: int):
    """(slot, start, count) of points in buckets ``bucket`` of a table of ``size``: each point's
    place in the bucket-sorted order; each bucket's first place and its size."""
    count = dr.zeros(mi.UInt32, size)
    dr.scatter_reduce(dr.ReduceOp.Add, count, mi.UInt32(1), bucket)
    start = dr.prefix_sum(count)                     # exclusive
    fill = dr.zeros(mi.UInt32, size)
    rank = dr.scatter_inc(fill, bucket)              # rank of the point inside its bucket
    slot = dr.gather(mi.UInt32, start, bucket) + rank
    dr.eval(slot, count, start)
    return slot, start, count
