"""Markov chains in primary sample space, many in lock-step (Kelemen, Szirmay-Kalos, Antal and
Csonka 2002; the layout of NVIDIA Fermat's ``pssmlt.cu``; the steps of pbrt-v4's ``MLTSampler``).

Nothing here renders: a chain's target I(u) and the payload a splat needs come from an
``evaluate`` callback, so a toy target drives exactly this code (tests/plugins/test_pssmlt_chain.py).

State
-----
``chains`` chains, one per lane. Chain c's primary sample is a point u of [0, 1)^D held in one flat
array at index ``d * chains + c`` (D = ``dims``; chains x D x 8 bytes with the proposal, 16
with the lazy steps' counters), with
its target I(u) > 0 and its payload (for lab_pssmlt: contribution and film position). Dimensions
d >= D are not stored: every evaluation draws them afresh (``PrimarySamples``), an independence
proposal from their uniform density, whose density ratio is 1, so the step below is still a
Metropolis-Hastings step on the whole (unbounded) primary sample, and the current state needs
those numbers no more once its I and payload are cached.

One step (``run``)
------------------
1. Propose v from u: with probability ``large_step`` (per chain) a *large step*, every stored
   number drawn afresh; else a *small step*, every stored number perturbed by a normal of
   standard deviation ``sigma`` or by Kelemen's exponential perturbation, and wrapped to [0, 1).
   Both steps are symmetric on the torus, q(u -> v) = q(v -> u). Eagerly (``lazy`` False, what
   the plugins run): all D numbers at every step, in one flat kernel. With ``lazy`` the normal
   step is made as pbrt-v4's ``MLTSampler`` makes it: a number is mutated only when the path
   reads it, by all the accepted steps it missed at once (``LazyProposal``: the same process in
   distribution, measured slower here, 2026-11-29-mlt-speed.md); the exponential step is always
   eager (no closed form for a sum of them).
2. Evaluate I(v) and its payload (for the lazy step, evaluating v is proposing it).
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
P_CATCH_UP = 0x9E3779B1    # a lazily read number's fresh start after an accepted large step
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
    of lane c from ``state[d * lanes + c]``, every other from ``uniform(keys[c], d)``. With
    ``lazy`` (a ``LazyProposal``) the stored numbers are the chain's current state and each one
    read is mutated as it is read (``LazyProposal.mutate``).

    A plain Python object on purpose: the sampler that holds it is traversed by Dr.Jit's
    symbolic loops (its Dr.Jit attributes become loop state), and the state is wider than a
    loop; inside the loop it is captured, not carried."""

    def __init__(self, lanes: int, keys, state=None, dims: int = 0, lazy: "LazyProposal | None" = None):
        self.lanes = lanes
        self.keys = keys
        self.state = state
        self.dims = dims if state is not None else 0
        self.lazy = lazy
        self.lane = dr.arange(mi.UInt32, lanes)

    def get(self, dim, active=True):
        fresh = uniform(self.keys, dim)
        if self.dims == 0:
            return fresh
        dim = mi.UInt32(dim)
        stored = dim < self.dims
        index = dim * self.lanes + self.lane
        if self.lazy is not None:
            # (every stored number read is mutated, used or not: its value is then a symmetric
            # proposal from the current one, which the acceptance needs)
            value = self.lazy.mutate(self.state, index, self.lane, dim, stored)
        else:
            value = dr.gather(mi.Float, self.state, index, stored & active)
        return dr.select(stored, value, fresh)


