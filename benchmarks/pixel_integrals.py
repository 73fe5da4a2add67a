"""Pixel integrals: how well a sampler's first dimension pair integrates random 2D
functions over a pixel, against exact values.

A render's pixel integrals are mostly of two kinds: smooth (shading, soft
lighting) and discontinuous (edges, the border of a light). Owen-scrambled nets
win by a wide margin on the first kind and not on the second; these functions
measure both on their own, away from everything else a render mixes in
(``bench_samplers.py`` beside it, ``tests/plugins/test_samplers.py``). ``exact_owen_pair``
is a slow numpy reference of exactly nested uniform scrambling, to check a
hash-based scramble against. Needs scipy (the ``dev`` extra).
"""
from __future__ import annotations

from typing import Callable, Iterable

import mitsuba as mi
import numpy as np

from mitsuba_lab.plugins.samplers.common import log2_ceil

#: A sampler's first 2D request: (spp, n_pixels, seed) -> x, y of shape (n_pixels, spp).
PairFn = Callable[[int, int, int], tuple[np.ndarray, np.ndarray]]


def first_pair(name: str, spp: int, n_pixels: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The first 2D request of ``n_pixels`` pixels x ``spp`` samples, shaped (n_pixels, spp)."""
    params = {"type": name, "sample_count": spp}
    if name == "lab_zsobol":
        params["width"] = int(round(n_pixels ** 0.5))
    s = mi.load_dict(params)
    s.set_samples_per_wavefront(spp)      # Mitsuba's samplers: spp consecutive lanes per pixel
    s.seed(seed, n_pixels * spp)
    p = s.next_2d()
    return np.array(p.x, np.float64).reshape(n_pixels, spp), np.array(p.y, np.float64).reshape(n_pixels, spp)


def exact_owen_pair(spp: int, n_pixels: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Reference for lab_sobol's hash scramble: the first 2^m Sobol points (scipy, unscrambled)
    under *exact* nested uniform scrambling, one independent random bit per node of the
    binary tree (per pixel, axis, level and prefix; splitmix64 of the tuple), in numpy."""
    from scipy.stats import qmc
    m = log2_ceil(spp)
    if 1 << m != spp:
        raise ValueError("exact Owen reference: sample count must be a power of two")
    u64 = np.uint64
    points = (qmc.Sobol(d=2, scramble=False).random_base2(m) * 2.0 ** 32).astype(u64)
    seeds = np.random.default_rng(seed).integers(0, 2 ** 62, (2, n_pixels), dtype=u64)

    def splitmix64(x):
        with np.errstate(over="ignore"):
            x = x + u64(0x9E3779B97F4A7C15)
            x = (x ^ (x >> u64(30))) * u64(0xBF58476D1CE4E5B9)
            x = (x ^ (x >> u64(27))) * u64(0x94D049BB133111EB)
        return x ^ (x >> u64(31))

    coords = []
    for axis in range(2):
        v, out = points[:, axis], np.zeros((n_pixels, spp), u64)
        for k in range(32):                                     # bit k below the binary point
            prefix = v >> u64(32 - k) if k else np.zeros_like(v)
            with np.errstate(over="ignore"):
                node = splitmix64(seeds[axis][:, None] * u64(1000003) + (prefix[None, :] << u64(6)) + u64(k))
            bit = (v[None, :] >> u64(31 - k)) & u64(1)
            out |= (bit ^ ((node >> u64(40)) & u64(1))) << u64(31 - k)
        coords.append(out.astype(np.float64) * 2.0 ** -32)
    return coords[0], coords[1]


def integrand_families(n_pixels: int, rng: np.random.Generator):
    """Two families of random 2D integrands on the unit square, one per pixel, with
    exact integrals: a smooth Gaussian bump (sigma in [0.15, 0.4]) and the indicator
    of a disk inside the square (radius in [0.15, 0.45]), the discontinuity that
    dominates a render's pixel integrals at the light's edge."""
    from scipy.special import ndtr
    c, sig = rng.uniform(0, 1, (n_pixels, 2)), rng.uniform(0.15, 0.4, (n_pixels, 1))
    gauss_exact = np.prod(sig * np.sqrt(2 * np.pi) * (ndtr((1 - c) / sig) - ndtr(-c / sig)), axis=1)
    r = rng.uniform(0.15, 0.45, n_pixels)
    d = r[:, None] + rng.uniform(0, 1, (n_pixels, 2)) * (1 - 2 * r[:, None])
    return {
        "gaussian": (lambda x, y: np.exp(-((x - c[:, :1]) ** 2 + (y - c[:, 1:]) ** 2) / (2 * sig ** 2)),
                     gauss_exact),
        "disk": (lambda x, y: ((x - d[:, :1]) ** 2 + (y - d[:, 1:]) ** 2 < r[:, None] ** 2).astype(float),
                 np.pi * r ** 2),
    }


def pixel_integral_mse(pair: PairFn, spp: int, families: dict, seeds: Iterable[int]) -> dict[str, list[float]]:
    """MSE over the pixels of each family's estimates, one value per seed."""
    out = {fam: [] for fam in families}
    n_pixels = len(next(iter(families.values()))[1])
    for seed in seeds:
        x, y = pair(spp, n_pixels, seed)
        for fam, (f, truth) in families.items():
            out[fam].append(float(np.mean((f(x, y).mean(axis=1) - truth) ** 2)))
    return out
