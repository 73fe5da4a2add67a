"""Markov chains in primary sample space, many in lock-step (Kelemen, Szirmay-Kalos, Antal and
Csonka 2002; the layout of NVIDIA Fermat's ``pssmlt.cu``; the steps of pbrt-v4's ``MLTSampler``).

Nothing here renders: a chain's target I(u) and the payload a splat needs come from an
``evaluate`` callback, so a toy target drives exactly this code (tests/plugins/test_pssmlt_chain.py).

State
-----
``chains`` chains, one per lane. Chain c's primary sample is a point u of [0, 1)^D held in one flat
array at index ``d * chains + c`` (D = ``dims``: chains x D x 4 bytes, twice during a step), with
its target I(u) > 0 and its payload (for lab_pssmlt: contribution and film position). Dimensions
d >= D are not stored: every evaluation draws them afresh (``PrimarySamples``), an independence
proposal from their uniform density, whose density ratio is 1, so the step below is still a
Metropolis-Hastings step on the whole (unbounded) primary sample, and the current state needs
those numbers no more once its I and payload are cached.

One step (``run``)
------------------
1. Propose v from u: with probability ``large_step`` (per chain) a *large step*, every stored
   number drawn afresh; else a *small step*, every stored number perturbed (eagerly: all D of
   them, used by the path or not; pbrt-v4 perturbs lazily only those a path reads) by a normal
   of standard deviation ``sigma`` or by Kelemen's exponential perturbation, and wrapped to
   [0, 1). Both steps are symmetric on the torus, q(u -> v) = q(v -> u).
2. Evaluate I(v) and its payload.
3. Acceptance a = min(1, I(v) q(v -> u) / (I(u) q(u -> v))), 0 where I(v) is 0 or not finite
   (the lab's steps pass no q ratio: it is 1).
4. Expected-value splatting: the current sample splats with weight (1 - a) / I(u), the proposal
   with a / I(v) (Veach 1997, sec. 11.3.3; Kelemen 2002).
5. Accept v with probability a.

The estimator
-------------
With b = integral of I over the primary sample space and the chains' stationary density I / b,
g's integral is b E[g / I]; over M = chains x steps mutations

    integral of g  ~  (b / M) sum over chains and steps of [(1 - a) g(u) / I(u) + a g(v) / I(v)].

b is the mean of I over ``bootstrap`` independent primary samples (``normaliser``), and each
chain starts from one of them drawn in proportion to I (``MarkovChains.start``). Then the
estimate is *unbiased*, not only consistent: for one chain started that way and any step t,
E[b_hat h(u_t)] = E[(1/n) sum_i I(x_i) (K^t h)(x_i)] = integral of I K^t h = b E_{I/b}[h], because
the Metropolis-Hastings kernel K leaves I / b invariant; the estimate is a sum of such terms, and
the expected-value splat of a step has the conditional mean (K h)(u_t). The bootstrap's size
changes the variance only (one random factor b_hat / b on the whole estimate), never the mean.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab.plugins.params import MLT_SMALL_STEPS
from mitsuba_lab.plugins.samplers.common import mix32

#: Kelemen et al.'s exponential perturbation: offsets from S1 to S2, log-uniformly.
KELEMEN_S1, KELEMEN_S2 = 1.0 / 1024.0, 1.0 / 64.0
#: Purposes of the keys (``key_of``): which random decision a key randomises.
P_BOOTSTRAP = 0x1B873593   # a bootstrap path's primary sample (its key per path)
P_START = 0x2545F491       # the bootstrap path each chain starts from
P_LARGE = 0x3C6EF372       # large or small step, per chain and step
P_MUTATE = 0x4F1BBCDC      # the new numbers (large) or perturbations (small), per number and step
P_ACCEPT = 0x68E31DA4      # acceptance, per chain and step
P_TAIL = 0x7A4E0D3B        # the unstored dimensions' fresh numbers, per chain and step
P_STEP = 0x8CB92BA7        # a step's key
#: 2^-24: the uniform numbers are (k + 1/2) 2^-24, k < 2^24: never 0, never 1.
INV_2_24 = 2.0 ** -24


# ----------------------------------------------------------------------------
# Counter-based random numbers
# ----------------------------------------------------------------------------

def key_of(*words):
    """A 32-bit key of a sequence of words (Python ints or UInt32 arrays): one MurmurHash3
    finaliser round per word (``samplers.common.mix32``)."""
    key = mi.UInt32(0x9E3779B9)
    for word in words:
        key = mix32(key ^ mi.UInt32(word))
    return key


def uniform(key, index):
    """A uniform number in (0, 1) of ``key`` and ``index`` (UInt32 arrays or ints):
    (k + 1/2) 2^-24 with k the top 24 bits of two finaliser rounds. The same (key, index)
    always gives the same number, so a bootstrap path's primary sample can be read again."""
    x = mix32(mi.UInt32(key) ^ mix32(mi.UInt32(index) * 0x9E3779B1 + 0x7F4A7C15))
    return (mi.Float(mi.Int32(x >> 8)) + 0.5) * INV_2_24


