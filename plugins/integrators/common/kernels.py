"""Density-estimation kernels on the plane, shared by ``lab_photon``'s gather and ``lab_vcm``'s
merges.

A kernel of radius r weighs a light vertex (photon) at distance d from the query point by
K(t) / r^2 with t = d / r, and integrates to 1 over the disc: int_0^1 K(t) 2 pi t dt = 1.

* ``epanechnikov``: K(t) = (2 / pi) (1 - t^2). Its second moment int t^2 K is 1/3 of the
  disc's r^2, against 1/2 for the constant kernel, so where the light varies smoothly its blur
  costs 2/3 the bias (4/9 the bias^2; less of a gain at edges and corners); its int K^2 is
  4 / (3 pi) against 1 / pi, so 4/3 the variance for the same light vertices (Silverman 1986, table 3.1, in two dimensions).
* ``constant``: K(t) = 1 / pi, the disc's area (Jensen's photon map; Georgiev et al.'s VCM and
  SmallVCM).
"""
from __future__ import annotations

import drjit as dr

#: A light vertex (photon) whose geometric normal is more than ~37 degrees off the query
#: point's is left out of the estimate (another wall at a corner, the far side of a thin slab).
NORMAL_COS = 0.8


def kernel(name: str, t2, dimension: int = 2):
    """K(t) for t^2 = ``t2`` in [0, 1) (callers reject t >= 1): the kernel ``name`` times r^2
    (a plain number where it does not depend on t); ``dimension`` 3: over the ball, times r^3
    (int_0^1 K(t) 4 pi t^2 dt = 1: (15 / (8 pi)) (1 - t^2), or 3 / (4 pi))."""
    if name == "epanechnikov":
        return (2.0 / dr.pi if dimension == 2 else 15.0 / (8.0 * dr.pi)) * (1.0 - t2)
    if name == "constant":
        return 1.0 / dr.pi if dimension == 2 else 3.0 / (4.0 * dr.pi)
    raise ValueError(f"unknown kernel {name!r}")     # (``params.KERNELS`` lists the names)
