"""Choosing how lab_vcm renders an image from a pilot (lab_vcm ``pilot``): path tracing alone, or
every technique, and then with how many light subpaths per camera subpath (``light_paths_max``).

Bidirectional techniques pay for themselves only where path tracing struggles: on a diffuse box
or glossy plates their connections and merges cost more than the variance they remove, while
on a caustic light tracing and merging carry the light, and where light tracing carries most of
the image (light seen through glass) more light subpaths per camera subpath pay too.
Efficiency-aware MIS (Grittmann, Yazici, Georgiev & Slusallek 2022) picks techniques from their
measured variance and cost; this is its coarsest form, one choice for the whole image:

* the pilot's size: its counted work (``PilotPlan.seconds``) at most ``pilot_share`` of the whole
  render's, which costs at least spp iterations of path tracing (``share_budget``), so it first
  renders one iteration of path tracing to count its cost, prices every technique's iterations at
  ``EVERY_OVER_PATH_PLAN`` times it until its first render of them has counted their own, and
  renders the most iterations per render up to ``pilot_iterations`` that fit
  (``PilotPlan.iterations``); none at all where ``PILOT_MIN_ITERATIONS`` would not fit (then the
  render is ``pilot.Pilot.fallback``'s choice: every technique at ``light_paths`` where the scene has
  a shape with only delta lobes, path tracing alone elsewhere). The choice rests on ``PILOT_RENDERS`` independent
  renders of each kind of at least ``PILOT_MIN_ITERATIONS`` iterations (16 or more independent
  iterations of each, spread over every pixel of the image);
* the pilot renders the scene ``PILOT_RENDERS`` times with every technique at ``light_paths`` and
  as many times with path tracing alone (lab_mis, the estimator of lab_vcm's mode pt in a
  lighter kernel), the iterations each that its size allows, render i of both with the same seed;
  with ``light_paths_max``, one more with every technique that shares the camera seed of its
  first but not its light seed; and one of path tracing with ``PATH_TRACING_SIZE`` times
  the iterations and a seed of its own;
* per pixel, in relMSE's units (1 / (mean^2 + 0.01)), one iteration's relative variance with
  every technique is its renders' spread, and its camera-side part (what more light subpaths
  cannot lower; the rest falls as 1 / light subpaths) the covariance of the two renders sharing
  a camera seed. Path tracing's is its renders' mean squared deviation from every technique's
  mean (or, if higher, the longer render's, less that mean's variance, over
  ``PATH_TRACING_SIZE``: a short pilot of path tracing often misses the rare paths that dominate
  its error, but the longer render's pixel samples are not every technique's), so light that path tracing's pilot
  misses (a caustic, a light behind glass) counts as error, not as a small variance, while in
  the renders with shared seeds light both sample alike counts for neither (a pilot's own spread
  underestimates a heavy tail);
* cost per iteration (``PilotCosts``), with ``pilot_costs = counted`` (the default) the work the
  pilot renders counted, by kind (``WORK_COSTS``: rays, connections, merge lookups, stored light
  vertices, passes), times the ``cost_*`` parameters (nanoseconds per unit, fitted once by
  ``benchmarks/bench_pilot_costs.py``), so the choice is a function of the scene, the settings,
  the seed and the variant alone; with ``measured``, from the pilot's times at two sizes (one
  render of every technique with one iteration, one of path tracing with ``PATH_TRACING_SIZE``
  times as many), so it also depends on the machine's load. Either way the light pass and
  grid grow with the light subpaths, the camera pass (which merges) as their square root
  (``bench_vcm.py``: 3.9x and 4.0x from 1 to 16 light subpaths on light_in_glass and the
  Cornell box), and a pass's fixed cost is shared by fewer iterations;
* the render is the choice with the lowest image-mean relative variance x time per iteration
  (path tracing's must be lower by ``PATH_TRACING_MARGIN``).

Whichever is chosen renders one of lab_vcm's estimators unchanged, unbiased or consistent as that
one is. Path tracing's pilot renders (and its one-iteration count) are the same estimator as the
render when it is chosen, so their iterations are averaged in; every technique's, whose merging radius restarts at r_1, are
not used in the image.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Pilot renders of each kind (their spread gives the variance).
PILOT_RENDERS = 4
#: The pilot's iterations per render: the render's samples per pixel over PILOT_FRACTION, at least
#: PILOT_MIN_ITERATIONS (one iteration's spread is too heavy-tailed to choose on: sds at 100
#: iterations chose path tracing for 2 seeds of 3 with pilots of 1, none of 5 with pilots of 4).
PILOT_FRACTION = 128
PILOT_MIN_ITERATIONS = 4
#: Path tracing's cost per iteration: from its pilot renders and one of this many times their
#: iterations (a few of its iterations take about as long as the timer's noise).
PATH_TRACING_SIZE = 4
#: Path tracing is chosen when its relative variance x time is below this share of every
#: technique's: its pilot's error is heavy-tailed (low when the pilot misses the rare paths that
#: dominate it), and choosing it where it is poor costs far more than the converse
#: (``tests/plugins/test_vcm_choices.py`` checks the choices this gives on four scenes).
PATH_TRACING_MARGIN = 0.8
#: Most light subpaths per camera subpath lab_vcm traces (``params.LAB_VCM``'s light_paths).
MOST_LIGHT_PATHS = 64.0
#: The parameter that prices each kind of counted work (``pilot_costs = counted``), per part of an
#: iteration: every technique's light passes and grids (lab_bdpt's ``work_counts()``, light
#: side), its camera passes (camera side), and path tracing's (lab_mis's ``ray_counts()``).
WORK_COSTS = {
    "light": {"light": "cost_light_ray", "sensor": "cost_sensor_ray", "light_vertices": "cost_light_vertex"},
    "camera": {"camera": "cost_camera_ray", "extension": "cost_extension_ray", "shadow": "cost_shadow_ray",
               "connection": "cost_connection", "merge": "cost_merge"},
    "path_tracing": {"camera": "cost_path_ray", "extension": "cost_path_ray", "shadow": "cost_path_shadow_ray"},
}


#: Every technique's counted cost per iteration over path tracing's that the pilot assumes when it
#: sizes itself before it has rendered every technique (measured: 10.4-10.8 on the Cornell box,
#: 2.6-2.7 on the caustic, 16x16 to 64x64): the pilot plans as if every technique cost this many
#: times path tracing, then checks its plan against every technique's own counts after its first
#: render and stops there (choosing every technique) if the rest would pass its share.
EVERY_OVER_PATH_PLAN = 16.0


def pilot_iterations(spp: int) -> int:
    """Iterations of each of every technique's pilot renders for a render of ``spp`` samples per
    pixel without a share bound (``pilot_share = 1``): spp / PILOT_FRACTION, at least
    PILOT_MIN_ITERATIONS."""
    return max(PILOT_MIN_ITERATIONS, spp // PILOT_FRACTION)


@dataclass(frozen=True)
class PilotPlan:
    """The pilot's renders: ``every`` of every technique (the independent ones and, choosing light
    subpaths, the one sharing a camera seed), ``path`` of path tracing with their seeds, and one
    of path tracing with ``PATH_TRACING_SIZE`` x ``iterations``; ``extra_every``: every
    technique's one-iteration renders that ``pilot_costs = measured`` times."""
    every: int
    path: int
    extra_every: int = 0

    def seconds(self, iterations: int, every: float, path: float, per_pass: float, pass_iterations: float) -> float:
        """Counted seconds of the pilot at ``iterations`` per render, ``every`` and ``path`` its
        techniques' seconds per iteration, ``per_pass`` a pass's."""
        passes = self.every * math.ceil(iterations / max(pass_iterations, 1.0)) + self.extra_every
        return (passes * per_pass + (self.every * iterations + self.extra_every) * every
                + (self.path + PATH_TRACING_SIZE) * iterations * path)

    def iterations(self, spp: int, budget: float, every: float, path: float, per_pass: float,
                   pass_iterations: float) -> int:
        """The most iterations per render, PILOT_MIN_ITERATIONS to ``pilot_iterations(spp)``, whose
        pilot costs at most ``budget`` counted seconds; 0 if even the fewest cost more."""
        best = 0
        for k in range(PILOT_MIN_ITERATIONS, pilot_iterations(spp) + 1):
            if self.seconds(k, every, path, per_pass, pass_iterations) > budget:
                break
            best = k
        return best


