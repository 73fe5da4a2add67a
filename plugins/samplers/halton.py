"""``lab_halton``: randomised Halton points per pixel."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.samplers.common import (
    ONE_MINUS_EPS, SALT_JITTER, LabSampler, check_choice, hash2, hash3, log2_ceil,
    mix32, pixel_seeds, to_unit_float)

RANDOMIZATIONS = ("permute_digits", "owen")


def first_primes(n: int) -> list[int]:
    primes, k = [], 2
    while len(primes) < n:
        if all(k % p for p in primes if p * p <= k):
            primes.append(k)
        k += 1
    return primes


#: Bases of the supported dimensions; dimension d uses PRIMES[d mod 64].
PRIMES = first_primes(64)


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
      scramble in base b.

    =============== ====== =====================================================
    sample_count    int    Samples per pixel, >= 1 (Default: 4)
    randomization   string ``permute_digits`` | ``owen`` (Default: ``owen``)
    seed            int    Base seed, added to the render seed (Default: 0)
    =============== ====== =====================================================

    Digits past the ceil(log2 spp) that the sample index can fill are
    replaced by a uniform offset below the last digit (per pixel and
    dimension for ``permute_digits``, per sample for ``owen``), which is what
    permuting infinitely many zero digits amounts to. Each pixel uses the
    first spp points of the sequence, so any sample count is fine. The base
    of a dimension is looked up at run time (the dimension index is a loop
    variable), so the kernel does integer divisions by a variable base.

    .. code-block:: python

        {'type': 'lab_halton', 'sample_count': 64, 'randomization': 'owen'}
    """
    plugin_name = "lab_halton"
    _settings = ("randomization",)

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.randomization = check_choice(self.plugin_name, "randomization",
                                          str(props.get("randomization", "owen")), RANDOMIZATIONS)
        self.pixel_seed = mi.UInt32(0)
        self.sample_index = mi.UInt32(0)
        self.primes = mi.UInt32(PRIMES)
        self.n_digits = 1

    def _seed_state(self, seed_value, wavefront_size, spp):
        pixel, sample = self.wavefront_layout(wavefront_size, spp)
        self.pixel_seed = pixel_seeds(seed_value, pixel)
        self.sample_index = sample
        self.primes = mi.UInt32(PRIMES)
        self.n_digits = max(1, log2_ceil(spp))

    def _radical_inverse(self, dim):
        """Randomised radical inverse of the sample index for dimension ``dim``."""
        owen = self.randomization == "owen"
        key = hash3(self.pixel_seed, dim, self.pass_index)
        # max(., 2): lanes past the end of a packet gather 0, and an integer
        # division by 0 in such a lane raises SIGFPE on the LLVM backend.
        base = dr.maximum(dr.gather(mi.UInt32, self.primes, dim % len(PRIMES)), 2)
        inv_base = dr.rcp(mi.Float(base))
        rest = mi.UInt32(self.sample_index)
        prefix = mi.UInt32(0)   # i mod b^k: the digits already placed (owen only)
        scale = mi.UInt32(1)
        value = mi.Float(0)
        weight = mi.Float(inv_base)
        for k in range(self.n_digits):
            digit = rest % base
            rest = rest // base
            digit_key = key ^ ((0x9E3779B9 * (k + 1)) & 0xFFFFFFFF)
            h = hash2(digit_key, prefix) if owen else mix32(digit_key)
            a = 1 + (h & 0xFFFF) % (base - 1)
            c = (h >> 16) % base
            value = dr.fma(mi.Float((a * digit + c) % base), weight, value)
            weight *= inv_base
            if owen:
                prefix += digit * scale
                scale *= base
        tail_key = hash3(key, SALT_JITTER, self.sample_index) if owen else hash2(key, SALT_JITTER)
        value = dr.fma(to_unit_float(tail_key), weight * mi.Float(base), value)
        return dr.minimum(value, ONE_MINUS_EPS)

    def _sample_1d(self, dim):
        return self._radical_inverse(dim)

    def _sample_2d(self, dim):
        return mi.Point2f(self._radical_inverse(dim), self._radical_inverse(dim + 1))


mi.register_sampler("lab_halton", lambda props: LabHaltonSampler(props))
