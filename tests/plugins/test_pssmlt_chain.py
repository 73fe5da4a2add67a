"""lab_pssmlt's Markov chains (plugins/integrators/mlt/chain.py) on a 2D toy target with a known
integral, driven through the same code the integrator runs: ``chain.run`` with the bootstrap start,
the lab's steps, the acceptance and expected-value splatting; only ``evaluate`` (the toy target
instead of a path) and ``splat`` (a histogram instead of a film) are the test's.

The target on the unit torus: I(x, y) = 0.1 + exp(-|(x, y) - (0.3, 0.6)|^2 / (2 0.08^2)), integral
known in closed form, also per bin of an 8 x 8 histogram. Each chain's histogram (b / steps times
its splats per bin, b the exact integral) is one replicate: chains are independent (apart from
sharing a 2^16-path bootstrap, whose start bias is O(1/2^16), far below the resolution), so the
mean over 4096 chains is compared with the exact bin integrals by a chi-squared test with the
covariance estimated over the chains (Hotelling's T^2 over 63 bins, the 64th being determined by
the others), correlations along each chain included. Fixed seeds; a correct kernel fails with
probability 1e-3 (the p-value bound). Power: a non-symmetric step (an independence proposal of
density 2x) with its proposal density left out of the acceptance fails with p < 1e-9; with the
density in, it passes.

Measured (seed 11, 48 steps): T^2 83.0 (lazy normal steps, p 0.046), 57.7 (eager exponential, p
0.66), 72.2 (small steps alone, p 0.20), 60.8 (y unstored, p 0.56), 79.8 and 78.7 (y read from number 1
or 2 by x, so the lazy steps skip and catch up numbers; p 0.075 and 0.088), 52.8 (the same, eager
exponential, p 0.82), 58.1 (the non-symmetric step with its density, p 0.65) over 63 bins; without the
density 17551 (p 0). Eager normal steps (the plugins'): 74.8 (p 0.15), switching 65.9 (p 0.38), and
with number 2 unstored 71.3 (p 0.22). Over seeds 1-8 the switching case's T^2 averaged 63.5 lazy and 65.9 eager (63
expected). The per-bin relative standard error of the mean over the chains is 2.2% to 4.0%.
"""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from scipy import stats

from mitsuba_lab.plugins.integrators.mlt import chain

CENTRE, WIDTH, FLOOR = (0.3, 0.6), 0.08, 0.1
BINS = 8
CHAINS, STEPS, BOOTSTRAP = 4096, 48, 1 << 16
P_BOUND = 1e-3


def _gauss_integral(a, b, m):
    s = WIDTH * math.sqrt(2.0)
    return WIDTH * math.sqrt(math.pi / 2.0) * (math.erf((b - m) / s) - math.erf((a - m) / s))


def exact_bins() -> np.ndarray:
    edges = np.linspace(0.0, 1.0, BINS + 1)
    gx = np.array([_gauss_integral(edges[i], edges[i + 1], CENTRE[0]) for i in range(BINS)])
    gy = np.array([_gauss_integral(edges[i], edges[i + 1], CENTRE[1]) for i in range(BINS)])
    return FLOOR / BINS ** 2 + np.outer(gy, gx)              # [y bin, x bin]


EXACT = exact_bins()
B = float(EXACT.sum())


def target(x, y):
    return FLOOR + dr.exp(-((x - CENTRE[0]) ** 2 + (y - CENTRE[1]) ** 2) / (2.0 * WIDTH ** 2))


def toy_evaluate(samples: chain.PrimarySamples, switch: bool = False):
    """(I, payload) of each lane's primary sample: the toy target at its first two numbers; the
    payload is (f, position) with f = I (a scalar target, as a grey image's luminance). With
    ``switch``, y is number 1 where x < 1/2 and number 2 elsewhere: a chain reads one of them per
    step, as a path reads more or fewer numbers, so the lazy steps skip and catch up numbers."""
    x = samples.get(0)
    y = samples.get(dr.select(x < 0.5, mi.UInt32(1), mi.UInt32(2)) if switch else 1)
    value = target(x, y)
    return value, (value, mi.Point2f(x, y))


def run_toy(seed: int, small_step="normal", sigma=0.03, large_step=0.3, dims=3, proposal=None, switch=False,
            lazy=True):
    """Per-chain histograms (chains, BINS, BINS) of b_exact x splats / steps, and b_hat. ``lazy``
    False: the normal steps made eagerly, as the plugins make them."""
    key = chain.seed_key(seed)
    boot_keys = chain.key_of(key, chain.P_BOOTSTRAP, dr.arange(mi.UInt32, BOOTSTRAP))
    boot_value, boot_payload = toy_evaluate(chain.PrimarySamples(BOOTSTRAP, boot_keys), switch)
    values = np.array(boot_value, dtype=np.float64)
    b_hat, b_se = chain.normaliser(values)
    chains = chain.MarkovChains(CHAINS, dims, key, large_step, small_step, sigma, lazy=lazy)
    chains.start(boot_keys, values, boot_value, boot_payload)
    histogram = dr.zeros(mi.Float, CHAINS * BINS * BINS)
    lane = dr.arange(mi.UInt32, CHAINS)

    def splat(payload, weight):
        f, p = payload
        cell = (mi.UInt32(dr.minimum(p.y * BINS, BINS - 1)) * BINS + mi.UInt32(dr.minimum(p.x * BINS, BINS - 1)))
        dr.scatter_reduce(dr.ReduceOp.Add, histogram, f * weight, lane * (BINS * BINS) + cell)

    chain.run(chains, STEPS, lambda samples: toy_evaluate(samples, switch), splat, proposal=proposal)
    per_chain = np.array(histogram, dtype=np.float64).reshape(CHAINS, BINS, BINS) * B / STEPS
    return per_chain, b_hat, b_se, chains


