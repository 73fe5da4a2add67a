"""``lab_stratified``: jittered strata per dimension pair, padded by permutation."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.samplers.common import (
    JITTER_X, JITTER_Y, PERMUTE, LabSampler, padded_index, sample_key, to_unit_float, unit_key)


@documented("lab_stratified")
class LabStratifiedSampler(LabSampler):
    r"""Stratified (jittered) sampler (:monosp:`lab_stratified`)

    A 1D request splits [0,1) into ``spp`` strata; a 2D request splits the
    square into a grid of ``nx x ny`` cells. Sample i of a pixel goes to cell
    ``pi(i)``, where ``pi`` is a random permutation drawn independently per
    (pixel, dimension) (Kensler 2013, ``common.padded_index``): "padding", so
    different dimension pairs are not correlated. Inside its cell the sample
    is uniform (jitter, keyed by the sample's lane and the dimension).

    Off a square number: the 2D grid is ``nx = floor(sqrt(spp))`` by
    ``ny = ceil(spp / nx)`` (``nx * ny >= spp``) and the spp samples of a pixel
    occupy spp distinct cells chosen at random; each sample is still uniform
    (unbiased), the grid is just not full. 1D requests are always fully
    stratified. There is no stratification across dimension pairs.

    .. code-block:: python

        {'type': 'lab_stratified', 'sample_count': 16, 'jitter': True}
    """
    plugin_name = "lab_stratified"
    PARAMETERS = params.LAB_STRATIFIED
    _settings = ("jitter",)

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.jitter = self._values["jitter"]
        self.pixel_key = mi.UInt32(0)
        self.lane_key = mi.UInt32(0)
        self.sample_index = mi.UInt32(0)
        self.nx = self.ny = 1

    def _seed_state(self, seed_value, wavefront_size, spp):
        pixel, sample = self.wavefront_layout(wavefront_size, spp)
        self.pixel_key = unit_key(seed_value, pixel)
        # The jitter is per sample: keyed by the lane (only when there is one).
        self.lane_key = unit_key(seed_value, dr.arange(mi.UInt32, wavefront_size)) if self.jitter else mi.UInt32(0)
        self.sample_index = sample
        self.nx = max(1, math.isqrt(spp))
        self.ny = -(-spp // self.nx)

    def _cell(self, dim, n_cells: int):
        """The stratum of this sample: its index shuffled per (pixel, dimension)."""
        return padded_index(self.sample_index, n_cells, sample_key(self.pixel_key, dim, self.pass_index, PERMUTE))

    def _offset(self, dim, purpose):
        if not self.jitter:
            return mi.Float(0.5)
        return to_unit_float(sample_key(self.lane_key, dim, self.pass_index, purpose))

    def _sample_1d(self, dim):
        cell = self._cell(dim, self.spp)
        return (mi.Float(cell) + self._offset(dim, JITTER_X)) * (1.0 / self.spp)

    def _sample_2d(self, dim):
        cell = self._cell(dim, self.nx * self.ny)
        u, v = self._offset(dim, JITTER_X), self._offset(dim, JITTER_Y)
        cx, cy = cell % self.nx, cell // self.nx
        return mi.Point2f((mi.Float(cx) + u) * (1.0 / self.nx), (mi.Float(cy) + v) * (1.0 / self.ny))


mi.register_sampler("lab_stratified", lambda props: LabStratifiedSampler(props))
