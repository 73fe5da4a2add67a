"""``lab_halton``: randomised Halton points per pixel."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.params import RANDOMIZATIONS  # noqa: F401 (re-exported)
from mitsuba_lab.plugins.samplers.common import (
    ONE_MINUS_EPS, LabSampler, mix32, sample_key, to_float, to_unit_float, unit_key)


def first_primes(n: int) -> list[int]:
    primes, k = [], 2
    while len(primes) < n:
        if all(k % p for p in primes if p * p <= k):
            primes.append(k)
        k += 1
    return primes


#: Bases of the supported dimensions; dimension d uses PRIMES[d mod 64].
PRIMES = first_primes(64)
#: Gaps PRIMES[d + 1] - PRIMES[d] (all <= 14) as 4-bit nibbles, 8 per word:
#: dimension d's gap is nibble d & 7 of word d >> 3 (the last one, 0, is never read).
GAP_WORDS = tuple(sum((PRIMES[8 * w + j + 1] - PRIMES[8 * w + j] if 8 * w + j + 1 < len(PRIMES) else 0) << (4 * j)
                      for j in range(8)) for w in range(len(PRIMES) // 8))
#: Largest sample count: digits are extracted in float32 as floor((n + 1/2) / b),
#: exact for every n < 2^21 and b <= 311 (checked exhaustively in the tests).
MAX_SPP = params.HALTON_MAX_SPP


def n_digits(spp: int, base: int) -> int:
    """Base-``base`` digits of the largest sample index spp - 1 (0 when spp == 1)."""
    k, reach = 0, 1
    while reach < spp:
        reach *= base
        k += 1
    return k


def refined_reciprocal(b, approx):
    """float32(1 / b), correctly rounded, from ``approx`` within 3 ulps of it (dr.rcp is
    CUDA's rcp.approx, off by up to an ulp; LLVM's is exact and stays so): one Newton step in
    fmas, exact for every base of lab_halton (tests/plugins/test_samplers.py). The trace-time
    path's constants are correctly rounded, so both paths give the same numbers on a GPU."""
    return dr.fma(dr.fma(-b, approx, 1.0), approx, approx)


def digit_constants(base, inv_base):
    """What the digit steps of one coordinate use: (b, 1/b, 1/(2b), b 2^-23, b - 1)."""
    return base, inv_base, 0.5 * inv_base, base * 2.0 ** -23, base - 1.0


