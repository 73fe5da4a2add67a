"""``lab_zsobol``: one global Sobol sequence in Morton order (blue-noise error)."""
from __future__ import annotations

import itertools

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.samplers.common import (
    SALT_X, SALT_Y, LabSampler, check_int, hash2, hash3, isqrt_exact, log2_ceil, mix32,
    morton_2d, owen_scramble_2, sobol_02, to_unit_float)

#: The 24 permutations of the base-4 digits {0,1,2,3}, each packed as 4 x 2 bits.
DIGIT_PERMUTATIONS = [sum(p[d] << (2 * d) for d in range(4)) for p in itertools.permutations(range(4))]


class LabZSobolSampler(LabSampler):
    r"""Blue-noise Z-ordered Sobol sampler (:monosp:`lab_zsobol`)

    Ahmed & Wonka 2020, "Screen-Space Blue-Noise Diffusion of Monte Carlo
    Sampling Error via Hierarchical Ordering of Pixels" (also pbrt-v4's
    default ``ZSobolSampler``). The whole image shares one Sobol sequence:
    sample s of pixel (x, y) takes index ``morton(x, y) * 2^m + s`` with
    2^m >= spp. The base-4 digits of that index are then randomly permuted,
    digit by digit, with a permutation picked from the 24 by a hash of the
    more significant digits, the dimension and the seed; the point is the
    (0,2)-sequence at the permuted index with Owen scrambling by hashing
    (Burley 2020) seeded by (seed, dimension, axis). Each pixel thus gets a
    (0,m,2)-net, and every aligned 2^j x 2^j block of pixels a larger net:
    neighbouring pixels' errors are negatively correlated, so the error image
    is blue noise at unchanged per-pixel variance.

    =============== ====== =====================================================
    sample_count    int    Samples per pixel, >= 1; powers of two keep each
                           pixel a full net (a warning otherwise) (Default: 4)
    width           int    Width of the rendered pixel block (the film, or its
                           crop window). 0 = infer it from a square block; a
                           non-square block needs it (Default: 0)
    seed            int    Base seed, added to the render seed (Default: 0)
    =============== ====== =====================================================

    Limits: 2 log2(max(width, height)) + m <= 32 bits of index (e.g. 4096^2
    pixels at 256 spp); dimension pairs are decorrelated by the per-dimension
    digit permutations and scrambles (padding, only Sobol dimensions 0 and 1
    are used). A wrong ``width`` keeps the estimate unbiased but loses the
    blue-noise arrangement. Multi-pass rendering rescrambles each pass.

    .. code-block:: python

        {'type': 'lab_zsobol', 'sample_count': 16, 'width': 128}
    """
    plugin_name = "lab_zsobol"
    prefers_power_of_two = True
    _settings = ("width",)

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.width = check_int(self.plugin_name, "width", props.get("width", 0), 0)
        self.morton_index = mi.UInt32(0)
        self.seed_key = mi.UInt32(0)
        self.digit_perms = mi.UInt32(DIGIT_PERMUTATIONS)
        self.n_bits = 0

    def _seed_state(self, seed_value, wavefront_size, spp):
        n_pixels = max(1, -(-wavefront_size // spp))
        width = self.width or isqrt_exact(n_pixels)
        if width is None:
            raise ValueError(f"{self.plugin_name}: parameter 'width' must be set to the film (crop) width "
                             f"for a non-square block of {n_pixels} pixels (got width={self.width})")
        height = -(-n_pixels // width)
        res_bits = log2_ceil(max(width, height))
        log2_spp = log2_ceil(spp)
        self.n_bits = 2 * res_bits + log2_spp
        if self.n_bits > 32:
            raise ValueError(f"{self.plugin_name}: {width}x{height} pixels at {spp} spp need "
                             f"{self.n_bits} > 32 index bits; lower 'sample_count' or the resolution")
        lane = dr.arange(mi.UInt32, wavefront_size)
        pixel, sample = lane // spp, lane % spp
        self.morton_index = (morton_2d(pixel % width, pixel // width, res_bits) << log2_spp) | sample
        self.seed_key = mix32(seed_value)
        self.digit_perms = mi.UInt32(DIGIT_PERMUTATIONS)

    def _sobol_index(self, dim):
        """Random base-4 digit permutations of the Morton index (pbrt-v4's scheme)."""
        m = self.morton_index
        salt = self.seed_key ^ (mi.UInt32(dim) * 0x55555555) ^ (self.pass_index * 0x2545F491)
        index = mi.UInt32(0)
        odd = self.n_bits % 2 == 1
        for j in range(self.n_bits // 2):
            shift = 2 * j + (1 if odd else 0)
            digit = (m >> shift) & 3
            higher = m >> (shift + 2)
            p = (mix32(higher ^ salt) >> 24) % 24
            digit = (dr.gather(mi.UInt32, self.digit_perms, p) >> (2 * digit)) & 3
            index |= digit << shift
        if odd:
            index |= (m & 1) ^ (mix32((m >> 1) ^ salt) & 1)
        return index

    def _scrambled(self, dim, two_d: bool):
        x, y = sobol_02(self._sobol_index(dim), self.n_bits if two_d else 0)
        key = hash3(self.seed_key, dim, self.pass_index)
        x = owen_scramble_2(x, hash2(key, SALT_X))
        return x, (owen_scramble_2(y, hash2(key, SALT_Y)) if two_d else None)

    def _sample_1d(self, dim):
        return to_unit_float(self._scrambled(dim, False)[0])

    def _sample_2d(self, dim):
        x, y = self._scrambled(dim, True)
        return mi.Point2f(to_unit_float(x), to_unit_float(y))


mi.register_sampler("lab_zsobol", lambda props: LabZSobolSampler(props))
