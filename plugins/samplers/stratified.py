"""``lab_stratified``: jittered strata per dimension pair, padded by permutation."""
from __future__ import annotations

import math

import mitsuba as mi

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.samplers.common import (
    SALT_JITTER, SALT_PERMUTE, LabSampler, hash2, hash3, padded_index, pixel_seeds, to_unit_float)


class LabStratifiedSampler(LabSampler):
    r"""Stratified (jittered) sampler (:monosp:`lab_stratified`)

    A 1D request splits [0,1) into ``spp`` strata; a 2D request splits the
    square into a grid of ``nx x ny`` cells. Sample i of a pixel goes to cell
    ``pi(i)``, where ``pi`` is a random permutation drawn independently per
    (pixel, dimension) (Kensler 2013, ``mi.permute_kensler``): "padding", so
    different dimension pairs are not correlated. Inside its cell the sample
    is uniform (jitter, from a hash of pixel, dimension and sample).

    =============== ====== =====================================================
    sample_count    int    Samples per pixel, >= 1 (Default: 4)
    jitter          bool   Uniform offset inside each cell; false puts every
                           sample at its cell centre (biased, for study)
                           (Default: true)
    seed            int    Base seed, added to the render seed (Default: 0)
    =============== ====== =====================================================

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
        self.pixel_seed = mi.UInt32(0)
        self.sample_index = mi.UInt32(0)
        self.nx = self.ny = 1

    def _seed_state(self, seed_value, wavefront_size, spp):
        pixel, sample = self.wavefront_layout(wavefront_size, spp)
        self.pixel_seed = pixel_seeds(seed_value, pixel)
        self.sample_index = sample
        self.nx = max(1, math.isqrt(spp))
        self.ny = -(-spp // self.nx)

    def _offsets(self, key):
        if not self.jitter:
            return mi.Float(0.5), mi.Float(0.5)
        u, v = mi.sample_tea_32(hash2(key, SALT_JITTER), self.sample_index)
        return to_unit_float(u), to_unit_float(v)

    def _sample_1d(self, dim):
        key = hash3(self.pixel_seed, dim, self.pass_index)
        cell = padded_index(self.sample_index, self.spp, hash2(key, SALT_PERMUTE))
        u, _ = self._offsets(key)
        return (mi.Float(cell) + u) * (1.0 / self.spp)

    def _sample_2d(self, dim):
        key = hash3(self.pixel_seed, dim, self.pass_index)
        n_cells = self.nx * self.ny
        cell = padded_index(self.sample_index, n_cells, hash2(key, SALT_PERMUTE))
        u, v = self._offsets(key)
        cx, cy = cell % self.nx, cell // self.nx
        return mi.Point2f((mi.Float(cx) + u) * (1.0 / self.nx), (mi.Float(cy) + v) * (1.0 / self.ny))


mi.register_sampler("lab_stratified", lambda props: LabStratifiedSampler(props))
