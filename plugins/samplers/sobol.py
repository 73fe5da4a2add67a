"""``lab_sobol``: padded, Owen-scrambled Sobol points per pixel."""
from __future__ import annotations

import mitsuba as mi

from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.samplers.common import (
    PERMUTE, SCRAMBLE_X, SCRAMBLE_Y, Base2PairSampler, log2_ceil, padded_index, sample_key,
    sobol_02_owen, unit_key)


@documented("lab_sobol")
class LabSobolSampler(Base2PairSampler):
    r"""Padded Owen-scrambled Sobol sampler (:monosp:`lab_sobol`)

    Each pixel draws its ``sample_count`` samples from the first two
    dimensions of the Sobol sequence, the (0,2)-sequence, for *every*
    dimension pair the integrator asks for ("padding", as pbrt-v4's
    ``PaddedSobolSampler``):

    * the sample index is shuffled by a random permutation of 0..spp-1 drawn
      per (pixel, dimension pair) (Kensler 2013, ``common.padded_index``), so
      different pairs are decorrelated;
    * each coordinate gets nested uniform (Owen) scrambling by hashing, with
      its own seed per (pixel, dimension, axis) (Burley 2020, "Practical
      Hash-based Owen Scrambling"; Laine & Karras 2011).

    Only the first two Sobol dimensions are used, so no direction-number table
    is needed; each pair is a (0,m,2)-net, and there is no joint stratification
    across pairs (which a full high-dimensional Sobol sequence would give).
    A ``sample_count`` that is a power of two makes every pair a full (0,m,2)-net;
    any other count gives a prefix of the sequence (still unbiased) and a warning.
    A 1D request uses the first coordinate of a pair. Multi-pass rendering
    (``samples_per_pass``) rescrambles each pass independently.

    .. code-block:: python

        {'type': 'lab_sobol', 'sample_count': 64, 'seed': 0}
    """
    plugin_name = "lab_sobol"
    prefers_power_of_two = True

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.pixel_key = mi.UInt32(0)
        self.sample_index = mi.UInt32(0)
        self.n_bits = 0

    def _seed_state(self, seed_value, wavefront_size, spp):
        pixel, sample = self.wavefront_layout(wavefront_size, spp)
        self.pixel_key = unit_key(seed_value, pixel)
        self.sample_index = sample
        self.n_bits = log2_ceil(spp)

    def _scrambled(self, dim, two_d: bool):
        def key(purpose):
            return sample_key(self.pixel_key, dim, self.pass_index, purpose)
        index = padded_index(self.sample_index, self.spp, key(PERMUTE))
        return sobol_02_owen(index, self.n_bits, key(SCRAMBLE_X), key(SCRAMBLE_Y) if two_d else None)


mi.register_sampler("lab_sobol", lambda props: LabSobolSampler(props))
