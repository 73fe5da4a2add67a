"""``lab_independent``: PCG32 uniform samples, the baseline Python sampler."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.samplers.common import LabSampler, unit_keys


@documented("lab_independent")
class LabIndependentSampler(LabSampler):
    r"""Independent sampler (:monosp:`lab_independent`)

    Every lane of the wavefront owns a PCG32 generator (O'Neill 2014); each
    ``next_1d`` / ``next_2d`` draws fresh uniform variates. This is Mitsuba's
    ``independent`` written in Python: it measures what a Python sampler costs
    and must render with the same error.

    Seeding: state and stream of lane i are the two words of its unit key
    (``common.unit_keys``: TEA of the render seed and i), exactly as Mitsuba's
    C++ ``PCG32Sampler`` does, so for equal seeds the two produce the same
    numbers. Feeding the lane index as the PCG32 stream directly would be a
    mistake: streams with consecutive increments are correlated, and the
    render's error would be wrong (lower than Mitsuba's independent: a false win).

    Handles any sample count; no stratification of any kind.

    .. code-block:: python

        {'type': 'lab_independent', 'sample_count': 64, 'seed': 0}
    """
    plugin_name = "lab_independent"

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.rng = mi.PCG32()

    def _seed_state(self, seed_value, wavefront_size, spp):
        v0, v1 = unit_keys(seed_value, dr.arange(mi.UInt32, wavefront_size))
        self.rng = mi.PCG32(wavefront_size)
        self.rng.seed(mi.UInt64(v0), mi.UInt64(v1))

    def next_1d(self, active=True):
        return self.rng.next_float32(active)

    def next_2d(self, active=True):
        u = self.rng.next_float32(active)
        v = self.rng.next_float32(active)
        return mi.Point2f(u, v)


mi.register_sampler("lab_independent", lambda props: LabIndependentSampler(props))
