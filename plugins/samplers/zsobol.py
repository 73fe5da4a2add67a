"""``lab_zsobol``: one global Sobol sequence in Morton order (blue-noise error)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.samplers.common import (
    BLOCKS, IMAGE, PERMUTE, SCRAMBLE_X, SCRAMBLE_Y, Base2PairSampler, isqrt_exact, log2_ceil,
    mix32, morton_2d, owen_scramble_2, sample_key, sobol_02_owen, unit_key)

#: Multiplication in GF(4) = {0, 1, a, a^2 = a + 1} coded 0..3: entry (x, y) at bits 2 (4x + y).
GF4_MUL = [[0, 0, 0, 0], [0, 1, 2, 3], [0, 2, 3, 1], [0, 3, 1, 2]]
GF4_MUL_BITS = sum(GF4_MUL[x][y] << (2 * (4 * x + y)) for x in range(4) for y in range(4))


def _gf4_permute(digit, h):
    """Apply the permutation coded by the 6 low bits of ``h`` to a base-4 digit.

    Bits 0-1: r, bit 2: f (Frobenius x -> x^2, which swaps 2 and 3), bits 3-5:
    v, a = 1 + (3 v) >> 3 in {1, 2, 3} (weights 3:3:2). Result a * digit^(2^f) xor r,
    read from the table's rows a = 1..3: bit 8 (a - 1) + 2 d, with 8 (a - 1) = 3 v & 24.
    """
    d = digit ^ ((digit >> 1) & (h >> 2) & 1)
    row = (((h >> 3) & 7) * 3) & 24
    prod = (mi.UInt32(GF4_MUL_BITS >> 8) >> (row | (d << 1))) & 3
    return prod ^ (h & 3)


def permute_digits(m, shifts: list[int], odd_bit: bool, salt):
    """Nested random permutations of the base-4 digits of ``m`` at bit positions ``shifts``
    (top first) and, with ``odd_bit``, of bit 0; the rest of ``m`` reads as 0.

    pbrt-v4's scheme (digit j is permuted by a permutation of {0,1,2,3} chosen by a
    hash of the digits above it and a salt), with two savings: one mix32 serves two
    digits (6 bits for the upper digit, and for the lower one 6 bits picked by the
    upper digit's value, so it still depends on every digit above it), and the
    permutation is the affine map d -> a * d^(2^f) + r over GF(4), a in {1,2,3},
    f in {0,1}, r in {0..3} (AGammaL(1,4), all 24 permutations), evaluated with a
    32-bit multiplication table instead of a gather. The hash input includes the
    level, so equal higher digits at different levels draw different permutations.
    """
    index = mi.UInt32(0)
    for g in range(0, len(shifts), 2):
        top = shifts[g]
        h = mix32((m >> (top + 2)) ^ (salt + ((0x9E3779B9 * (g + 1)) & 0xFFFFFFFF)))
        d_top = (m >> top) & 3
        index |= _gf4_permute(d_top, h) << top
        if g + 1 < len(shifts):
            low = shifts[g + 1]
            index |= _gf4_permute((m >> low) & 3, h >> (6 + 6 * d_top)) << low
        elif odd_bit:
            # the odd lowest bit: flipped by a bit chosen by the digit above it
            index |= (m & 1) ^ ((h >> (6 + d_top)) & 1)
            odd_bit = False
    if odd_bit:
        h = mix32((m >> 1) ^ (salt + 0x7F4A7C15))
        index |= (m & 1) ^ (h & 1)
    return index


class LabZSobolSampler(Base2PairSampler):
    r"""Blue-noise Z-ordered Sobol sampler (:monosp:`lab_zsobol`)

    Ahmed & Wonka 2020, "Screen-Space Blue-Noise Diffusion of Monte Carlo
    Sampling Error via Hierarchical Ordering of Pixels" (also pbrt-v4's
    default ``ZSobolSampler``). The whole image shares one Sobol sequence:
    sample s of pixel (x, y) takes index ``morton(x, y) * 2^m + s`` with
    2^m >= spp. The base-4 digits of that index are then randomly permuted,
    digit by digit, with one of the 24 permutations of {0,1,2,3} chosen by a
    hash of the more significant digits, the level and a key (one mix32 per
    two digits, no table: ``permute_digits``); the point is the
    (0,2)-sequence at the permuted index with Owen scrambling by hashing
    (Burley 2020) keyed by (seed, dimension, axis). All keys are the image's
    (``common.IMAGE``): one sequence for all pixels. Each pixel thus gets a
    (0,m,2)-net, and every aligned 2^j x 2^j block of pixels a larger net:
    neighbouring pixels' errors are negatively correlated, so the error image
    is blue noise at unchanged per-pixel variance.

    Per dimension, pbrt-v4 permutes every digit of the index. Here the
    pixel digits (which block of the sequence a pixel gets) are permuted that
    way once per render and pass, then per dimension by a nested random flip
    of their bits (``owen_scramble_2`` of the pixel bits: bit j flips as a hash
    of the dimension's key and the bits above it, a dozen operations for all of
    them); only the ceil(m / 2) sample digits (which point of its block a
    sample takes) get per-dimension permutations of {0,1,2,3}, nested under
    the pixel's digits. The per-dimension flips keep the dimensions apart
    across pixels: with one pixel order for all dimensions, neighbouring pixels
    would get complementary blocks in every dimension at once, and the error
    would be less blue at low sample counts.

    =============== ====== =====================================================
    sample_count    int    Samples per pixel, >= 1; powers of two keep each
                           pixel a full net (a warning otherwise) (Default: 4)
    width           int    Width of the rendered pixel block (the film, or its
                           crop window). 0 = infer it from a square block; a
                           non-square block needs it (Default: 0)
    seed            int    Base seed, added to the render seed (Default: 0)
    =============== ====== =====================================================

    Limits: 2 log2(max(width, height)) + m <= 32 bits of index (e.g. 4096^2
    pixels at 256 spp); only Sobol dimensions 0 and 1 are used (padded). A
    wrong ``width`` keeps the estimate unbiased but loses the blue-noise
    arrangement. Multi-pass rendering rescrambles each pass.

    .. code-block:: python

        {'type': 'lab_zsobol', 'sample_count': 16, 'width': 128}
    """
    plugin_name = "lab_zsobol"
    prefers_power_of_two = True
    PARAMETERS = params.LAB_ZSOBOL
    _settings = ("width",)

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.width = self._values["width"]
        self.morton_index = mi.UInt32(0)
        self.pixel_block = mi.UInt32(0)
        self.image_key = mi.UInt32(0)
        self.n_bits = self.log2_spp = 0

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
        self.image_key = unit_key(seed_value, IMAGE)
        self.log2_spp = log2_spp
        self._permute_pixels()

    def advance(self):
        super().advance()
        self._permute_pixels()

    def _permute_pixels(self):
        """The permuted pixel digits of this render and pass, in place (low m bits 0)."""
        m = self.log2_spp
        shifts = [m + 2 * j for j in reversed(range((self.n_bits - m) // 2))]
        self.pixel_block = permute_digits(self.morton_index, shifts, False,
                                          sample_key(self.image_key, 0, self.pass_index, BLOCKS))

    def _sobol_index(self, dim):
        """The index of this sample's point for dimension ``dim``: the pixel's permuted
        digits with their bits flipped for this dimension, then its sample digits
        permuted for this dimension (reading the pixel's digits above them)."""
        m, pixel_bits = self.log2_spp, self.n_bits - self.log2_spp
        if pixel_bits > 0:
            flips = sample_key(self.image_key, dim, self.pass_index, PERMUTE)
            aligned = (self.pixel_block >> m) << (32 - pixel_bits)
            index = (owen_scramble_2(aligned, flips) >> (32 - pixel_bits)) << m
        else:
            index = mi.UInt32(0)
        shifts = [2 * j + m % 2 for j in reversed(range(m // 2))]
        salt = sample_key(self.image_key, dim, self.pass_index)
        return index | permute_digits(self.morton_index, shifts, m % 2 == 1, salt)

    def _scrambled(self, dim, two_d: bool):
        def key(purpose):
            return sample_key(self.image_key, dim, self.pass_index, purpose)
        return sobol_02_owen(self._sobol_index(dim), self.n_bits, key(SCRAMBLE_X),
                             key(SCRAMBLE_Y) if two_d else None)


mi.register_sampler("lab_zsobol", lambda props: LabZSobolSampler(props))