@dataclass
class LazyProposal:
    """A step's proposal made lazily (pbrt-v4's ``MLTSampler``), for the normal small step: a
    stored number is mutated only when a path reads it, by all the steps it missed at once.

    Per chain: ``iteration`` (accepted steps so far, plus one: the proposal's), ``last_large`` (the
    iteration of the last accepted large step) and ``large`` (this step is a large one); per
    stored number: ``last`` (the iteration it was last brought up to date at). Reading number d:
    if a large step was accepted since ``last``, it starts from a fresh uniform at ``last_large``;
    then a large step draws it afresh, and a small step adds a normal of standard deviation
    sigma sqrt(iteration - last) (the sum of the accepted small steps it missed), wrapped. The
    proposal and the step's ``stamp`` are written to ``proposal`` and ``stamps``; accepting a
    chain copies its numbers stamped this step. In distribution this is the eager step (every
    stored number moved at every accepted step): the numbers no path read influence nothing."""
    chains: int
    sigma: float
    key: object                 # the step's key (the per-chain keys are derived from it)
    iteration: object           # UInt32 per chain
    last_large: object          # UInt32 per chain
    large: object               # Bool per chain
    last: object                # UInt32 per stored number
    proposal: object            # Float per stored number (written)
    stamps: object              # UInt32 per stored number (written)
    stamp: object               # the step's stamp (opaque UInt32)

    def __post_init__(self):
        # per chain, made once outside the path loop: the keys of the mutations and of the fresh starts
        lane = dr.arange(mi.UInt32, self.chains)
        self.mutate_keys = key_of(self.key, P_MUTATE, lane)
        self.catch_up_keys = key_of(self.key, P_CATCH_UP, lane)
        dr.eval(self.mutate_keys, self.catch_up_keys)

    def mutate(self, state, index, lane, dim, stored):
        """Number ``dim`` of each lane's proposal (flat ``index``; per-chain arrays are lane-aligned)."""
        u = dr.gather(mi.Float, state, index, stored)
        last = dr.gather(mi.UInt32, self.last, index, stored)
        iteration, last_large, large = self.iteration, self.last_large, self.large
        # a large step accepted since the number was last brought up to date: a fresh start there
        stale = last < last_large
        u = dr.select(stale, uniform(self.catch_up_keys, dim), u)
        last = dr.maximum(last, last_large)
        xi = uniform(self.mutate_keys, dim)
        spread = self.sigma * dr.sqrt(mi.Float(iteration - last))
        value = dr.select(large, xi, wrap(u + spread * math.sqrt(2.0) * dr.erfinv(2.0 * xi - 1.0)))
        dr.scatter(self.proposal, value, index, stored)
        dr.scatter(self.stamps, self.stamp, index, stored)
        return value


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
    """Per chain: summed acceptance probabilities, accepted proposals, large steps, the
    acceptance summed over large steps, and steps taken (Float arrays of ``chains``)."""
    acceptance: object = None
    accepted: object = None
    large: object = None
    large_acceptance: object = None
    taken: object = None

    @classmethod
    def zeros(cls, n: int) -> "ChainCounts":
        return cls(*(dr.zeros(mi.Float, n) for _ in range(5)))

    def arrays(self) -> tuple:
        return self.acceptance, self.accepted, self.large, self.large_acceptance, self.taken


