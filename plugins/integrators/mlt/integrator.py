"""``lab_pssmlt``: the driver (bootstrap, chains, splats, normalisation) and the plugin."""
from __future__ import annotations

import time
import warnings
from dataclasses import asdict, dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab.plugins import interrupts
from mitsuba_lab.plugins.integrators.bdpt import splats
from mitsuba_lab.plugins.integrators.common.support import render_arguments, warn_if_unsupported
from mitsuba_lab.plugins.integrators.path import KernelPlan, LabMISIntegrator
from mitsuba_lab.plugins.param_docs import documented
from mitsuba_lab.plugins.params import MLT_GROWN_BOOTSTRAP
from mitsuba_lab.plugins.scene_traits import SceneTraits

from . import chain
from .estimator import PSSMLT
from .frozen import FrozenRounds
from .sampler import PrimarySampleSampler

#: The most primary-sample dimensions a chain stores (chains x MAX_DIMS x 16 bytes);
#: a path reading more draws the rest afresh at every step (``chain`` module docstring).
MAX_DIMS = 256
#: Full lock-step rounds recorded once per render and replayed (``frozen.FrozenRounds``): a traced
#: round's Python (the path loop's trace) is paid once per render, not per round; the same images.
#: Not in spectral variants nor with ``majorants`` = grid (values the round reads that the frozen
#: function cannot take as inputs: the spectral tables, the grid kept on the integrator).
FREEZE_ROUNDS = True


@dataclass
class MLTStats:
    """What the last render's chains did (``mlt_stats()``)."""
    b: float = 0.0                      # the normaliser: mean luminance of the bootstrap's paths
    b_standard_error: float = 0.0
    bootstrap: int = 0                  # bootstrap paths
    bootstrap_nonzero: int = 0          # ... of which carried light (I > 0)
    distinct_starts: int = 0            # distinct bootstrap paths the chains start from
    b_per_length: list = field(default_factory=list)       # lab_mmlt: b of each path length 1 .. max_depth
    chains_per_length: list = field(default_factory=list)  # lab_mmlt: chains that hold each length
    dims: int = 0                       # primary-sample dimensions stored per chain
    dims_read_max: int = 0              # the most any bootstrap path read
    chains: int = 0
    steps: int = 0                      # lock-step rounds of this render (the last may be partial)
    mutations: int = 0                  # this render's: pixels x spp
    chain_mutations: int = 0            # the chains' since their start (continued renders included)
    mutations_per_pixel: float = 0.0
    acceptance: float = 0.0             # mean acceptance probability over all steps
    acceptance_quantiles: list = field(default_factory=list)   # per chain: 5%, 50%, 95%
    accepted_share: float = 0.0         # proposals accepted (the coin's outcomes)
    large_step_share: float = 0.0       # steps that were large steps
    large_step_acceptance: float = 0.0  # mean acceptance probability of large steps
    small_step_acceptance: float = 0.0
    bootstrap_s: float = 0.0
    chains_s: float = 0.0
    seconds_per_mutation: float = 0.0   # chains_s / mutations (with the splats)
    frozen_recordings: int = 0          # lab_mmlt: recordings of its frozen round (0: rounds not frozen)

    def as_dict(self) -> dict:
        return asdict(self)


