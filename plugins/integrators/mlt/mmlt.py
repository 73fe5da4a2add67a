"""``lab_mmlt``: multiplexed Metropolis light transport over lab_bdpt's subpaths and MIS weights."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab.plugins import interrupts
from mitsuba_lab.plugins.integrators.bdpt.camera_subpath import CameraPass, sensor_constants, trace_camera_subpaths
from mitsuba_lab.plugins.integrators.bdpt.endpoints import EmitterTable, direction_is_delta
from mitsuba_lab.plugins.integrators.bdpt.light_subpath import LightTracer
from mitsuba_lab.plugins.integrators.bdpt.techniques import Strategy
from mitsuba_lab.plugins.integrators.bdpt.vertices import LightVertices
from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights
from mitsuba_lab.plugins.integrators.common import spawn, spectral
from mitsuba_lab.plugins.integrators.common.support import render_arguments
from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.scene_traits import SceneTraits
from mitsuba_lab.plugins.variant import plugin_settings

from . import chain
from .estimator import MMLT
from .frozen import FrozenRounds
from .integrator import LabPSSMLTIntegrator, target
from .sampler import PrimarySampleSampler

#: Russian roulette never starts (pbrt-v4's MLTIntegrator has none: the state picks the length).
NO_ROULETTE = 1 << 30
#: Full lock-step rounds recorded once per render and replayed (``frozen.FrozenRounds``): 1.7-2.5x
#: cheaper per mutation at the default chains, the same images (2026-11-29-mlt-speed.md; two sweeps
#: had aborted inside a recording before the garbage collector was kept out of it). False traces
#: every round.
FREEZE_ROUNDS = True
#: The primary sample's streams, interleaved (``PrimarySampleSampler``): the camera's (the
#: strategy, the film position, the camera subpath and its NEE) and the light's.
CAMERA_STREAM, LIGHT_STREAM, STREAMS = 0, 1, 2


def strategy_probability(n_strategies):
    """The probability of one strategy pick among the k + 1 of a length of k segments
    (``n_strategies`` = k + 1, per lane)."""
    return 1.0 / mi.Float(n_strategies)


def per_length_normaliser(values: np.ndarray, lengths: int) -> tuple[list, list]:
    """(b_k, its standard error) per length of a bootstrap laid out length by length, ``lengths``
    equal blocks."""
    per = np.asarray(values, dtype=np.float64).reshape(lengths, -1)
    n = per.shape[1]
    se = per.std(axis=1, ddof=1) / math.sqrt(n) if n > 1 else np.full(lengths, math.inf)
    return per.mean(axis=1).tolist(), se.tolist()


class LaneSplats:
    """Stands in for lab_bdpt's splat block (``splats.splat`` calls ``offset`` and ``put``): keeps
    each lane's light-tracing contribution and film position instead of splatting it. A lane's
    one strategy (s, 1) splats at most once, so nothing is overwritten."""

    def __init__(self, lanes: int):
        self.lane = dr.arange(mi.UInt32, lanes)
        # (flat, interleaved: a scatter's target is a 1D array)
        self._value = dr.zeros(mi.Float, lanes * dr.size_v(mi.Spectrum))
        self._position = dr.zeros(mi.Float, lanes * 2)

    def offset(self):
        return mi.ScalarVector2i(0, 0)

    def put(self, position, wavelengths, value, alpha, weight, active):
        dr.scatter(self._value, mi.Spectrum(value), self.lane, active)
        dr.scatter(self._position, mi.Point2f(position), self.lane, active)

    @property
    def value(self):
        return dr.gather(mi.Spectrum, self._value, self.lane)

    @property
    def position(self):
        return dr.gather(mi.Point2f, self._position, self.lane)


@documented("lab_mmlt")
class LabMMLTIntegrator(LabPSSMLTIntegrator):
    r"""Multiplexed Metropolis light transport (:monosp:`lab_mmlt`)

    Hachisuka, Kaplanyan and Dachsbacher 2014 ("Multiplexed Metropolis light transport"), as
    pbrt-v4's ``MLTIntegrator`` makes it, over lab_bdpt's subpaths and MIS weights, with
    lab_pssmlt's chains (``mlt/chain.py``: lock-step chains, eager steps, expected-value
    splatting, bootstrap and start in proportion to the target). The primary sample holds two
    interleaved streams (pbrt-v4's ``MLTSampler`` streams): the camera's first number picks the
    strategy (s, t) with s + t = k + 1 vertices (each of the k + 1 with probability 1 / (k + 1)),
    the next the film position, then the camera subpath's numbers; the light stream drives the
    light subpath. One population of chains per path length k (segments, 1 .. ``max_depth``), as
    pbrt-v4's: the bootstrap's ``bootstrap`` paths are split evenly over the lengths, b_k is the
    mean I of length k's and b their sum; each chain starts from a bootstrap path drawn in
    proportion to I over all of them, so a length gets chains in proportion to b_k (drawn from
    the seed), and keeps its length (the chains' lanes are grouped by length, so neighbouring
    lanes trace alike). Every step is then a step on the joint space of (length, primary
    sample) that never changes the length, which leaves its target invariant: the image stays
    unbiased (``mlt/chain.py``'s argument, with the bootstrap stratified by length).

    A sample's value f is that one strategy's contribution with lab_bdpt's MIS weight over all
    strategies of its path (``heuristic``, ``beta``), divided by the probability of picking it;
    light-tracing strategies (t = 1) land where their sensor connection meets the film, the
    others at the camera stream's film position. The target is f's luminance, the image
    (b / mutations per pixel) sum over steps of the expected-value splats (lab_pssmlt's), so its
    mean is lab_bdpt's image at the same ``max_depth``. No Russian roulette (pbrt-v4's MMLT has
    none). Each side is traced only as far as the picked strategy needs (the camera subpath t - 1
    segments, the light subpath s, one more than needed so that its last needed vertex is stored),
    and only that strategy's contribution is kept. Full lock-step rounds are recorded once per
    render with Dr.Jit's ``dr.freeze`` and replayed (``mlt/frozen.py``: the same image for the same
    seed, without a traced round's Python per round); scenes with a projector and spectral
    variants trace every round, as does ``mlt.mmlt.FREEZE_ROUNDS = False``.

    Variants: RGB, mono and spectral. In a spectral variant the wavelength sample is one more number
    of the camera stream (after the film position), so a chain walks over wavelengths as over the
    film, and each lane's light subpath is emitted at its camera ray's wavelengths
    (``spectral.EmitterSpectra.lane_samples``; a blackbody emitter, which Mitsuba samples only from
    literals, is refused). Polarized variants, crop windows, participating media and
    ``render(develop=False)`` are refused in one line. A scene whose bootstrap finds no light
    renders black, with a warning. Statistics of the last render: ``mlt_stats()``.

    .. code-block:: python

        {'type': 'lab_mmlt', 'max_depth': 8, 'chains': 8192, 'bootstrap': 100000,
         'large_step': 0.3, 'sigma': 0.01, 'heuristic': 'power'}
    """
    ESTIMATOR = MMLT
    PARAMETERS = MMLT.PARAMETERS
    SORT_STARTS = True

    def __init__(self, props: mi.Properties):
        values = plugin_settings(self.ESTIMATOR.plugin_name, props, self.PARAMETERS, "integrator")
        mi.SamplingIntegrator.__init__(self, props)    # (not lab_mis's: no path loop of its own)
        self.values = values
        self.estimator = self.ESTIMATOR(values)
        self.max_depth = values["max_depth"]
        self._init_chains()
        self._scene = None
        self._lengths = None        # each lane's path length k, for ``evaluate``

    # -- One population per path length -------------------------------------------------

    def _per_length(self) -> int:
        return max(1, self._render_bootstrap // self.max_depth)

    def _bootstrap_paths(self) -> int:
        return self._per_length() * self.max_depth

    def _before_bootstrap(self, n: int) -> None:
        self._lengths = dr.arange(mi.UInt32, n) // self._per_length() + 1

    def _normaliser(self, values: np.ndarray) -> tuple[float, float]:
        b, se = per_length_normaliser(values, self.max_depth)
        self.stats.b_per_length = b
        return float(sum(b)), float(math.sqrt(sum(e * e for e in se)))

    def _started(self, held, starts: np.ndarray) -> None:
        lengths = np.asarray(starts) // self._per_length() + 1
        held.lengths = mi.UInt32(lengths.astype(np.uint32))
        self.stats.chains_per_length = np.bincount(lengths - 1, minlength=self.max_depth).tolist()

    def _continue(self, scene, sensor, held, spp: int):
        self._lengths = held.lengths
        return super()._continue(scene, sensor, held, spp)

    def _frozen_rounds(self, chains, evaluate, splat, captured: list):
        if not FREEZE_ROUNDS or self._scene.table.projectors or mi.is_spectral:    # (spectral: not tried)
            return None
        captured = captured + [self._lengths, vars(self._scene.table)]
        return FrozenRounds(chains, evaluate, splat, captured, self.ESTIMATOR.plugin_name)

    def render(self, scene: mi.Scene, sensor=0, seed=0, spp: int = 0, develop: bool = True,
               evaluate: bool = True):
        self.refuse(develop)
        traits = SceneTraits.from_scene(scene)
        problem = self.ESTIMATOR.unsupported(traits)
        if problem:
            raise ValueError(problem)
        sensor, seed, spp = render_arguments(scene, sensor, seed, spp)
        film = sensor.film()
        if tuple(film.crop_size()) != tuple(film.size()):
            raise self.error("crop windows are not supported: light tracing's film positions cover the whole film")
        interrupts.restore()
        name = self.ESTIMATOR.plugin_name
        inv_area, axis = sensor_constants(sensor, name)
        weights = BdptWeights(self.values["heuristic"], self.values["beta"], self.estimator.techniques())
        spectra = spectral.EmitterSpectra(scene, name) if mi.is_spectral else None
        if spectra is not None:
            spectra.check_lane_samples()
        self._scene = _SceneSetup(traits, spawn.offset_floor(traits), inv_area, axis, weights, EmitterTable(scene),
                                  spectra)
        try:
            return self._render(scene, sensor, seed, spp)
        finally:
            self._scene = None

    def evaluate(self, scene, sensor, samples: chain.PrimarySamples, width: int, height: int, active=True):
        """(I, (f, film position in pixels[, wavelengths]), numbers read) of one strategy of one path
        per lane of ``samples`` (the class docstring)."""
        setup, lanes = self._scene, samples.lanes
        if not scene.emitters():     # (no light subpath to start: every path is dark, the driver warns)
            zero = dr.zeros(mi.Float, lanes)
            payload = (dr.zeros(mi.Spectrum, lanes), dr.zeros(mi.Point2f, lanes))
            if mi.is_spectral:
                payload += (dr.zeros(type(mi.Ray3f().wavelengths), lanes),)
            return zero, payload, dr.zeros(mi.UInt32, lanes)
        camera = PrimarySampleSampler(samples, CAMERA_STREAM, STREAMS)
        light = PrimarySampleSampler(samples, LIGHT_STREAM, STREAMS)
        # ---------------- the length (the lane's) and the strategy ----------------
        k = mi.UInt32(self._lengths)            # segments
        n_strategies = k + 1
        s = dr.minimum(mi.UInt32(camera.next_1d() * mi.Float(n_strategies)), n_strategies - 1)
        t = n_strategies - s
        only = Strategy(s, t)
        pick = dr.rcp(strategy_probability(n_strategies))
        # ---------------- the camera ray ----------------
        film_u = camera.next_2d()
        # spectral: the wavelengths are one more number of the camera stream, so a chain walks over
        # them too; the light subpath is emitted at its lane's (``spectral.EmitterSpectra.lane_samples``)
        wavelength_u = camera.next_1d() if mi.is_spectral else mi.Float(0.5)
        aperture_u = camera.next_2d() if sensor.needs_aperture_sample() else mi.Point2f(0.5)
        time = mi.Float(sensor.shutter_open())
        ray, ray_weight = sensor.sample_ray_differential(time, wavelength_u, film_u, aperture_u)
        # ---------------- the light subpath (its t = 1 strategy kept per lane) ----------------
        weights, floor = setup.weights, setup.floor
        tracer = LightTracer(scene, sensor, self.max_depth, NO_ROULETTE, weights, floor, only,
                             plugin=self.ESTIMATOR.plugin_name, table=setup.table, spectra=setup.spectra)
        if mi.is_spectral:       # (the sensor's spectral weight, which light tracing's splats carry)
            _, sensor_weight = sensor.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f, lanes), wavelength_u)
            tracer.pass_spectrum = (ray.wavelengths, sensor_weight)
        # Each side stops where the strategy needs it: the light subpath at x_(s-1) (its bound, a
        # path length, lets x_(s-1) be stored for a connection: s + 1), the camera's at t - 1
        # segments (its own bound stays the path's length k, which its checks compare against).
        tracer.lane_max_depth = dr.select(s > 1, dr.minimum(k, s + 1), 1)
        record = LaneSplats(lanes)
        vertices = LightVertices(lanes * self.max_depth, setup.traits.tangent_bsdf)
        reached, stores, last = tracer.trace(lanes, 0, record, 1.0, vertices, rng=light)
        # (the slots come from atomics: evaluated before the camera subpaths read them, as lab_bdpt does)
        dr.eval(last, reached, stores, *vertices.arrays(), record._value, record._position, light.dim)
        # ---------------- the camera subpath (t >= 2) ----------------
        cp = CameraPass(vertices, last, weights, tracer.table, setup.inv_area, setup.axis, k,
                        NO_ROULETTE, False, floor, setup.traits.hittable_emitters, only, lanes,
                        sensor_delta=direction_is_delta(sensor), camera_depth=t - 1)
        L, _ = trace_camera_subpaths(scene, cp, camera, mi.Ray3f(ray), mi.Bool(active) & (t > 1))
        light_tracing = t == 1
        f = dr.select(light_tracing, record.value, mi.Spectrum(ray_weight * L)) * pick
        value, f = target(f, ray.wavelengths, active)
        position = dr.select(light_tracing, record.position, mi.Point2f(film_u.x * width, film_u.y * height))
        payload = (f, position, ray.wavelengths) if mi.is_spectral else (f, position)
        return value, payload, dr.maximum(camera.dims_read(), light.dims_read())

    # -- What a path tracer's interface would answer ------------------------------------

    def sample(self, scene, sampler, ray, medium=None, active=True):
        raise self.error("cannot be nested inside another integrator that calls its sample(): its chains are "
                         "run by its own render()")

    def settings(self) -> dict:
        return dict(self.values)

    def to_string(self):
        return f"LabMMLTIntegrator[{', '.join(f'{k}={v}' for k, v in self.settings().items())}]"

    def ray_counts(self, reset: bool = True) -> dict[str, int]:
        return {}

    def aov_names(self):
        return []


class _SceneSetup:
    """What every evaluation of one render shares."""

    def __init__(self, traits, floor, inv_area, axis, weights, table, spectra=None):
        self.traits, self.floor, self.inv_area, self.axis, self.weights = traits, floor, inv_area, axis, weights
        self.table = table          # the emitters' constants (``EmitterTable``), made once per render
        self.spectra = spectra      # spectral variants: the emitters' wavelength maps, likewise


mi.register_integrator("lab_mmlt", lambda props: LabMMLTIntegrator(props))