@dataclass
class MarkovChains:
    """``chains`` Metropolis-Hastings chains in lock-step on [0, 1)^dims (see the module docstring).

    ``u`` (flat, index d * chains + c), ``value`` (I of each chain's current state, > 0) and
    ``payload`` (a tuple of Dr.Jit arrays of width ``chains``) are set by ``start``. ``lazy``
    (the normal small step only: Kelemen's exponential one is always eager): steps mutate only
    the numbers a path reads (``LazyProposal``), with the counters ``iteration``, ``last_large``
    and ``last`` and the buffers ``proposal`` and ``stamps`` (chains x dims x 16 bytes in all)."""
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
    lazy: bool = True

    def __post_init__(self):
        if self.small_step not in MLT_SMALL_STEPS:
            raise ValueError(f"small_step must be one of {', '.join(MLT_SMALL_STEPS)}, got {self.small_step!r}")
        self.lazy = self.lazy and self.small_step == "normal" and self.dims > 0
        self.counts = ChainCounts.zeros(self.chains)
        self.lane = dr.arange(mi.UInt32, self.chains)
        self.flat = dr.arange(mi.UInt32, self.chains * self.dims)
        # (the lazy steps' counters: accepted iterations, the last accepted large step's, and per number)
        self.iteration = dr.zeros(mi.UInt32, self.chains)
        self.last_large = dr.zeros(mi.UInt32, self.chains)
        self.last = dr.zeros(mi.UInt32, self.chains * self.dims) if self.lazy else None
        if self.lazy:
            self.proposal = dr.zeros(mi.Float, self.chains * self.dims)
            self.stamps = dr.zeros(mi.UInt32, self.chains * self.dims)

    # -- start ------------------------------------------------------------------------

    def start(self, boot_keys, boot_values: np.ndarray, boot_value, boot_payload: tuple,
              sort: bool = False) -> np.ndarray:
        """Each chain starts from a bootstrap sample drawn in proportion to its I (``resample``):
        its primary sample read again from its key (``uniform(key, d)``), its I and payload
        gathered. The bootstrap's total I must be > 0. Returns the drawn indices; ``sort`` hands
        them to the chains in increasing order (the draws are independent of the chains' keys, so
        the order changes no chain's distribution, only which lanes run side by side)."""
        xi = np.array(uniform(key_of(self.key, P_START), self.lane), dtype=np.float64)
        drawn = resample(boot_values, xi)
        index = mi.UInt32(np.sort(drawn) if sort else drawn)
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

    def step_index(self):
        """This step's number as an opaque UInt32 (one kernel for every step)."""
        return dr.opaque(mi.UInt32, self.steps)

    def step_key(self, index):
        """The key of the step numbered ``index`` (a UInt32, ``step_index``)."""
        return key_of(self.key, P_STEP, index)

    def tail_keys(self, key):
        """Per chain, the key of the unstored dimensions' numbers of this step's proposal."""
        return key_of(key, P_TAIL, self.lane)

    def propose(self, key, index):
        """(samples, large): the proposal of step ``index`` as ``PrimarySamples`` for ``evaluate``
        and which chains take a large step. Eager: every stored number moved here
        (``eager_proposal``); lazy: as the path reads them (``LazyProposal``)."""
        large = self.large_steps(key)
        if not self.lazy:
            return self.samples(self.eager_proposal(key, large), key), large
        lazy = LazyProposal(self.chains, self.sigma, key, self.iteration + 1, self.last_large, large, self.last,
                            self.proposal, self.stamps, index + 1)
        return PrimarySamples(self.chains, self.tail_keys(key), self.u, self.dims, lazy), large

    def large_steps(self, key):
        """Which chains take a large step (Bool per chain)."""
        return uniform(key_of(key, P_LARGE), self.lane) < self.large_step

    def eager_proposal(self, key, large=None):
        """Every stored number of every chain moved: afresh (large step) or perturbed (flat, like
        ``u``). ``large``: ``large_steps(key)`` where the caller has it (gathered per number, not
        drawn again: the same decisions)."""
        if not self.dims:
            return self.u
        chain = self.flat % self.chains
        if large is None:
            large_here = uniform(key_of(key, P_LARGE), chain) < self.large_step
        else:
            large_here = dr.gather(mi.Bool, large, chain)
        xi = uniform(key_of(key, P_MUTATE), self.flat)
        return dr.select(large_here, xi, perturb(self.u, xi, self.small_step, self.sigma))

    def samples(self, v, key) -> PrimarySamples:
        """The eager proposal ``v`` (flat) as ``PrimarySamples``."""
        return PrimarySamples(self.chains, self.tail_keys(key), v, self.dims)

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

    def accept(self, key, samples: PrimarySamples, value, payload: tuple, a, large, active=None) -> None:
        """Each chain moves to its proposal with probability ``a`` (``a`` is 0 where ``active``,
        a Bool per chain, is false: those chains take no step, and count none)."""
        xi = uniform(key_of(key, P_ACCEPT), self.lane)
        moves = xi < a
        if active is not None:
            large = large & active
        if self.dims:
            # (the chain's coin gathered, not drawn again per number: one hash per chain, not per number)
            chain = self.flat % self.chains
            moves_here = dr.gather(mi.Bool, moves, chain)
            if samples.lazy is not None:             # the numbers its path read
                moves_here &= self.stamps == samples.lazy.stamp
                self.u = dr.select(moves_here, self.proposal, self.u)
            else:                                    # every number
                self.u = dr.select(moves_here, samples.state, self.u)
            if self.lazy:                            # (read by the lazy steps only)
                next_iteration = dr.gather(mi.UInt32, self.iteration, chain) + 1
                self.last = dr.select(moves_here, next_iteration, self.last)
        self.iteration = dr.select(moves, self.iteration + 1, self.iteration)
        self.last_large = dr.select(moves & large, self.iteration, self.last_large)
        self.value = dr.select(moves, value, self.value)
        self.payload = tuple(dr.select(moves, p, q) for p, q in zip(payload, self.payload))
        c = self.counts
        c.acceptance = c.acceptance + a
        c.accepted = c.accepted + dr.select(moves, 1.0, 0.0)
        c.large = c.large + dr.select(large, 1.0, 0.0)
        c.large_acceptance = c.large_acceptance + dr.select(large, a, 0.0)
        c.taken = c.taken + (1.0 if active is None else dr.select(active, 1.0, 0.0))
        self.steps += 1

    def arrays(self) -> tuple:
        last = () if self.last is None else (self.last,)
        return (self.u, self.value, *self.payload, *self.counts.arrays(), self.iteration, self.last_large, *last)

    #: Every attribute holding Dr.Jit arrays that a step reads or writes (``frozen.FrozenRounds``).
    STATE = ("key", "u", "value", "payload", "counts", "lane", "flat", "iteration", "last_large", "last",
             "proposal", "stamps")

    def state(self) -> dict:
        return {name: getattr(self, name, None) for name in self.STATE}

    def set_state(self, state: dict) -> None:
        for name, value in state.items():
            setattr(self, name, value)


