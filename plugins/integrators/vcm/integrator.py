"""``lab_vcm``: the plugin (lab_bdpt's passes, one sample per pass, with merging and its radius)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.integrators.bdpt.integrator import LabBDPTIntegrator
from mitsuba_lab.plugins.integrators.bdpt.passes import BdptStats, Passes
from mitsuba_lab.plugins.integrators.bdpt.techniques import Technique
from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights, iteration_sizes
from mitsuba_lab.plugins.integrators.common.aim import AimedEmission
from mitsuba_lab.plugins.integrators.common.density_radius import first_radius

from .estimator import VertexMerging, merges_first
from .merging import VertexGrid, table
from .pilot import Pilot
from .volume_merging import MediumGrid, volume_radius


def vcm_radius(r1: float, iteration: int, alpha: float) -> float:
    """r_i = r_1 i^((alpha - 1) / 2), i = 1, 2, ..: the merging area pi r_i^2 shrinks as
    i^(alpha - 1), so the bias vanishes while the merges per iteration grow without bound
    (Georgiev et al. 2012, sec. 5; Knaus & Zwicker 2011)."""
    return r1 * iteration ** ((alpha - 1.0) / 2.0)


#: Pass sizes when merging. Each pass traces its light subpaths, stores and buckets their
#: vertices, then merges; several iterations in one pass share its per-pass overhead (Python,
#: kernel launches, about 10 ms), but a grid larger than the caches makes merging slower. So
#: a pass holds about PASS_LIGHT_VERTICES stored vertices, measured by the render's first pass
#: (of FIRST_PASS_LIGHT_SUBPATHS subpaths), within [MIN, MAX]_PASS_LIGHT_SUBPATHS subpaths
#: (``benchmarks/bench_vcm.py`` compares the pass sizes). Below one light subpath per camera
#: subpath, a pass holds at most MAX_PASS_CAMERA_LANES camera subpaths: they keep no state
#: between vertices in memory, so a longer wavefront only saves passes (``benchmarks/bench_vcm.py
#: --light-paths 0.0625`` measures it: fewer, longer passes).
PASS_LIGHT_VERTICES = 1 << 20
FIRST_PASS_LIGHT_SUBPATHS = 1 << 18
MIN_PASS_LIGHT_SUBPATHS, MAX_PASS_LIGHT_SUBPATHS = 1 << 14, 1 << 18
MAX_PASS_CAMERA_LANES = 1 << 20


class PpmWeights(BdptWeights):
    """ppm's weights: none. A camera subpath merges once, at its first vertex with a smooth lobe,
    and goes on only through delta lobes, so each path has one technique: an emitter hit (along
    a camera prefix of delta lobes) or the merge at that vertex; each has weight 1."""

    def hit(self, camera, pdf_nee, pdf_emit, pdf_pos):
        return self.e[Technique.HIT]

    def merge(self, light, camera, pdf_cam_fwd, pdf_cam_rev, medium=None):
        return self.e[Technique.MERGE]


@dataclass
class VcmStats(BdptStats):
    """lab_bdpt's statistics of the last render, and merging's and the pilot's."""
    grid_s: float = 0.0               # building the light vertices' grids (both, in scenes with media)
    volume_grid_s: float = 0.0        # of it, building the grid of the light vertices in media
    merging_vertices: int = 0         # light vertices in the grids (merge_vertices: all or caustic)
    radius_first: float = 0.0         # the merging radius of the first and last pass
    radius_last: float = 0.0
    medium_merging_vertices: int = 0  # of them, light vertices in media (their own grid; scenes with media)
    radius_volume_first: float = 0.0  # the ball's radius in media, of the first and last pass
    radius_volume_last: float = 0.0
    pilot_s: float = 0.0              # pilot: the pilot's time
    chose_path_tracing: bool = False  # pilot: the pilot chose path tracing alone
    light_paths_chosen: float = 0.0   # pilot: the light subpaths per camera subpath chosen (0: none)
    pilot_scores: dict = field(default_factory=dict)   # pilot: relative variance x s per iteration
    pilot_costs: str = ""             # pilot: how it priced an iteration (counted or measured work)
    pilot_iterations: int = 0         # pilot: iterations per pilot render (0: none, the share too small)
    pilot_counted_s: float = 0.0      # pilot: its counted work (cost_* x counts), seconds
    render_counted_s: float | None = None   # pilot: the render's after it (None: not counted, count_rays off)
    pilot_share: float | None = None  # pilot: pilot_counted_s over pilot + render (None: not counted)