@documented("lab_halton")
class LabHaltonSampler(LabSampler):
    r"""Randomised Halton sampler (:monosp:`lab_halton`)

    Sample i of a pixel has coordinate d = radical inverse of i in base
    ``PRIMES[d]`` (the first 64 primes; dimension d >= 64 reuses base
    ``PRIMES[d mod 64]`` with an independent randomisation). The digits are
    randomised per (pixel, dimension), which makes each point uniform
    (unbiased) and decorrelates pixels while keeping the Halton structure:

    * ``permute_digits``: digit k is mapped by ``d -> (a_k d + c_k) mod b``
      with a_k in [1, b-1], c_k in [0, b-1] hashed from (pixel, dimension, k)
      -- random *linear* digit permutations (Matousek 1998), a subfamily of
      all b! permutations in which each digit's image is uniform;
    * ``owen``: the same maps, but (a_k, c_k) also hash the less significant
      digits of i (the prefix of the radical inverse), a nested (Owen 1995)
      scramble in base b: the hash of digit k is chained, h_{k+1} =
      mix(h_k xor d_k), h_0 = hash(pixel, dimension).

    Only the K_b = ceil(log_b spp) digits the sample indices 0..spp-1 can
    fill are permuted (one for every base >= spp); the digits past them are
    replaced by a uniform offset below digit K_b (per pixel and dimension for
    ``permute_digits``, per sample for ``owen``), which is what permuting
    infinitely many zero digits amounts to. Each pixel uses the first spp
    points of the sequence, so any sample count is fine.

    Cost: inside the integrator's path loop the dimension index is a loop
    variable. The base of the next dimension is carried from request to request
    as sampler state: the next prime is the current one plus a 4-bit gap read
    from eight 32-bit constants through a 3-level select tree (a gather from a
    64-entry table is slower on CPUs, though every lane reads the same entry).
    The first digit is unrolled and the rest run in one symbolic loop shared by
    both coordinates of a 2D request, for max K_b = K of the smaller base
    trips: the loop carries b_min^k and stops once it reaches spp, so K_b is
    never computed. Where the dimension is known at trace time (the pixel
    position, requested before the loop) the bases are constants and all
    digits are unrolled, with the same numbers as the loop. There is no
    integer division in the kernel: digits and ``(a d + c) mod b`` are float32
    ``floor((n + 1/2) / b)`` on integers below 2^21 (exact). The affine map
    takes one uniform ``u = b (h >> 9) / 2^23`` from the digit's hash: ``c =
    floor(u)`` (uniform up to b 2^-23) and ``a = 1 + floor((b - 1) frac(u))``
    (frac(u) keeps at least 14 bits, and given c it is still about uniform). A
    uniformly random affine map over GF(b) is sharply 2-transitive (a pair of
    distinct digits goes to a uniform pair of distinct digits), which is all
    that Owen's variance analysis asks of the nested permutations.

    .. code-block:: python

        {'type': 'lab_halton', 'sample_count': 64, 'randomization': 'owen'}
    """
    plugin_name = "lab_halton"
    #: sample_count limited to [1, 2^21], and randomization (``params.LAB_HALTON``).
    PARAMETERS = params.LAB_HALTON
    _settings = ("randomization",)

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.randomization = self._values["randomization"]
        self.pixel_key = mi.UInt32(0)
        self.sample_index = mi.UInt32(0)
        self.base = mi.UInt32(PRIMES[0])   # base of the next dimension to be drawn

    def _check_spp(self, spp: int):
        """A render's sample count (set after construction), checked by the declaration."""
        next(p for p in self.PARAMETERS if p.name == "sample_count").convert(self.plugin_name, spp)

    def _seed_state(self, seed_value, wavefront_size, spp):
        self._check_spp(spp)
        pixel, sample = self.wavefront_layout(wavefront_size, spp)
        self.pixel_key = unit_key(seed_value, pixel)
        self.sample_index = sample

    def _restart_dims(self):
        super()._restart_dims()
        self.base = mi.UInt32(PRIMES[0])

    def _next_base(self, base, dim):
        """PRIMES[(dim + 1) mod 64] given base = PRIMES[dim mod 64], without a gather."""
        d = mi.UInt32(dim) & (len(PRIMES) - 1)
        words, word_index = [mi.UInt32(w) for w in GAP_WORDS], d >> 3
        for bit in (1, 2, 4):
            pick = (word_index & bit) != 0
            words = [dr.select(pick, words[i + 1], words[i]) for i in range(0, len(words), 2)]
        gap = (words[0] >> ((d & 7) << 2)) & 15
        return dr.select(d == len(PRIMES) - 1, mi.UInt32(PRIMES[0]), base + gap)

    def _bases(self, dims):
        """The bases of the consecutive dimensions ``dims`` and the request's digit count
        (max K_b): Python numbers where the dimensions are known at trace time, else
        Float arrays from the carried base and None. Moves the carried base past them."""
        if all(isinstance(dim, int) for dim in dims):
            bases = [PRIMES[dim % len(PRIMES)] for dim in dims]
            self.base = mi.UInt32(PRIMES[(dims[-1] + 1) % len(PRIMES)])
            # float32(1/b), correctly rounded, as refined_reciprocal gives below
            return [(float(b), float(np.float32(1.0 / b))) for b in bases], max(n_digits(self.spp, b) for b in bases)
        out, base = [], self.base
        for dim in dims:
            b = to_float(base)
            out.append((b, refined_reciprocal(b, dr.rcp(b))))
            base = self._next_base(base, dim)
        self.base = base
        return out, None

    def _radical_inverses(self, dims):
        """Randomised radical inverses of the sample index for the dimensions ``dims``.

        The coordinates of one request share one digit loop of max K_b trips.
        Permuting zero digits past a coordinate's own K_b is harmless: it is
        the same nested scramble carried one digit further before the
        uniform tail, so no coordinate needs a mask.
        """
        owen = self.randomization == "owen"
        bases, trips = self._bases(dims)
        coords = [digit_constants(b, inv) for b, inv in bases]

        def digit_step(c, rest, h, value, scale):
            """Digit k of ``rest`` permuted by d -> (a d + c) mod b; (a, c) from the hash h
            of the prefix (owen) or of the level (permute_digits). Float arithmetic on
            integers < 2^24 (exact); floor((n + 1/2) / b) cannot round across an
            integer for n < 2^21, b <= 311 (the margin 1/(2b) beats the rounding)."""
            base, inv_base, half_inv, u_scale, base_minus_1 = coords[c]
            q = dr.floor(dr.fma(rest, inv_base, half_inv))
            digit = dr.fma(-q, base, rest)
            u = to_float(h >> 9) * u_scale
            c_shift = dr.floor(u)
            a = dr.floor(dr.fma(u - c_shift, base_minus_1, 1.0))
            t = dr.fma(a, digit, c_shift)
            permuted = dr.fma(-dr.floor(dr.fma(t, inv_base, half_inv)), base, t)
            scale = scale * inv_base
            value = dr.fma(permuted, scale, value)
            h = mix32(h ^ mi.UInt32(mi.Int32(digit))) if owen else mix32(h + 0x9E3779B9)
            return q, h, value, scale

        index = to_float(self.sample_index)
        state = [(index, sample_key(self.pixel_key, dim, self.pass_index), mi.Float(0), mi.Float(1))
                 for dim in dims]
        if self.spp > 1:   # K_b >= 1 once spp >= 2
            state = [digit_step(c, *st) for c, st in enumerate(state)]

        if trips is not None:
            # The loop's trip count, max K_b over the request, unrolled: same numbers.
            for _ in range(trips - 1):
                state = [digit_step(c, *st) for c, st in enumerate(state)]
        elif self.spp > 2:   # K_b > 1 happens for base 2 at spp >= 3 only
            # max K_b is K of the smallest base; with b_min^k carried (k digits done) the
            # loop runs while b_min^k < spp. Float products are exact below 2^24, and the
            # last one, at least spp, cannot round below it.
            b_min = bases[0][0] if len(bases) == 1 else dr.minimum(bases[0][0], bases[1][0])
            spp = float(self.spp)

            def body(reach, *flat):
                out = []
                for c in range(len(dims)):
                    out += digit_step(c, *flat[4 * c: 4 * c + 4])
                return (reach * b_min, *out)

            flat = [v for st in state for v in st]
            out = dr.while_loop((b_min, *flat), lambda reach, *_: reach < spp, body,
                                label="lab_halton_digits")
            state = [out[1 + 4 * c: 5 + 4 * c] for c in range(len(dims))]

        values = []
        for _, h, value, scale in state:
            # h has been mixed after the last digit and not used since: a fresh
            # hash of (pixel, dimension[, index]) for the uniform tail.
            values.append(dr.minimum(dr.fma(to_unit_float(h), scale, value), ONE_MINUS_EPS))
        return values

    def _sample_1d(self, dim):
        return self._radical_inverses([dim])[0]

    def _sample_2d(self, dim):
        return mi.Point2f(*self._radical_inverses([dim, dim + 1]))


mi.register_sampler("lab_halton", lambda props: LabHaltonSampler(props))