def run(chains: MarkovChains, steps: int, evaluate, splat, proposal=None, checkpoint=None) -> None:
    """``steps`` steps of every chain (``step``); ``checkpoint()`` runs after each."""
    for _ in range(steps):
        step(chains, evaluate, splat, proposal)
        if checkpoint is not None:
            checkpoint()


def step(chains: MarkovChains, evaluate, splat, proposal=None, active=None, index=None) -> None:
    """One step of the chains in lock-step: propose, ``evaluate(samples, active)`` -> (I, payload) of
    the proposal (``samples``: ``PrimarySamples``; ``active`` None or a Bool per chain), splat the
    current (``splat(payload, (1 - a) / I(u))``) and the proposal (``splat(payload, a / I(v))``),
    accept. ``proposal(chains, key)`` -> (v, large, q_ratio), v flat like ``chains.u``, replaces
    the lab's symmetric steps (a test's non-symmetric proposal). ``active`` (a Bool per chain):
    the chains that take this step; the others splat nothing and stay as they are (a partial
    step: ``run_mutations``). ``index``: the step's number as a UInt32 (default: ``step_index``).
    Dr.Jit evaluates the state (and the splats) once per step."""
    index = chains.step_index() if index is None else index
    key = chains.step_key(index)
    if proposal is None:
        samples, large = chains.propose(key, index)
        q_ratio = None
    else:
        v, large, q_ratio = proposal(chains, key)
        samples = chains.samples(v, key)
    value, payload = evaluate(samples) if active is None else evaluate(samples, active)
    a, w_current, w_proposal = chains.weigh(value, q_ratio)
    if active is not None:
        a, w_current, w_proposal = (dr.select(active, x, 0.0) for x in (a, w_current, w_proposal))
    dr.eval(value, *payload, a, w_current, w_proposal)    # (the proposal traced once)
    splat(chains.payload, w_current)
    splat(payload, w_proposal)
    chains.accept(key, samples, value, payload, a, large, active)
    dr.eval(*chains.arrays())


def rounds(start: int, count: int, chains: int) -> list[tuple[int, int]]:
    """The lock-step rounds that make mutations start .. start + count - 1 of a render whose
    mutation k is a step of chain k mod ``chains``: [(first lane, end lane)] per round, a round
    stepping lanes first <= c < end. Only the first and the last round may be partial, so a
    render continued over several passes advances its chains in turn, each at most one step
    ahead of another."""
    out, k, end = [], start, start + count
    while k < end:
        lane = k % chains
        stop = min(chains, lane + end - k)
        out.append((lane, stop))
        k += stop - lane
    return out


def run_mutations(chains: MarkovChains, start: int, count: int, evaluate, splat, checkpoint=None,
                  full_step=None) -> None:
    """Mutations start .. start + count - 1 (``rounds``): full rounds step every chain
    (``step``, or ``full_step()`` where given: ``frozen.FrozenRounds``), a partial one the lanes
    of its range only (``active``)."""
    for first, stop in rounds(start, count, chains.chains):
        if (first, stop) == (0, chains.chains) and full_step is not None:
            full_step()
        elif (first, stop) == (0, chains.chains):
            step(chains, evaluate, splat)
        else:
            # (opaque: the bounds change from pass to pass, the kernels do not)
            active = (chains.lane >= dr.opaque(mi.UInt32, first)) & (chains.lane < dr.opaque(mi.UInt32, stop))
            step(chains, evaluate, splat, active=active)
        if checkpoint is not None:
            checkpoint()


def quantiles(values, qs=(0.05, 0.5, 0.95)) -> list[float]:
    values = np.asarray(values, dtype=np.float64)
    return [float(np.quantile(values, q)) for q in qs] if len(values) else [float("nan")] * len(qs)