class VcmPasses(Passes):
    """What lab_vcm asks of lab_bdpt's driver (``bdpt.passes.Passes``): its MIS weights, merging
    with each iteration's radius, pass sizes for the grids, and its connection settings, from the
    plugin ``plugin`` (its values and, once ``render`` has set it, ``first_radius``)."""
    stats_class = VcmStats

    def __init__(self, plugin, merging: bool, merge_from: int, connect_share: float, connect_one: bool,
                 caustic_merges: bool, ppm: bool):
        self.plugin, self.merging, self.ppm = plugin, merging, ppm
        self.merge_from, self.connect_share, self.connect_one = merge_from, connect_share, connect_one
        self.caustic_merges = caustic_merges
        #: whether the render's scene has media (merging at medium vertices too; set by ``render``)
        self.media = False
        if ppm:
            self.weights_class = PpmWeights

    def radii(self, plan) -> list[float]:
        """The merging radius of each iteration of a pass (iterations done + 1 .. done + spp)."""
        return [vcm_radius(self.plugin.first_radius, plan.done + k + 1, self.plugin.values["alpha"])
                for k in range(plan.spp)]

    def volume_radii(self, plan) -> list[float]:
        """The ball's radius in media of each iteration of a pass (``volume_merging``)."""
        return [volume_radius(self.plugin.first_volume_radius, plan.done + k + 1, self.plugin.values["alpha"])
                for k in range(plan.spp)]

    def spp_limit(self, film_pixels: int, stats) -> int:
        if not self.merging:
            return super().spp_limit(film_pixels, stats)
        # stored vertices per subpath from this render's own passes (the same seed, the same passes)
        traced = stats.light_subpaths
        per_path = stats.light_vertices_stored / traced if traced else None
        subpaths = FIRST_PASS_LIGHT_SUBPATHS if per_path is None else min(
            MAX_PASS_LIGHT_SUBPATHS, max(MIN_PASS_LIGHT_SUBPATHS, int(PASS_LIGHT_VERTICES / max(per_path, 1e-3))))
        iterations = int(subpaths / (film_pixels * self.plugin.values["light_paths"]))
        return max(1, min(iterations, MAX_PASS_CAMERA_LANES // film_pixels))

    def light_subpaths(self, count: int, spp_pass: int, camera_lanes: int) -> int:
        """Below one light subpath per camera subpath (``light_paths`` < 1), camera lane i uses
        light subpath i mod N; with N a multiple of the pass's iterations K, both lie in the same
        iteration, i mod K (``BdptWeights.lane_iteration``), so a lane connects only to light
        vertices of its own iteration, whose radius and N_k its weights carry."""
        if not self.merging or spp_pass == 1 or count >= camera_lanes:
            return count
        return spp_pass * max(1, count // spp_pass)

    @staticmethod
    def iteration_light_subpaths(plan) -> list[int]:
        """N_k, the light subpaths of each iteration of a pass (at least 1: an iteration without
        any has no camera lanes either, as camera lane i pairs with light subpath i)."""
        return [max(n, 1) for n in iteration_sizes(plan.light_subpaths, plan.spp)]

    def equip(self, weights, plan, connectable_per_path: float):
        if self.connect_one:
            # a connection technique is sampled about once per L stored light vertices (L: their mean
            # per light subpath, from the passes so far); opaque, as it changes from pass to pass
            count = min(1.0, 1.0 / max(connectable_per_path, 1.0))
            weights.connect_weight = dr.opaque(mi.Float, weights._m(count))
        if self.merging:
            # merging in iteration k: density pi r_k^2 N_k, N_k = the iteration's light subpaths
            sizes = self.iteration_light_subpaths(plan)
            etas = [weights._m(math.pi * r * r * n) for r, n in zip(self.radii(plan), sizes)]
            iterations = mi.UInt32(plan.spp)
            dr.make_opaque(iterations)
            weights.lane_tables = (table(etas), table([1.0 / e for e in etas]), iterations)
            if self.media:
                # at medium vertices: the ball's volume, 4/3 pi r_k^3 N_k
                weights.volume_table = table([weights._m(4.0 / 3.0 * math.pi * r ** 3 * n)
                                              for r, n in zip(self.volume_radii(plan), sizes)])
        return weights

    def merge_area(self, plan) -> float:
        return math.pi * self.plugin.first_radius ** 2 * plan.light_subpaths / plan.spp if self.merging else 0.0

    def grid(self, vertices, stored: int, plan, stats):
        if not self.merging:
            return None
        radii = self.radii(plan)
        start = time.perf_counter()
        sizes, kernel = self.iteration_light_subpaths(plan), self.plugin.values["kernel"]
        grid = VertexGrid(vertices, stored, radii, sizes, kernel)
        grid.first_only = self.ppm
        dr.eval(grid.buckets, grid.order, grid.points, grid.records)
        if vertices.media:
            dr.sync_thread()
            volume_start = time.perf_counter()
            volume_radii = self.volume_radii(plan)
            grid.volume = MediumGrid(vertices, stored, volume_radii, sizes, kernel)
            dr.eval(grid.volume.buckets, grid.volume.order, grid.volume.points, grid.volume.records)
            dr.sync_thread()
            stats.volume_grid_s += time.perf_counter() - volume_start
            stats.merging_vertices += grid.volume.count
            stats.medium_merging_vertices += grid.volume.count
            if plan.index == 0:
                stats.radius_volume_first = volume_radii[0]
            stats.radius_volume_last = volume_radii[-1]
        dr.sync_thread()
        stats.grid_s += time.perf_counter() - start
        stats.merging_vertices += grid.count
        if plan.index == 0:
            stats.radius_first = radii[0]
        stats.radius_last = radii[-1]
        return grid


@documented("lab_vcm")
class LabVCMIntegrator(LabBDPTIntegrator):
    r"""Vertex connection and merging (:monosp:`lab_vcm`)

    Each iteration (one sample per pixel) traces one light subpath per pixel (``light_paths``)
    and stores its vertices, builds a hashed grid over them, then traces one camera subpath per pixel sample.
    At each camera vertex every technique of ``lab_bdpt`` runs (emitter hit, next-event
    estimation, connections to the lane's light subpath, light tracing from the light side),
    plus *merging* (from the camera's second vertex on, unless ``merge_first``): a density
    estimate from the light vertices of all light subpaths within radius r_i (``kernel``). One
    MIS, balance or power heuristic, weights
    them all, merging counted as a technique of density pi r_i^2 N_light (Georgiev, Krivanek,
    Davidovic & Slusallek 2012; Hachisuka, Pantaleoni & Jensen 2012). Caustics come from
    merging as in photon mapping, diffuse light from connections as in BDPT, in one image.

    **Biased, consistent.** Merging blurs the light over a disc of radius r_i; with
    r_i = r_1 i^((alpha - 1) / 2) the bias vanishes as the iterations grow, and for finite
    iterations the image is biased wherever merging has weight (``bpt``, ``lt`` and ``pt``
    do not merge and are unbiased).

    A light vertex merges with a camera vertex when within r_i, facing the same way (normals
    within ~37 degrees, as lab_photon) and when the merged path is no longer than
    ``max_depth``. Where light tracing or connections compete with merging, a camera vertex's
    merges run under a Russian roulette: their weights cannot exceed a bound b known before any
    light vertex is read, so they run with probability min(1, 2b) and count 1 / it (unbiased;
    it skips the lookups MIS would mostly discard, as in diffuse scenes with few light
    vertices). Supports what lab_bdpt supports (projector emitters; orthographic sensors, where
    light tracing cannot reach the sensor: no t = 1 technique there, in any mode or MIS sum,
    and mode ``lt`` renders nothing; RGB, mono and spectral variants; spectral: one iteration
    per pass). Participating media, homogeneous and heterogeneous, in every mode: lab_bdpt's media
    loops, and camera vertices in a medium merge with the light vertices stored in media inside a
    ball of radius r_v,i = r_v,1 i^((alpha - 1) / 3) (``radius_volume``; default the surfaces'
    r_1), counted by the MIS with the ball's volume (``volume_merging.py``; Krivanek et al. 2014's
    point-to-point estimator); ``connections = one`` and ``merge_vertices = caustic`` are refused
    with media in one line. Statistics of the
    last render (``bdpt_stats()``): light, grid and camera time, the radii; with ``pilot`` the
    pilot's time, whether it chose path tracing alone, the light subpaths it chose, each
    choice's score (relative variance x seconds per iteration) and ``pilot_costs``, its iterations
    per render (0: no pilot), its counted seconds and the render's after it (with ``count_rays``)
    and its share of their sum; with counted costs the pilot's counts are in ``pilot.work`` (every
    technique's and path tracing's).

    Modes: ``bpm`` is bidirectional photon mapping (emitter hits and merging at every camera
    vertex that merges, with MIS among them); ``ppm`` is progressive photon mapping (merging at
    the first camera vertex with a smooth lobe, delta lobes followed and emitters seen along
    them, no MIS); ``bpt`` is lab_bdpt's estimator, ``pt`` lab_mis's. ``light_paths`` light
    subpaths per camera subpath are all stored, merged with and splatted; more of them make
    merging's estimate less noisy for the same camera work, and below 1 the camera subpaths of
    an iteration share them (i mod N). MIS counts merging with the disc's area whatever the
    ``kernel``. Without ``merge_first`` the merges at the first vertex are out of every MIS
    sum: they share an iteration's light vertices and add variance that light tracing does
    not (equal or lower error without them on every scene of experiments/vcm.toml).
    ``merge_vertices = caustic`` makes merging at x_i a technique only where x_{i-1} is a
    delta-lobe vertex, in every MIS sum too, so the image stays consistent and scenes without
    caustics skip most merging. ``connections = one`` picks one of the n vertices a camera
    vertex may connect to uniformly and counts it n times (unbiased). The pilot (on by default
    in mode vcm; ``pilot.py``, ``selection.py``) makes a few short renders with every technique
    and with path tracing alone, path tracing's averaged into the image when chosen, which it is
    only when it wins by a margin (``selection.PATH_TRACING_MARGIN``). Its counted work (its
    renders' counts times the ``cost_*`` parameters, fitted by ``benchmarks/bench_pilot_costs.py``)
    is at most ``pilot_share`` of the whole render's: it sizes its renders from path tracing's
    counted cost per iteration (one iteration rendered first; the render costs at least spp of
    them) and, before it has rendered every technique, prices an iteration of it at
    ``selection.EVERY_OVER_PATH_PLAN`` times that, checked against every technique's own counts
    after its first pilot render. Where even its fewest iterations (``selection.PILOT_MIN_ITERATIONS``
    per render: fewer chose wrongly on sds) would pass the share there is no pilot, and the choice
    follows the scene (``Pilot.fallback``): every technique at ``light_paths`` where a shape has only
    delta lobes (glass, mirrors: caustics, light behind glass), path tracing alone elsewhere, with
    what the pilot rendered of path tracing averaged in. On the Cornell box at 64x64 the smallest
    pilot costs the counted work of about 276 iterations of path tracing, so at the default
    share of 1/8 it starts at about 1930 spp (2048 spp: 4 iterations per pilot render, 0.12 of
    the counted work), and at 1024 spp it stops after its first pair of renders (0.005) (``experiments/results/2026-11-28-vcm-pilot.md``); ``pilot_share = 1`` sizes it
    without a bound (max(4, spp / 128) iterations per render). ``aim``'s default depends on the mode: 0.9 in vcm,
    lab_bdpt's 0.5 in bpt and lt, 0 in bpm and ppm, where merging carries the direct light too
    and only the unaimed share of the light subpaths would bring it (a noisier, heavier-tailed
    image away from the aimed shapes, not a biased one); aiming changes nothing where no shape
    is aimed at (experiments/results/2026-11-28-vcm-defaults.md measures the choice).

    .. code-block:: python

        {'type': 'lab_vcm', 'mode': 'vcm', 'max_depth': 8, 'alpha': 0.75}
    """
    ESTIMATOR = VertexMerging
    PARAMETERS = VertexMerging.PARAMETERS
    RAY_KINDS = LabBDPTIntegrator.RAY_KINDS + ("merge",)
    #: In mode vcm, a connection that would add less than this share of its lane's estimate so
    #: far runs with probability (its share / this) (``camera_subpath.connection_roulette``;
    #: connections that add a sliver seldom pay for their shadow ray: the Cornell box 9% faster for
    #: 1% more variance); mode bpt keeps lab_bdpt's image.
    CONNECT_SHARE = 0.1

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.merging = Technique.MERGE in self.techniques
        ppm = self.values["mode"] == "ppm"
        if ppm and "merge_first" in props and not self.values["merge_first"]:
            raise ValueError("lab_vcm: mode 'ppm' merges only at the first smooth camera vertex: "
                             "merge_first = false does not apply to it")
        #: r_1, the first iteration's merging radius (set by ``render``: ``radius``, or automatic), and
        #: the ball's in media (``radius_volume``, or r_1)
        self.first_radius = 0.0
        self.first_volume_radius = 0.0
        #: how the automatic r_1 was made (``density_radius.FirstRadius``; None: ``radius`` given)
        self.radius_probe = None
        #: the pilot's choice and the renders it makes (``pilot.Pilot``)
        self.pilot = Pilot(self)
        if self.values["light_paths_max"] and not self.values["pilot"]:
            raise ValueError("lab_vcm: light_paths_max is the most light subpaths the pilot may choose: it needs "
                             "pilot = true")
        if self.values["light_paths_max"] and self.values["light_paths_max"] < self.values["light_paths"]:
            raise ValueError(f"lab_vcm: light_paths_max = {self.values['light_paths_max']:g} is below light_paths = "
                             f"{self.values['light_paths']:g}: the pilot chooses from light_paths up to it")
        if self.values["pilot"] and self.values["mode"] not in ("vcm", "bpt"):
            raise ValueError(f"lab_vcm: pilot chooses between every technique and path tracing alone, which only "
                             f"modes 'vcm' and 'bpt' have, not mode '{self.values['mode']}'")
        caustic_merges = self.values["merge_vertices"] == "caustic"
        if caustic_merges and self.values["mode"] != "vcm":
            raise ValueError(f"lab_vcm: merge_vertices = 'caustic' leaves the light of paths without a delta lobe "
                             f"before the merge to the other techniques, which only mode 'vcm' has all of, not "
                             f"mode '{self.values['mode']}'")
        if self.values["connections"] == "one" and Technique.CONNECT not in self.techniques:
            raise ValueError(f"lab_vcm: connections = 'one' picks the light vertex a camera vertex connects to; "
                             f"mode '{self.values['mode']}' makes no connections")
        # (no first merge: merging from the camera's second vertex on; ``BdptWeights.merge_from``)
        self.passes = VcmPasses(self, self.merging,
                                merge_from=1 if merges_first(self.values) or not self.merging else 2,
                                connect_share=self.CONNECT_SHARE if self.merging else 0.0,
                                connect_one=self.values["connections"] == "one" and Technique.CONNECT in self.techniques,
                                caustic_merges=caustic_merges, ppm=ppm)
        self.stats = VcmStats()

    def refuse_unsupported(self, scene: mi.Scene):
        traits = super().refuse_unsupported(scene)
        problem = VertexMerging.media_settings_problem(traits, self.values)
        if problem:
            raise ValueError(problem)
        self.passes.media = bool(traits.media)
        return traits

    def render(self, scene: mi.Scene, sensor=0, seed=0, spp: int = 0, develop: bool = True,
               evaluate: bool = True):
        if self._pass is None and self.merging:
            r1 = self.values["radius"]
            if not r1 > 0:
                r1 = self.default_radius(scene, scene.sensors()[sensor] if isinstance(sensor, int) else sensor)
            self.first_radius = r1
            self.first_volume_radius = self.values["radius_volume"] or r1
        if self._pass is None and self.values["pilot"]:
            self.refuse_undeveloped(develop)
            self.refuse_unsupported(scene)         # (the pilot may choose path tracing, which would not)
            return self.pilot.render(scene, sensor, seed, spp, develop, evaluate)
        return super().render(scene, sensor, seed, spp, develop, evaluate)

    def default_radius(self, scene: mi.Scene, sensor: mi.Sensor) -> float:
        """The automatic r_1 (``common.density_radius``): a pixel's width, or more where this
        render's light vertices (light_paths per pixel, aimed as ``aim`` aims them) are sparse."""
        v = self.values
        size = sensor.film().crop_size()
        depth = v["max_depth"] if v["max_depth"] > 0 else 1 << 30
        self.radius_probe = first_radius(scene, sensor, v["light_paths"] * int(size[0]) * int(size[1]), depth - 1,
                                         aim=AimedEmission(scene, v["aim"], v["aim_at"], "lab_vcm"))
        return self.radius_probe.radius

    def render_every(self, scene, sensor, seed, spp, develop=True, evaluate=True):
        """A render with every technique of this one's mode, without the pilot (what the pilot
        renders when it chooses them at this one's light_paths)."""
        return super().render(scene, sensor, seed, spp, develop, evaluate)

    def to_string(self):
        fields = ", ".join(f"{k}={v}" for k, v in self.settings().items())
        return f"LabVCMIntegrator[{fields}]"


mi.register_integrator("lab_vcm", lambda props: LabVCMIntegrator(props))