def share_budget(share: float, render: float) -> float:
    """The pilot's counted seconds when it is at most ``share`` of pilot + render and the render
    costs at least ``render``: share / (1 - share) x render (any cost at share 1)."""
    return math.inf if share >= 1.0 else share / (1.0 - share) * render


def light_path_ratios(light_paths: float, light_paths_max: float) -> list[float]:
    """The light subpath counts the pilot may choose, as multiples of ``light_paths``: powers of
    two up to ``light_paths_max`` (0: light_paths alone)."""
    ratios = [1.0]
    while light_paths * ratios[-1] * 2 <= min(light_paths_max, MOST_LIGHT_PATHS) * (1 + 1e-9):
        ratios.append(ratios[-1] * 2)
    return ratios


@dataclass(frozen=True)
class PilotVariances:
    """Image means of one iteration's relative variance (relMSE's units)."""
    every: float          # every technique at light_paths
    camera_side: float    # the part of ``every`` that the camera subpaths alone give
    path_tracing: float   # path tracing's error (its variance and the light it misses)

    def every_at(self, ratio: float) -> float:
        """Every technique's with ``ratio`` x light_paths light subpaths per camera subpath."""
        return self.camera_side + (self.every - self.camera_side) / ratio


def pilot_variances(every: np.ndarray, shared: np.ndarray | None, camera: np.ndarray, iterations: int,
                    longer: np.ndarray | None = None, longer_iterations: int = 0) -> PilotVariances:
    """``every``: every technique's renders (renders, h, w, channels), independent, each the mean
    of ``iterations`` iterations; ``shared``: one more (shape (1, h, w, channels)) with the camera
    seed of ``every[0]`` and a light seed of its own (None: no camera share, all of the variance
    counts as the camera side's); ``camera``: path tracing's renders, with ``every``'s seeds (the same
    pixel samples: light both see alike, such as a small emitter within a pixel, counts for
    neither); ``longer``: one more of path tracing's, of ``longer_iterations``, with a seed of its
    own (its deviation less the variance of every technique's mean). Path tracing's error is the
    renders' with shared seeds or, if higher, the longer one's over PATH_TRACING_SIZE. Per-pixel estimates summed over channels, then
    averaged over the image (a pixel's may be negative; the mean is what the choice needs)."""
    mean = every.mean(axis=0)
    scale = 1.0 / (mean * mean + 0.01)

    def image(per_pixel, n) -> float:
        return float(np.mean((per_pixel * scale).sum(axis=-1))) * n

    spread = every.var(axis=0, ddof=1)
    total = image(spread, iterations)
    # every[0] - every[1] and shared[0] - every[2] share only every[0]'s camera seed: the mean of
    # their product is the variance that seed alone gives
    camera_side = total if shared is None else image((every[0] - every[1]) * (shared[0] - every[2]), iterations)
    path_tracing = image(((camera - mean) ** 2).mean(axis=0), iterations)
    if longer is not None:
        # its own pixel samples: it also finds what every technique's renders had no sample for
        # (a light within a pixel), so it counts at 1 / PATH_TRACING_SIZE, enough to catch the
        # rare paths that dominate path tracing's error where a short pilot misses them
        deviation = image((longer - mean) ** 2 - spread / len(every), longer_iterations)
        path_tracing = max(path_tracing, deviation / PATH_TRACING_SIZE)
    return PilotVariances(max(total, 0.0), min(max(camera_side, 0.0), max(total, 0.0)), max(path_tracing, 0.0))