def seed_key(seed: int):
    """The key of a render seed, opaque (a new seed reuses the compiled kernels)."""
    value = int(mi.sample_tea_32(mi.UInt32(seed % 2 ** 32), mi.UInt32(0x4D4C5421))[0][0])
    return dr.opaque(mi.UInt32, value)


class PrimarySamples:
    """The primary samples of ``lanes`` lanes, read dimension by dimension: dimension d < ``dims``
    of lane c from ``state[d * lanes + c]``, every other from ``uniform(keys[c], d)``.

    A plain Python object on purpose: the sampler that holds it is traversed by Dr.Jit's
    symbolic loops (its Dr.Jit attributes become loop state), and the state is wider than a
    loop; read-only inside the loop, it is captured, not carried."""

    def __init__(self, lanes: int, keys, state=None, dims: int = 0):
        self.lanes = lanes
        self.keys = keys
        self.state = state
        self.dims = dims if state is not None else 0
        self.lane = dr.arange(mi.UInt32, lanes)

    def get(self, dim, active=True):
        fresh = uniform(self.keys, dim)
        if self.dims == 0:
            return fresh
        dim = mi.UInt32(dim)
        stored = dim < self.dims
        value = dr.gather(mi.Float, self.state, dim * self.lanes + self.lane, stored & active)
        return dr.select(stored, value, fresh)


# ----------------------------------------------------------------------------
# Small steps
# ----------------------------------------------------------------------------

def wrap(v):
    """v mod 1, in [0, 1)."""
    v = v - dr.floor(v)
    return dr.select(v >= 1.0, v - 1.0, v)


def perturb(u, xi, small_step: str, sigma: float):
    """u moved by a symmetric offset drawn from the uniform ``xi`` in (0, 1), wrapped to [0, 1):
    normal: sigma sqrt(2) erfinv(2 xi - 1); exponential (Kelemen 2002): +-s2 exp(-ln(s2 / s1) x),
    the sign from xi < 1/2 and x = 2 xi mod 1 uniform."""
    if small_step == "normal":
        offset = sigma * math.sqrt(2.0) * dr.erfinv(2.0 * xi - 1.0)
    elif small_step == "exponential":
        up = xi < 0.5
        x = dr.select(up, 2.0 * xi, 2.0 * xi - 1.0)
        size = KELEMEN_S2 * dr.exp(-math.log(KELEMEN_S2 / KELEMEN_S1) * x)
        offset = dr.select(up, size, -size)
    else:
        raise ValueError(f"small_step must be one of {', '.join(MLT_SMALL_STEPS)}, got {small_step!r}")
    return wrap(u + offset)


