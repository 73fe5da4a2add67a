"""``lab_zsobol``: one global Sobol sequence in Morton order (blue-noise error)."""
from __future__ import annotations

from functools import partial

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.samplers.common import (
    BLOCKS, IMAGE, PERMUTE, SCRAMBLE_X, SCRAMBLE_Y, Base2PairSampler, isqrt_exact, log2_ceil,
    mix32, morton_2d, owen_scramble_2, sample_key, sobol_02_owen, unit_key)
from mitsuba_lab.plugins.samplers.layout import film_block_size

#: Multiplication in GF(4) = {0, 1, a, a^2 = a + 1} coded 0..3: entry (x, y) at bits 2 (4x + y).
GF4_MUL = [[0, 0, 0, 0], [0, 1, 2, 3], [0, 2, 3, 1], [0, 3, 1, 2]]
GF4_MUL_BITS = sum(GF4_MUL[x][y] << (2 * (4 * x + y)) for x in range(4) for y in range(4))


def z_order(x, y, x_bits: int, y_bits: int):
    """Z-order (Morton) code of pixel (x, y) of a 2^x_bits x 2^y_bits grid: the low
    min(x_bits, y_bits) bits of x and y interleaved (x on the even bits), the rest
    of the longer axis above them. Every aligned 2^j x 2^j square (j up to the
    shorter axis's bits) is a run of consecutive codes; on a square grid this is
    ``morton_2d``, and a thin film (1 x n) keeps its pixels in order."""
    k = min(x_bits, y_bits)
    code = morton_2d(x, y, k)
    if x_bits > k:
        code |= (mi.UInt32(x) >> k) << (2 * k)
    elif y_bits > k:
        code |= (mi.UInt32(y) >> k) << (2 * k)
    return code


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


@documented("lab_zsobol")
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

    A ``sample_count`` that is a power of two keeps each pixel a full net (a warning otherwise).
    Any film works: square or not, crop windows, odd sizes (33x17, 1x64).
    Mitsuba tells a sampler only how many lanes it renders, so the film is bound
    to its sampler before the render (``layout.bind_film_layout``): every render
    through the lab does this (``mitsuba_lab.render.render``, the command line,
    the runner, and the lab integrators' own ``render``), whatever the integrator,
    Mitsuba's ``path`` included. A non-square block uses the Z-order of its
    enclosing 2^a x 2^b grid (``z_order``). Outside the lab, call
    ``bind_film_layout(scene)`` before ``mi.render`` or set ``width``; without
    either, the sampler logs one warning and takes the pixels as a square block
    (a square pixel count) or one row: the image is still unbiased, every pixel
    with its own points, but the error is blue noise only if the guess is the
    film's shape. A bound film wins over a different ``width`` (one warning).

    Limits: log2 of the enclosing grid + m <= 32 bits of index (e.g. 4096^2
    pixels at 256 spp); only Sobol dimensions 0 and 1 are used (padded).
    Multi-pass rendering rescrambles each pass.

    .. code-block:: python

        {'type': 'lab_zsobol', 'sample_count': 16}
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
        #: The pixel block of the last seed: (width, height, how it was found).
        self.layout = None
        # Zero-argument reader of the bound film's block size (``bind_film``), and the
        # warnings already given; both shared with clones and forks (one warning in all).
        self._film_size = None
        self._warned = set()

    # -- the film's layout -------------------------------------------------------
    def bind_film(self, film):
        """Hook of ``layout.bind_film_layout``: read the pixel block's shape from
        ``film`` at every seed (None: forget the film). A closure, not the film
        itself, is stored: Dr.Jit traverses a sampler's attributes as loop state."""
        self._film_size = None if film is None else partial(film_block_size, film)

    def _warn_once(self, key: str, message: str):
        if key not in self._warned:
            self._warned.add(key)
            mi.Log(mi.LogLevel.Warn, f"{self.plugin_name}: {message}")

    def _layout(self, wavefront_size: int, spp: int) -> tuple[int, int, int, str]:
        """(width, height, samples per pixel in this wavefront, source) of the pixels
        of a wavefront; source is 'film', 'width', 'one pixel' or 'guess' (with one
        warning). Every answer maps the pixels one to one onto Z-order codes, so the
        image is right whatever the answer; only the blue noise needs the true width."""
        why = "the film's layout is unknown (no film bound)"
        if self._film_size is not None:
            w, h = self._film_size()
            per_pass, rest = divmod(wavefront_size, w * h)
            # A bound film rendered in passes of spp / k samples per pixel: k divides spp.
            if rest == 0 and per_pass >= 1 and spp % per_pass == 0:
                if self.width and self.width != w:
                    self._warn_once("width", f"parameter 'width' ({self.width}) differs from the film's "
                                             f"{w}x{h} pixel block; the film's width is used")
                return w, h, per_pass, "film"
            why = f"a wavefront of {wavefront_size} lanes at {spp} spp does not fit the bound {w}x{h} film"
        n_pixels = max(1, -(-wavefront_size // spp))
        if n_pixels == 1:        # one pixel has one layout (mi.render ends with seed(0, 1))
            return 1, 1, spp, "one pixel"
        if self.width:
            if self._film_size is not None:
                self._warn_once("layout", f"{why}; using width={self.width}")
            return self.width, -(-n_pixels // self.width), spp, "width"
        side = isqrt_exact(n_pixels)
        w, h = (side, side) if side else (n_pixels, 1)
        self._warn_once("layout", f"{why}: its {n_pixels} pixels are taken as {'a square' if side else 'one row'}"
                                  f" of {w}x{h}, unbiased but blue noise only if that is the film's shape (set "
                                  "'width', or call mitsuba_lab.bind_film_layout(scene) before mi.render; "
                                  "the lab's own renders do)")
        return w, h, spp, "guess"

    def _seed_state(self, seed_value, wavefront_size, spp):
        width, height, spp, source = self._layout(wavefront_size, spp)
        x_bits, y_bits = log2_ceil(width), log2_ceil(height)
        pixel_bits = x_bits + y_bits + (x_bits + y_bits) % 2      # whole base-4 digits
        log2_spp = log2_ceil(spp)
        self.n_bits = pixel_bits + log2_spp
        if self.n_bits > 32:
            raise ValueError(f"{self.plugin_name}: {width}x{height} pixels at {spp} spp need "
                             f"{self.n_bits} > 32 index bits; lower 'sample_count' or the resolution")
        self.layout = (width, height, source)
        lane = dr.arange(mi.UInt32, wavefront_size)
        pixel, sample = lane // spp, lane % spp
        code = z_order(pixel % width, pixel // width, x_bits, y_bits)
        self.morton_index = (code << log2_spp) | sample
        self.image_key = unit_key(seed_value, IMAGE)
        self.log2_spp = log2_spp
        self._permute_pixels()

    def _copy_settings(self, other, with_state: bool):
        # Before the base's copy: it re-seeds a clone, which must see the same film.
        other._film_size, other._warned = self._film_size, self._warned
        return super()._copy_settings(other, with_state)

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