def seconds(counts: dict, part: str, costs: dict) -> float:
    """Counted seconds of ``counts`` (work by kind) in ``part`` of ``WORK_COSTS``, at ``costs``
    (lab_vcm's ``cost_*`` parameters, nanoseconds per unit)."""
    return 1e-9 * sum(counts.get(kind, 0) * costs[name] for kind, name in WORK_COSTS[part].items())


def every_seconds(counts: dict, costs: dict) -> float:
    """Counted seconds of every technique's work ``counts`` (``work_counts()``), passes included."""
    return (seconds(counts, "light", costs) + seconds(counts, "camera", costs)
            + 1e-9 * costs["cost_pass"] * counts.get("passes", 0))


@dataclass(frozen=True)
class PilotCosts:
    """Seconds per iteration: every technique's camera pass (with its merges) and light pass +
    grid at light_paths, a pass's fixed cost and its iterations there, path tracing's."""
    camera: float
    light: float
    per_pass: float
    pass_iterations: float
    path_tracing: float

    @staticmethod
    def from_sizes(small: tuple[float, float], large: tuple[float, float], iterations: int,
                   pass_iterations: float, path_tracing: tuple[float, float], path_small: int, path_large: int):
        """From every technique's pass times (light + grid, camera) in renders of one and of
        ``iterations`` iterations and path tracing's render times at ``path_small`` and
        ``path_large`` iterations: an iteration's cost is the difference over the extra
        iterations, a pass's own cost the rest."""
        n = max(iterations - 1, 1)
        if sum(large) <= sum(small):        # (a clock hiccup: each render's own cost unknown)
            return PilotCosts(large[1] / iterations, large[0] / iterations, 0.0, pass_iterations,
                              path_tracing[1] / path_large)
        light = max(large[0] - small[0], 0.0) / n
        camera = max(large[1] - small[1], 0.0) / n
        per_pass = max(small[0] + small[1] - light - camera, 0.0)
        path = max(path_tracing[1] - path_tracing[0], 0.0) / max(path_large - path_small, 1)
        return PilotCosts(camera, light, per_pass, pass_iterations, path)

    @staticmethod
    def from_counts(every: dict, iterations: int, pass_iterations: float, path_tracing: dict, path_iterations: int,
                    costs: dict):
        """From counted work (``pilot_costs = counted``): ``every``, every technique's counts over
        renders of ``iterations`` iterations in all, ``path_tracing``, path tracing's over
        ``path_iterations``; ``costs``, lab_vcm's parameters (``WORK_COSTS``: nanoseconds per
        unit; ``cost_pass`` per pass). No clock is read: the same counts, the same costs."""
        return PilotCosts(seconds(every, "camera", costs) / iterations, seconds(every, "light", costs) / iterations,
                          1e-9 * costs["cost_pass"], pass_iterations,
                          seconds(path_tracing, "path_tracing", costs) / path_iterations)

    def every_at(self, ratio: float) -> float:
        """Every technique's with ``ratio`` x light_paths (passes hold 1 / ratio the iterations)."""
        return (self.camera * math.sqrt(ratio) + self.light * ratio
                + self.per_pass / max(1.0, self.pass_iterations / ratio))


def choose(variances: PilotVariances, costs: PilotCosts, ratios: list[float]):
    """(the chosen multiple of light_paths, or None for path tracing alone; the relative
    variance x time per iteration of each choice, path tracing's under None). Path tracing must
    win by PATH_TRACING_MARGIN."""
    scores = {r: variances.every_at(r) * costs.every_at(r) for r in ratios}
    best = min(scores, key=lambda r: scores[r])
    scores[None] = variances.path_tracing * costs.path_tracing
    return (None if scores[None] < PATH_TRACING_MARGIN * scores[best] else best), scores
