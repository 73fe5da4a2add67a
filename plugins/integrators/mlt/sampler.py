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
    lab_pssmlt builds one per evaluation, and it cannot be cloned or seeded.

    ``streams`` > 1 interleaves that many samplers over one primary sample (pbrt-v4's
    ``MLTSampler`` streams): this one reads dimensions ``stream + streams * d``, so a path's
    camera and light numbers keep their places in the state whatever the other side reads
    (lab_mmlt). ``next_float32`` is ``next_1d`` under the name a light subpath's ``mi.PCG32`` has."""

    def __init__(self, samples: PrimarySamples, stream: int = 0, streams: int = 1):
        super().__init__(mi.Properties())
        self._samples = samples
        self._stream, self._streams = stream, streams
        self.dim = dr.zeros(mi.UInt32, samples.lanes)

    def _get(self, dim, active):
        if self._streams == 1:
            return self._samples.get(dim, active)
        return self._samples.get(dim * self._streams + self._stream, active)

    def next_1d(self, active=True):
        value = self._get(self.dim, active)
        self.dim = self.dim + 1
        return value

    def next_float32(self, active=True):
        return self.next_1d(active)

    def next_2d(self, active=True):
        value = mi.Point2f(self._get(self.dim, active), self._get(self.dim + 1, active))
        self.dim = self.dim + 2
        return value

    def dims_read(self):
        """Per lane, one past the highest dimension of the primary sample this stream read (0: none)."""
        if self._streams == 1:
            return self.dim
        return dr.select(self.dim > 0, (self.dim - 1) * self._streams + self._stream + 1, 0)

    def seed(self, seed, wavefront_size=2 ** 32 - 1):
        raise RuntimeError("lab_pssmlt's primary-sample sampler is not seeded: its numbers are a chain's state")

    def clone(self):
        raise RuntimeError("lab_pssmlt's primary-sample sampler cannot be cloned")

    def fork(self):
        raise RuntimeError("lab_pssmlt's primary-sample sampler cannot be forked")
