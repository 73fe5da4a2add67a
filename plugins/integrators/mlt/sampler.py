"""The sampler through which the path loop reads a chain's primary sample."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .chain import PrimarySamples


class PrimarySampleSampler(mi.Sampler):
    """An ``mi.Sampler`` whose numbers are one primary sample per lane (``chain.PrimarySamples``),
    handed out in the order they are asked for: ``next_1d`` dimension d, ``next_2d`` d and d + 1,
    d counted per lane in ``dim``. ``dim`` is a Dr.Jit array, so the path loop carries it as loop
    state (as every lab sampler's counter, ``samplers/common.py``); the primary samples are not
    (see ``PrimarySamples``). After a path, ``dim`` is how many numbers it read. Never registered:
    lab_pssmlt builds one per evaluation, and it cannot be cloned or seeded."""

    def __init__(self, samples: PrimarySamples):
        super().__init__(mi.Properties())
        self._samples = samples
        self.dim = dr.zeros(mi.UInt32, samples.lanes)

    def next_1d(self, active=True):
        value = self._samples.get(self.dim, active)
        self.dim = self.dim + 1
        return value

    def next_2d(self, active=True):
        value = mi.Point2f(self._samples.get(self.dim, active), self._samples.get(self.dim + 1, active))
        self.dim = self.dim + 2
        return value

    def seed(self, seed, wavefront_size=2 ** 32 - 1):
        raise RuntimeError("lab_pssmlt's primary-sample sampler is not seeded: its numbers are a chain's state")

    def clone(self):
        raise RuntimeError("lab_pssmlt's primary-sample sampler cannot be cloned")

    def fork(self):
        raise RuntimeError("lab_pssmlt's primary-sample sampler cannot be forked")
