"""What lab_bdpt's driver needs to know of a pass beyond its own parameters: the plan of a
pass, the render's statistics, the pass seeds, and ``Passes``, the settings of a plugin built
on the driver (lab_bdpt's own are the defaults)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import mitsuba as mi

from .weights import BdptWeights


@dataclass
class BdptStats:
    """What the last render did (times in seconds, after dr.eval + dr.sync_thread)."""
    passes: int = 0
    retraces: int = 0
    light_subpaths: int = 0
    light_vertices_reached: int = 0
    light_vertices_stored: int = 0
    peak_vertex_bytes: int = 0
    light_s: float = 0.0
    camera_s: float = 0.0

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class PassPlan:
    """One pass of a render: its ``index``, the samples per pixel before it (``done``) and in it
    (``spp``; with merging, sample k of every pixel is iteration done + k + 1), its light
    subpaths and camera lanes (light and camera lane i belong to sample i mod spp)."""
    index: int
    done: int
    spp: int
    light_subpaths: int
    camera_lanes: int


def pass_seed(seed: int, index: int) -> int:
    """Seed of pass ``index`` (pass 0 keeps the render's seed)."""
    if index == 0:
        return seed & 0xFFFFFFFF
    return int(mi.sample_tea_32(mi.UInt32(seed & 0xFFFFFFFF), mi.UInt32(index))[0][0])


class Passes:
    """How the driver equips each pass, lab_bdpt's way: no merging, every connection, the
    render's seed for the light subpaths. A plugin built on the driver hands it an instance of a
    subclass (``LabBDPTIntegrator.passes``) that overrides what it does otherwise."""
    #: The MIS weights' class; None: ``BdptWeights``.
    weights_class = None
    #: The render's statistics' class (``BdptStats`` or a subclass with more fields).
    stats_class = BdptStats
    #: The first camera depth that merges (``BdptWeights.merge_from``).
    merge_from = 1
    #: Connections' Russian roulette against this share of the lane's estimate so far
    #: (``camera_subpath.connection_roulette``); 0: every connection runs.
    connect_share = 0.0
    #: Each camera vertex connects to one vertex of its light subpath, not to all of them.
    connect_one = False
    #: Merging only with light vertices reached through a delta lobe.
    caustic_merges = False
    #: The light subpaths' own seed; None: the render's.
    light_seed = None

    def spp_limit(self, film_pixels: int, stats) -> int:
        """Most samples per pixel in one pass besides ``max_vertices`` (``stats``: the render's
        so far)."""
        return 1 << 30

    def light_subpaths(self, count: int, spp_pass: int, camera_lanes: int) -> int:
        """The light subpaths a pass of ``spp_pass`` samples per pixel and ``camera_lanes`` camera
        subpaths traces, given the ``count`` that ``light_paths`` and ``max_vertices`` ask for."""
        return count

    def merge_area(self, plan: PassPlan) -> float:
        """pi r^2 N of the pass's merging, 0 without merging."""
        return 0.0

    def equip(self, weights: BdptWeights, plan: PassPlan, connectable_per_path: float) -> BdptWeights:
        """The pass's MIS weights, given the driver's (``connectable_per_path``: stored light
        vertices per light subpath that camera subpaths connect to, from the passes so far)."""
        return weights

    def grid(self, vertices, stored: int, plan: PassPlan, stats):
        """What the camera subpaths merge with; None: no merging."""
        return None