@documented("lab_pssmlt")
class LabPSSMLTIntegrator(LabMISIntegrator):
    r"""Primary-sample-space Metropolis light transport (:monosp:`lab_pssmlt`)

    Kelemen, Szirmay-Kalos, Antal and Csonka 2002 ("A simple and robust mutation strategy for the
    Metropolis light transport algorithm") over lab_mis's path tracer: a path is a function of
    its primary sample u, the numbers in [0, 1) it reads (the first two choose the film
    position over the whole crop window, then time, wavelength and aperture where the sensor
    needs them, then the path loop's). Markov chains over u, one per lane, advance in
    lock-step; each proposal is traced by the lab_mis path loop, its target I(u) is the
    luminance of the path's contribution f(u), and each step splats the current and the proposed
    sample weighted by the acceptance probability (expected-value splatting):

        image = (b / mutations per pixel) sum over steps [(1 - a) f(u) / I(u) + a f(v) / I(v)]

    at their film positions, through the film's reconstruction filter (corrected at the crop's
    edges as lab_bdpt's light tracing is: ``bdpt/splats.py``). b, the integral of I, is the mean I
    of ``bootstrap`` independent paths; each chain starts from one of them drawn in proportion to
    I, which makes the image unbiased (``mlt/chain.py`` has the argument; b's error adds
    variance, one factor on the whole image, no bias). spp is mutations per pixel, exactly:
    the render makes pixels x spp mutations, mutation k a step of chain k mod ``chains``, so the
    last lock-step round may step only some chains (the rest wait, splatting nothing). Full
    rounds are recorded once per render with Dr.Jit's ``dr.freeze`` and replayed
    (``mlt/frozen.py``: the same image for the same seed, without a traced round's Python),
    except in spectral variants and with ``majorants`` = grid (``mlt.integrator.FREEZE_ROUNDS =
    False`` traces every round).

    Progressive runs (the runner's ``experiment/execution/progressive.py``): a render with
    ``continue_chains`` set continues the last render's chains on the same scene and sensor
    (its seed unused) and returns the image of its own mutations normalised by their count, so
    the runner's spp-weighted mean of the passes is the chains' image after all their
    mutations, the same as one render of that many (the bootstrap paid once, by the first
    pass).

    Steps (``mlt/chain.py``): with probability ``large_step`` every stored number is drawn
    afresh, else every stored number is perturbed (``small_step``: a normal of standard deviation
    ``sigma``, pbrt-v4's, or Kelemen's exponential perturbation) and wrapped to [0, 1); both are
    symmetric, so a = min(1, I(v) / I(u)). Both steps are eager: every stored number moves at
    every step, in one flat kernel before the paths are traced (pbrt-v4's lazy normal step, a
    number moved only when a path reads it, is the same process in distribution, but its
    bookkeeping inside the path loop cost more: 2026-11-29-mlt-speed.md). A chain stores D
    numbers, D the most any bootstrap path read (at most 256: memory chains x D x 8 bytes);
    numbers past D are drawn afresh by every proposal (an independence proposal in those
    dimensions, still exact).

    Parameters: lab_mis's (its path loop and weights) and the chains': ``chains`` (lanes in
    lock-step), ``bootstrap`` (paths for b and the chains' start; with ``bootstrap_share`` > 0 at
    least that many paths per mutation of the render, so the bootstrap grows with the budget),
    ``large_step``, ``small_step`` and ``sigma`` (the table below). The defaults were measured at
    equal time against the alternatives (experiments/results/2026-11-28-mlt-second.md: 32x32, 1 and 4 s, the door ajar
    and the Cornell box): the bootstrap's size matters most, since where few paths carry light
    many chains start from one bootstrap path and stay correlated (``mlt_stats()``'s
    ``distinct_starts``; on the door a 16384-path bootstrap and 2048 chains were 4.6x the
    defaults' relMSE at 4 s); fewer, longer chains lose (a lock-step costs nearly the same at
    512 lanes as at 2048), more than 8192 gained nothing resolved, and large_step 0.1 or sigma
    0.03 changed nothing resolved. A larger bootstrap (262144) gained 2.5x on the door at 4 s
    but lost on the Cornell box and missed 1 s budgets; one that grows with the render's
    mutations (``bootstrap_share`` 0.25, the default) gained 4.7x on the door at 16 s and was
    level on the Cornell box in relMSE x time (2026-11-29-mlt-fourth.md, single renders).

    Variants: RGB, mono and spectral (the wavelength sample is the primary sample's number after the
    film position and time, so a chain perturbs it as any other). Every render seed is an
    independent bootstrap and set of chains. A scene whose bootstrap
    finds no light renders black, with a warning. The alpha channel is 1. Refused in one line:
    polarized variants, ``render(develop=False)``. Participating media go through lab_mis's
    path loop unchanged (tests/plugins/test_pssmlt.py: block and image means agree with volpath's
    on tests/media_scenes.py's fog_box). Statistics of the last render:
    ``mlt_stats()``.

    .. code-block:: python

        {'type': 'lab_pssmlt', 'max_depth': 8, 'chains': 8192, 'bootstrap': 100000,
         'large_step': 0.3, 'sigma': 0.01}
    """
    ESTIMATOR = PSSMLT
    PARAMETERS = PSSMLT.PARAMETERS
    #: Chains take their starts in the bootstrap's order (lab_mmlt: lanes grouped by path length).
    SORT_STARTS = False
    #: Normal small steps made lazily in the path loop (``chain.LazyProposal``), else eagerly in a
    #: flat kernel per step: eager measured 1.2-1.8x cheaper per mutation (2026-11-29-mlt-speed.md).
    LAZY_STEPS = False

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self._init_chains()

    def _init_chains(self) -> None:
        """The chains' settings, from ``self.estimator`` (shared with lab_mmlt)."""
        e = self.estimator
        self.chains, self.bootstrap, self.bootstrap_share = e.chains, e.bootstrap, e.bootstrap_share
        self.large_step, self.small_step, self.sigma = e.large_step, e.small_step, e.sigma
        self.stats = MLTStats()
        #: Set (by the runner's progressive runs) to continue the chains of the last render of this
        #: scene and sensor instead of starting new ones (``_continue``).
        self.continue_chains = False
        self._held = None

    def error(self, text: str) -> ValueError:
        return ValueError(f"{self.ESTIMATOR.plugin_name}: {text}")

    # -- Driver -------------------------------------------------------------------

    def render(self, scene: mi.Scene, sensor=0, seed=0, spp: int = 0, develop: bool = True,
               evaluate: bool = True):
        self.refuse(develop)
        traits = SceneTraits.from_scene(scene)
        warn_if_unsupported(self, traits)
        sensor, seed, spp = render_arguments(scene, sensor, seed, spp)
        interrupts.restore()
        self._plan = (scene, KernelPlan.of(traits, self.estimator))
        try:
            return self._render(scene, sensor, seed, spp)
        finally:
            self._plan = None

    def refuse(self, develop: bool) -> None:
        """One-line errors for what no chain estimator renders."""
        if not develop:
            raise self.error("render(develop=False) is not supported: the chains splat into a film of their "
                             "own, normalised by b when developed")
        if mi.is_polarized:
            raise self.error(f"variant '{mi.variant()}' is not supported: the target is a luminance; use "
                             f"{mi.variant().replace('_polarized', '')}")

    def _render(self, scene, sensor, seed: int, spp: int):
        film = sensor.film()
        width, height = (int(v) for v in film.crop_size())
        pixels = width * height
        identity = (id(scene), id(sensor), width, height, mi.variant())
        held, self._held = self._held, None
        if self.continue_chains and held is not None and held.identity == identity:
            return self._continue(scene, sensor, held, spp)
        key = chain.seed_key(seed)
        self._render_bootstrap = self.bootstrap_for(pixels * spp)
        self.stats = stats = MLTStats(bootstrap=self._render_bootstrap)

        # ---------------- Bootstrap: b and the paths the chains start from ----------------
        start = _now()
        stats.bootstrap = n = self._bootstrap_paths()
        boot_keys = chain.key_of(key, chain.P_BOOTSTRAP, dr.arange(mi.UInt32, n))
        self._before_bootstrap(n)
        boot_value, boot_payload, dims_read = self.evaluate(scene, sensor, chain.PrimarySamples(n, boot_keys),
                                                            width, height)
        dr.eval(boot_keys, boot_value, *boot_payload, dims_read)
        values = np.array(boot_value, dtype=np.float64)
        stats.b, stats.b_standard_error = self._normaliser(values)
        stats.bootstrap_nonzero = int(np.count_nonzero(values))
        stats.dims_read_max = int(dr.max(dims_read)[0]) if n else 0
        stats.bootstrap_s = _now() - start
        if not stats.b > 0:
            warnings.warn(f"{self.ESTIMATOR.plugin_name}: none of the {n} bootstrap paths carried light (the "
                          f"scene has no emitter the paths reach, or bootstrap is too small): the image is black",
                          stacklevel=2)
            return self._image(film, splats.new_block(film), 0.0)

        # ---------------- The chains ----------------
        stats.chains = n_chains = self.chains
        stats.dims = dims = min(stats.dims_read_max, MAX_DIMS)
        chains = chain.MarkovChains(n_chains, dims, key, self.large_step, self.small_step, self.sigma,
                                    lazy=self.LAZY_STEPS)
        starts = chains.start(boot_keys, values, boot_value, boot_payload, sort=self.SORT_STARTS)
        stats.distinct_starts = int(np.unique(starts).size)
        del boot_value, boot_payload, boot_keys
        held = _Held(identity, chains, pixels)
        self._started(held, starts)
        return self._continue(scene, sensor, held, spp)

    # -- What lab_mmlt's per-length populations change (lab_pssmlt: one population) ----------

    def bootstrap_for(self, mutations: int) -> int:
        """The bootstrap's paths of a render of ``mutations`` that starts chains: ``bootstrap``, or
        ``bootstrap_share`` x ``mutations`` (at most MLT_GROWN_BOOTSTRAP) where that is more."""
        return int(max(self.bootstrap, min(round(self.bootstrap_share * mutations), MLT_GROWN_BOOTSTRAP)))

    def _bootstrap_paths(self) -> int:
        return self._render_bootstrap

    def _before_bootstrap(self, n: int) -> None:
        """Called before the bootstrap's ``n`` paths are evaluated."""

    def _normaliser(self, values: np.ndarray) -> tuple[float, float]:
        """(b, its standard error) from the bootstrap's I."""
        return chain.normaliser(values)

    def _started(self, held: "_Held", starts: np.ndarray) -> None:
        """Called once the chains have started from the bootstrap paths ``starts`` (one per chain)."""

    def _continue(self, scene, sensor, held: "_Held", spp: int):
        """pixels x spp more mutations of the held chains (``chain.run_mutations``: mutation k a
        step of chain k mod chains), splatted into a film of their own and normalised by their
        count: an unbiased image of these mutations alone. Held for the next render, which
        continues them when ``continue_chains`` is set (a progressive run's later passes: the
        runner's spp-weighted mean of the passes is then the chains' image after all of them)."""
        film = sensor.film()
        width, height = (int(v) for v in film.crop_size())
        stats, chains = self.stats, held.chains
        start = _now()
        block = splats.new_block(film)
        mutations = held.pixels * spp

        def evaluate(samples, active=True):
            value, payload, _ = self.evaluate(scene, sensor, samples, width, height, active)
            return value, payload

        def splat(payload, weight):
            wavelengths = payload[2] if len(payload) > 2 else type(mi.Ray3f().wavelengths)()   # (rgb, mono: none)
            splats.splat(block, payload[1], wavelengths, payload[0] * weight, weight > 0)

        steps_before = chains.steps
        full_step = self._frozen_rounds(chains, evaluate, splat, [scene, sensor, block])
        chain.run_mutations(chains, held.mutations, mutations, evaluate, splat,
                            checkpoint=lambda: interrupts.checkpoint(self), full_step=full_step)
        stats.frozen_recordings = 0 if full_step is None else full_step.recordings
        held.mutations += mutations
        stats.steps = chains.steps - steps_before
        stats.mutations = mutations
        stats.mutations_per_pixel = mutations / held.pixels
        stats.chain_mutations = held.mutations
        self._count(chains)
        image = self._image(film, block, stats.b / stats.mutations_per_pixel)
        stats.chains_s = _now() - start
        stats.seconds_per_mutation = stats.chains_s / max(mutations, 1)
        self._held = held
        return image

    def _frozen_rounds(self, chains, evaluate, splat, captured: list):
        """``frozen.FrozenRounds`` for the full rounds of a render (``captured``: the Dr.Jit values
        ``evaluate`` and ``splat`` read besides the chains'), or None to trace every round."""
        if not FREEZE_ROUNDS or mi.is_spectral or (self._plan[1].media and self.majorants == "grid"):
            return None
        # (the path loop counts its rays into the counters' array: an input too)
        return FrozenRounds(chains, evaluate, splat, captured + [vars(self.counters)], self.ESTIMATOR.plugin_name)

    def _count(self, chains: chain.MarkovChains) -> None:
        """The acceptance statistics of every step the chains took so far (continued renders
        included)."""
        stats, counts = self.stats, chains.counts
        acceptance = np.array(counts.acceptance, dtype=np.float64)
        large = np.array(counts.large, dtype=np.float64)
        large_acceptance = np.array(counts.large_acceptance, dtype=np.float64)
        taken = np.array(counts.taken, dtype=np.float64)
        total = taken.sum()
        stats.acceptance = float(acceptance.sum() / total)
        stats.acceptance_quantiles = chain.quantiles(acceptance[taken > 0] / taken[taken > 0])
        stats.accepted_share = float(np.array(counts.accepted, dtype=np.float64).sum() / total)
        stats.large_step_share = float(large.sum() / total)
        stats.large_step_acceptance = float(large_acceptance.sum() / large.sum()) if large.sum() else float("nan")
        small = total - large.sum()
        stats.small_step_acceptance = (float((acceptance.sum() - large_acceptance.sum()) / small) if small
                                       else float("nan"))

    def _image(self, film, block, scale: float):
        """The developed splats times ``scale`` in the colour channels; alpha (and any other
        channel) 1."""
        image = np.array(splats.develop(film, block), dtype=np.float32)
        channels = 1 if mi.is_monochromatic else 3
        image[:, :, :channels] *= scale
        image[:, :, channels:] = 1.0
        return mi.TensorXf(image)

    # -- One path per lane, from its primary sample ---------------------------------------

    def evaluate(self, scene, sensor, samples: chain.PrimarySamples, width: int, height: int, active=True):
        """(I, (f, film position in pixels[, wavelengths]), numbers read) of one path per lane of
        ``samples``: f = the sensor's ray weight times lab_mis's L, I its luminance (0 where not
        finite or not positive, and f 0 there)."""
        sampler = PrimarySampleSampler(samples)
        film_u = sampler.next_2d()
        shutter = mi.Float(sensor.shutter_open())
        if sensor.shutter_open_time() > 0:
            shutter = shutter + sampler.next_1d() * sensor.shutter_open_time()
        wavelength_u = sampler.next_1d() if mi.is_spectral else mi.Float(0.5)
        aperture_u = sampler.next_2d() if sensor.needs_aperture_sample() else mi.Point2f(0.5)
        ray, ray_weight = sensor.sample_ray_differential(shutter, wavelength_u, film_u, aperture_u)
        L, _, _ = self.sample(scene, sampler, ray, sensor.get_medium(), mi.Bool(active))
        value, f = target(mi.Spectrum(ray_weight * L), ray.wavelengths, active)
        position = mi.Point2f(film_u.x * width, film_u.y * height)
        payload = (f, position, ray.wavelengths) if mi.is_spectral else (f, position)
        return value, payload, sampler.dim

    # -- Reporting --------------------------------------------------------------------

    def mlt_stats(self) -> dict:
        """Statistics of the last render (``MLTStats``), as plain values."""
        return self.stats.as_dict()


@dataclass
class _Held:
    """The chains of the last render, for a render that continues them."""
    identity: tuple
    chains: object
    pixels: int
    mutations: int = 0
    lengths: object = None      # lab_mmlt: each chain's path length (UInt32 per chain)


def target(f, wavelengths, active=True):
    """(I, f): a chain's target I, the luminance of the contribution f, and f, both 0 where I is
    not finite or not positive (or the lane is not ``active``)."""
    if mi.is_spectral:
        value = mi.luminance(f, wavelengths)
    elif mi.is_monochromatic:
        value = f[0]
    else:
        value = mi.luminance(f)
    value = mi.Float(value)
    ok = dr.isfinite(value) & (value > 0) & active
    return dr.select(ok, value, 0.0), dr.select(ok, f, 0.0)


def _now() -> float:
    dr.sync_thread()
    return time.perf_counter()


mi.register_integrator("lab_pssmlt", lambda props: LabPSSMLTIntegrator(props))