# ----------------------------------------------------------------------------
# Bootstrap
# ----------------------------------------------------------------------------

def normaliser(values: np.ndarray) -> tuple[float, float]:
    """(b, its standard error): the mean of the bootstrap's I and the mean's standard error."""
    values = np.asarray(values, dtype=np.float64)
    n = len(values)
    b = float(values.mean()) if n else 0.0
    se = float(values.std(ddof=1) / math.sqrt(n)) if n > 1 else float("inf")
    return b, se


def resample(values: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """Indices into ``values`` drawn in proportion to them, one per uniform in ``xi``: the first
    index whose cumulative sum (float64) exceeds xi times the total, so an index of weight 0 is
    never drawn."""
    cdf = np.cumsum(np.asarray(values, dtype=np.float64))
    index = np.searchsorted(cdf, np.asarray(xi, dtype=np.float64) * cdf[-1], side="right")
    return np.minimum(index, len(cdf) - 1).astype(np.uint32)


# ----------------------------------------------------------------------------
# The chains
# ----------------------------------------------------------------------------

@dataclass
class ChainCounts:
    """Per chain: summed acceptance probabilities, accepted proposals, large steps, and the
    acceptance summed over large steps (Float arrays of ``chains``)."""
    acceptance: object = None
    accepted: object = None
    large: object = None
    large_acceptance: object = None

    @classmethod
    def zeros(cls, n: int) -> "ChainCounts":
        return cls(*(dr.zeros(mi.Float, n) for _ in range(4)))

    def arrays(self) -> tuple:
        return self.acceptance, self.accepted, self.large, self.large_acceptance


@dataclass
class MarkovChains:
    """``chains`` Metropolis-Hastings chains in lock-step on [0, 1)^dims (see the module docstring).

    ``u`` (flat, index d * chains + c), ``value`` (I of each chain's current state, > 0) and
    ``payload`` (a tuple of Dr.Jit arrays of width ``chains``) are set by ``start``."""
    chains: int
    dims: int
    key: object                 # the render's key (``seed_key``)
    large_step: float = 0.3
    small_step: str = "normal"
    sigma: float = 0.01
    u: object = None
    value: object = None
    payload: tuple = ()
    counts: ChainCounts = field(default=None)
    steps: int = 0

    def __post_init__(self):
        if self.small_step not in MLT_SMALL_STEPS:
            raise ValueError(f"small_step must be one of {', '.join(MLT_SMALL_STEPS)}, got {self.small_step!r}")
        self.counts = ChainCounts.zeros(self.chains)
        self.lane = dr.arange(mi.UInt32, self.chains)
        self.flat = dr.arange(mi.UInt32, self.chains * self.dims)

    # -- start ------------------------------------------------------------------------

    def start(self, boot_keys, boot_values: np.ndarray, boot_value, boot_payload: tuple) -> np.ndarray:
        """Each chain starts from a bootstrap sample drawn in proportion to its I (``resample``):
        its primary sample read again from its key (``uniform(key, d)``), its I and payload
        gathered. The bootstrap's total I must be > 0. Returns the drawn indices."""
        xi = np.array(uniform(key_of(self.key, P_START), self.lane), dtype=np.float64)
        index = mi.UInt32(resample(boot_values, xi))
        keys = dr.gather(mi.UInt32, boot_keys, index)
        if self.dims:
            self.u = uniform(dr.gather(mi.UInt32, keys, self.flat % self.chains), self.flat // self.chains)
        else:
            self.u = mi.Float()
        self.value = dr.gather(mi.Float, boot_value, index)
        self.payload = tuple(dr.gather(type(p), p, index) for p in boot_payload)
        dr.eval(self.u, self.value, *self.payload)
        return np.array(index)

    # -- one step ---------------------------------------------------------------------

    def step_key(self, step: int):
        return key_of(self.key, P_STEP, dr.opaque(mi.UInt32, step))

    def tail_keys(self, key):
        """Per chain, the key of the unstored dimensions' numbers of this step's proposal."""
        return key_of(key, P_TAIL, self.lane)

    def propose(self, key):
        """(v, large): the proposal (flat, like ``u``) and which chains take a large step."""
        large = uniform(key_of(key, P_LARGE), self.lane) < self.large_step
        if not self.dims:
            return self.u, large
        chain = self.flat % self.chains
        large_here = uniform(key_of(key, P_LARGE), chain) < self.large_step
        xi = uniform(key_of(key, P_MUTATE), self.flat)
        v = dr.select(large_here, xi, perturb(self.u, xi, self.small_step, self.sigma))
        return v, large

    def weigh(self, value, q_ratio=None):
        """(a, current's weight (1 - a) / I(u), proposal's weight a / I(v)) for proposals of target
        ``value``; ``q_ratio`` = q(v -> u) / q(u -> v) where the proposal is not symmetric."""
        ok = dr.isfinite(value) & (value > 0)
        ratio = value / self.value
        if q_ratio is not None:
            ratio = ratio * q_ratio
            ok &= ratio >= 0                     # (false for NaN)
        a = dr.select(ok, dr.minimum(ratio, 1.0), 0.0)
        return a, (1.0 - a) / self.value, dr.select(ok, a / value, 0.0)

    def accept(self, key, v, value, payload: tuple, a, large) -> None:
        """Each chain moves to its proposal with probability ``a``."""
        xi = uniform(key_of(key, P_ACCEPT), self.lane)
        moves = xi < a
        if self.dims:
            chain = self.flat % self.chains
            moves_here = uniform(key_of(key, P_ACCEPT), chain) < dr.gather(mi.Float, a, chain)
            self.u = dr.select(moves_here, v, self.u)
        self.value = dr.select(moves, value, self.value)
        self.payload = tuple(dr.select(moves, p, q) for p, q in zip(payload, self.payload))
        c = self.counts
        c.acceptance = c.acceptance + a
        c.accepted = c.accepted + dr.select(moves, 1.0, 0.0)
        c.large = c.large + dr.select(large, 1.0, 0.0)
        c.large_acceptance = c.large_acceptance + dr.select(large, a, 0.0)
        self.steps += 1

    def arrays(self) -> tuple:
        return (self.u, self.value, *self.payload, *self.counts.arrays())


def run(chains: MarkovChains, steps: int, evaluate, splat, proposal=None, checkpoint=None) -> None:
    """``steps`` steps of every chain: propose, ``evaluate(v, tail_keys)`` -> (I, payload), splat
    the current (``splat(payload, (1 - a) / I(u))``) and the proposal (``splat(payload, a / I(v))``),
    accept. ``proposal(chains, key)`` -> (v, large, q_ratio) replaces the lab's symmetric steps
    (a test's non-symmetric proposal). Dr.Jit evaluates the state (and the splats) once per step;
    ``checkpoint()`` runs after each."""
    for _ in range(steps):
        key = chains.step_key(chains.steps)
        if proposal is None:
            v, large = chains.propose(key)
            q_ratio = None
        else:
            v, large, q_ratio = proposal(chains, key)
        value, payload = evaluate(v, chains.tail_keys(key))
        a, w_current, w_proposal = chains.weigh(value, q_ratio)
        dr.eval(value, *payload, a, w_current, w_proposal)    # (the proposal traced once)
        splat(chains.payload, w_current)
        splat(payload, w_proposal)
        chains.accept(key, v, value, payload, a, large)
        dr.eval(*chains.arrays())
        if checkpoint is not None:
            checkpoint()


def quantiles(values, qs=(0.05, 0.5, 0.95)) -> list[float]:
    values = np.asarray(values, dtype=np.float64)
    return [float(np.quantile(values, q)) for q in qs] if len(values) else [float("nan")] * len(qs)