def chi_squared(per_chain: np.ndarray) -> tuple[float, float]:
    """(T^2, p-value) of the chains' mean histogram against the exact one: Hotelling's T^2 over
    the first BINS^2 - 1 bins with the covariance over chains, referred to chi-squared."""
    flat = per_chain.reshape(len(per_chain), -1)[:, :-1]
    d = flat.mean(axis=0) - EXACT.reshape(-1)[:-1]
    cov = np.cov(flat, rowvar=False) / len(flat)
    t2 = float(d @ np.linalg.solve(cov, d))
    return t2, float(stats.chi2.sf(t2, flat.shape[1]))


@pytest.mark.parametrize("case", [
    {"small_step": "normal"},
    {"small_step": "exponential"},
    {"small_step": "normal", "large_step": 0.0},              # small steps alone (they wrap)
    {"small_step": "normal", "dims": 1},                      # y unstored: drawn afresh each step
    {"small_step": "normal", "switch": True},                 # lazy steps skip numbers and catch up
    {"small_step": "normal", "switch": True, "dims": 2},      # ... and number 2 unstored
    {"small_step": "exponential", "switch": True},            # (eager)
    {"small_step": "normal", "lazy": False},                  # eager normal steps (the plugins')
    {"small_step": "normal", "lazy": False, "switch": True},
    {"small_step": "normal", "lazy": False, "switch": True, "dims": 2},
])
def test_the_chains_leave_the_toy_target_invariant(case):
    per_chain, b_hat, b_se, chains = run_toy(11, **case)
    t2, p = chi_squared(per_chain)
    acceptance = float(np.array(chains.counts.acceptance).sum()) / (CHAINS * STEPS)
    print(f"{case}: T^2 {t2:.1f} over {BINS * BINS - 1} bins, p {p:.3g}; acceptance {acceptance:.3f}; "
          f"b {b_hat:.5f} +- {b_se:.5f} (exact {B:.5f})")
    assert p > P_BOUND, (t2, p)
    assert abs(b_hat - B) < 4.0 * b_se


def test_bootstrap_normaliser_is_the_integral():
    """b_hat over 2^16 uniform samples of the toy: within 4 standard errors of the exact integral."""
    _, b_hat, b_se, _ = run_toy(5, large_step=1.0)
    assert abs(b_hat - B) < 4.0 * b_se and b_se < 0.01 * B


def _independence_proposal(with_density: bool):
    """Half the chains (a coin per chain and step) propose from the lab's steps, the others from
    an independence proposal of density g(x) = 2x in x (uniform in every other number), whose
    q(v -> u) / q(u -> v) = g(u_x) / g(v_x) the acceptance needs; ``with_density`` False leaves it
    out (the deliberate error)."""
    def proposal(chains: chain.MarkovChains, key):
        v_lab, large = chains.eager_proposal(key), chains.large_steps(key)   # (the lab's steps, eagerly)
        lane, flat = chains.lane, chains.flat
        xi = chain.uniform(chain.key_of(key, 0x1234567), flat)
        first = flat < chains.chains                         # dimension 0 of every chain
        v_ind = dr.select(first, dr.sqrt(xi), xi)
        use = chain.uniform(chain.key_of(key, 0x7654321), flat % chains.chains) < 0.5
        v = dr.select(use, v_ind, v_lab)
        use_lane = chain.uniform(chain.key_of(key, 0x7654321), lane) < 0.5
        u_x, v_x = dr.gather(mi.Float, chains.u, lane), dr.gather(mi.Float, v, lane)
        q_ratio = dr.select(use_lane, u_x / v_x, 1.0) if with_density else None
        return v, large & ~use_lane, q_ratio
    return proposal


def test_a_non_symmetric_step_needs_its_proposal_density():
    per_chain, *_ = run_toy(23, proposal=_independence_proposal(True))
    t2, p = chi_squared(per_chain)
    print(f"independence step with q ratio: T^2 {t2:.1f}, p {p:.3g}")
    assert p > P_BOUND, (t2, p)


def test_leaving_out_the_proposal_density_fails_the_chi_squared_test():
    """Power: the same non-symmetric step with q(v -> u) / q(u -> v) dropped from the acceptance."""
    per_chain, *_ = run_toy(23, proposal=_independence_proposal(False))
    t2, p = chi_squared(per_chain)
    print(f"independence step without q ratio: T^2 {t2:.1f}, p {p:.3g}")
    assert p < 1e-9, (t2, p)
