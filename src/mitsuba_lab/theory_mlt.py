"""Problem 8 of :mod:`mitsuba_lab.theory`: a Metropolis-Hastings chain on a two-peaked target,
the walk Metropolis light transport takes through primary sample space, in one dimension.

The target f on the circle [0, 1) has two Gaussian peaks (at 0.25 and 0.7, of widths 0.04 and
0.07, the second 0.6 as high). The chain proposes y = x + sigma N(0, 1) wrapped to [0, 1) (a
*small step*, symmetric) or, with probability ``large``, a uniform y (a *large step*, Kelemen et
al. 2002), and accepts with probability min(1, f(y) / f(x)). Predicted by quadrature over a grid
of the circle (the kernel as a matrix, its rejected mass on the diagonal):

* the acceptance rate E_pi[ integral q(y | x) min(1, f(y) / f(x)) dy ] against the step size;
* the variance of the mean of g over N steps of a chain started in its stationary law,
  Var_pi(g) / N x tau_N, with tau_N = 1 + 2 sum_{k<N} (1 - k/N) rho_k (rho_k: the chain's
  autocorrelation of g at lag k, from powers of the kernel): the variance inflation that
  correlated samples cost against independent ones (tau -> the integrated autocorrelation time).
  g is the indicator of the first peak's half [0, 1/2): small steps rarely cross between the
  peaks, so g's correlation is long; large steps cut it.

:mod:`mitsuba_lab.theory` measures them with many independent chains (``run_all``). Pure numpy.
"""
from __future__ import annotations

import numpy as np

from . import metrics
from .theory_rows import TOL_SE, mean_row, row

__all__ = ["p8_target", "p8_kernel", "p8_predicted", "run_chains", "problem8"]

P8_PEAKS = ((0.25, 0.04, 1.0), (0.7, 0.07, 0.6))      # (centre, width, height)
#: Small-step sizes whose acceptance rate is predicted and measured.
P8_SIGMAS = (0.01, 0.05, 0.2, 0.5)
#: (sigma, large-step probability) of the variance-inflation rows.
P8_MIXING = ((0.05, 0.0), (0.05, 0.3))
#: Steps per chain.
P8_STEPS = 400
#: Cells of the quadrature grid.
P8_GRID = 500


def _circle_distance(x, c):
    d = np.abs(np.asarray(x, float) - c) % 1.0
    return np.minimum(d, 1.0 - d)


def p8_target(x):
    """The unnormalised target f(x): two Gaussian bumps on the circle."""
    return sum(h * np.exp(-0.5 * (_circle_distance(x, c) / w) ** 2) for c, w, h in P8_PEAKS)


def _wrapped_normal(d, sigma):
    """The density of sigma N(0, 1) wrapped to the circle, at offsets ``d``."""
    d = np.asarray(d, float)
    total = np.zeros_like(d)
    for k in range(-3, 4):
        total += np.exp(-0.5 * ((d + k) / sigma) ** 2)
    return total / (sigma * np.sqrt(2 * np.pi))


def p8_kernel(sigma: float, large: float, cells: int = P8_GRID):
    """(x, pi, P): the grid's cell centres, the target's probabilities there, and the chain's
    transition matrix (row i: from cell i), its rejected mass on the diagonal."""
    x = (np.arange(cells) + 0.5) / cells
    f = p8_target(x)
    pi = f / f.sum()
    proposal = (1 - large) * _wrapped_normal(x[None, :] - x[:, None], sigma) / cells + large / cells
    accept = np.minimum(1.0, f[None, :] / f[:, None])
    P = proposal * accept
    np.fill_diagonal(P, 0.0)
    P[np.diag_indices(cells)] = 1.0 - P.sum(axis=1)
    return x, pi, P


def p8_predicted(sigma: float, large: float = 0.0, steps: int = P8_STEPS, cells: int = P8_GRID) -> dict:
    """Predicted acceptance rate, E_pi[g], Var_pi(g) and tau_N for ``steps`` steps."""
    x, pi, P = p8_kernel(sigma, large, cells)
    # accepted: every move to another cell, and a proposal of the same cell (on the diagonal)
    proposal_same = (1 - large) * _wrapped_normal(np.zeros(1), sigma)[0] / cells + large / cells
    acceptance = float(pi @ (1.0 - np.diag(P))) + proposal_same
    g = (x < 0.5).astype(float)
    mean = float(pi @ g)
    variance = mean * (1.0 - mean)
    centred = g - mean
    tau, v = 1.0, centred.copy()
    for k in range(1, steps):
        v = P @ v
        rho = float(pi @ (centred * v)) / variance
        tau += 2.0 * (1.0 - k / steps) * rho
    return {"acceptance": acceptance, "mean_g": mean, "var_g": variance, "tau": tau}


def _sample_target(rng, n: int) -> np.ndarray:
    """``n`` exact draws from the normalised target (rejection from the uniform: f <= 1.1)."""
    out = np.empty(0)
    bound = 1.1
    while out.size < n:
        x = rng.random(2 * n)
        out = np.concatenate([out, x[rng.random(2 * n) * bound < p8_target(x)]])
    return out[:n]


def run_chains(rng, chains: int, steps: int, sigma: float, large: float = 0.0):
    """(acceptance rate per chain, mean of g per chain) of ``chains`` independent chains of
    ``steps`` steps each, started from exact draws of the target."""
    x = _sample_target(rng, chains)
    f = p8_target(x)
    accepted = np.zeros(chains)
    g_sum = np.zeros(chains)
    for _ in range(steps):
        big = rng.random(chains) < large
        y = np.where(big, rng.random(chains), (x + sigma * rng.standard_normal(chains)) % 1.0)
        fy = p8_target(y)
        move = rng.random(chains) * f < fy
        x = np.where(move, y, x)
        f = np.where(move, fy, f)
        accepted += move
        g_sum += x < 0.5
    return accepted / steps, g_sum / steps


def problem8(rng, n):
    chains = n["p8"]
    steps = P8_STEPS
    note = f"two peaks on [0,1), {chains} chains x {steps} steps from the target, tol {TOL_SE:g} SE"
    rows = []
    for sigma in P8_SIGMAS:
        rates, _ = run_chains(rng, chains, steps, sigma)
        rows.append(mean_row("P8", f"acceptance_sigma{sigma:g}", p8_predicted(sigma, steps=1)["acceptance"], rates,
                             note))
    for sigma, large in P8_MIXING:
        pred = p8_predicted(sigma, large, steps)
        _, means = run_chains(rng, chains, steps, sigma, large)
        inflation = steps * metrics.mc_variance(means) / pred["var_g"]
        se = steps * metrics.variance_standard_error(means) / pred["var_g"]
        rows.append(mean_row("P8", f"mean_g_sigma{sigma:g}_large{large:g}", pred["mean_g"], means, note))
        rows.append(row("P8", f"tau_N_sigma{sigma:g}_large{large:g}", pred["tau"], inflation, TOL_SE * se,
                        note + "; Var(chain mean) x N / Var_pi(g)"))
    return rows
