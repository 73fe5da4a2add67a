"""Eight worked Monte Carlo problems (toy estimators), with their analytic predictions.

Each problem predicts a number before measuring it: (1) an RMSE from a single-sample
variance and its N^-1/2 law, (2) the variance reduction of importance sampling,
(3) a zero-variance cosine estimator, (4) MIS weights and the MIS gain (Veach 1997,
ch. 9), (5) the cost of Russian roulette, (6) transmittance through a heterogeneous
medium by delta tracking and by ratio tracking (means, variances, density look-ups),
(7) single scattering from a point light along a ray in a thin medium by distance
sampling, equi-angular sampling (Kulla and Fajardo 2012) and their MIS (both in
:mod:`mitsuba_lab.theory_media`), (8) a Metropolis-Hastings chain on a two-peaked target:
acceptance rate against step size and the variance inflation of correlated samples
(:mod:`mitsuba_lab.theory_mlt`; rows in :mod:`mitsuba_lab.theory_rows`). This module derives the
predictions, runs the estimators with numpy (fixed seeds), measures them
through :mod:`mitsuba_lab.metrics` so the same metric code the renderer
experiments use is exercised, and reports both side by side::

    rows = run_all(seed=0, quick=True)
    print(format_table(rows))
    assert not check(rows)

Every row carries a tolerance derived from the measurement's own standard
error (``TOL_SE`` of them) or, for exact identities, from floating-point
rounding. The MIS weights are the lab's own (``mis_weights``). Pure numpy: no
Mitsuba or Dr.Jit import.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from . import metrics
from .theory_media import problem6, problem7
from .theory_mlt import problem8
from .theory_rows import FP_TOL, TOL_SE
from .theory_rows import mean_row as _mean_row
from .theory_rows import ratio_row as _ratio_row
from .theory_rows import rmse_row as _rmse_row
from .theory_rows import row as _row
from .theory_rows import variance_row as _variance_row
from .plugins.integrators.common.mis_weight import mis_weight

__all__ = [
    "mis_weights",
    "p1_sigma2",
    "p2_variances",
    "p3_uniform_variance",
    "p4_densities_at",
    "p4_true_value",
    "p4_predicted_variances",
    "rr_added_variance",
    "rr_expected_extra_bounces",
    "sample_uniform_hemisphere",
    "sample_cosine_hemisphere",
    "run_all",
    "check",
    "format_table",
]

# Largest temporary array, in float64 elements (2**21 = 16 MB), so even the
# 4000 x 65536 trial matrix of Problem 1 never needs more than ~100 MB.
CHUNK_ELEMENTS = 1 << 21

# Trials per problem by default, and ~10x fewer when quick.
_DEFAULT = dict(p1=4000, p2=4000, p3=100_000, p4=3000, p5=2_000_000, p6=1_000_000, p7=1_000_000,
                p8=4000, var=1_000_000)
_QUICK = dict(p1=400, p2=400, p3=100_000, p4=1000, p5=200_000, p6=100_000, p7=100_000, p8=1000,
              var=100_000)


# --------------------------------------------------------------------------
# Multiple importance sampling weights
# --------------------------------------------------------------------------
def mis_weights(p_a, p_b, heuristic: str = "balance", beta: float = 2.0,
                n_a: int = 1, n_b: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """MIS weights ``(w_a, w_b)`` for two techniques taking ``n_a``, ``n_b`` samples.

    The lab's one MIS weight (``mitsuba_lab.plugins.integrators.common.mis_weight``, the formula
    ``lab_mis`` traces into its kernels) applied to ``a = n_a p_a`` and ``b = n_b p_b``
    (Veach 1997, ch. 9): ``'balance'`` ``a / (a + b)``; ``'power'`` ``a^beta / (a^beta + b^beta)``;
    ``'max'`` 1 for the larger, 1/2 on ties; ``'average'`` 1/2 each wherever both densities are
    positive (the plain average of the two estimators, whatever ``n_a`` and ``n_b``). A technique
    with zero density gets weight 0, the other one 1; both zero gives ``(0, 0)``; weights are
    never NaN and sum to 1 wherever either density is positive. Densities must be >= 0 and not
    NaN; both are scaled by ``1 / max(n_a, n_b)``, which keeps their ratio and cannot overflow.
    """
    p_a, p_b = np.broadcast_arrays(np.asarray(p_a, float), np.asarray(p_b, float))
    if np.any(~(p_a >= 0)) or np.any(~(p_b >= 0)):
        raise ValueError("pdfs must be non-negative and not NaN")
    n_max = max(n_a, n_b)
    a, b = p_a * (n_a / n_max), p_b * (n_b / n_max)
    return mis_weight(a, b, heuristic, beta), mis_weight(b, a, heuristic, beta)


# --------------------------------------------------------------------------
# Analytic predictions
# --------------------------------------------------------------------------
def p1_sigma2() -> float:
    """Problem 1: ``Var[e^X]``, X ~ U[0,1]: ``(e^2 - 1)/2 - (e - 1)^2 = 0.24204``."""
    return (math.e**2 - 1) / 2 - (math.e - 1) ** 2


def _p2_truth() -> float:
    return (1 - math.exp(-8)) / 8  # int_0^1 e^{-8x} dx = 0.1249581


def _p2_normaliser() -> float:
    return (1 - math.exp(-6)) / 6  # Z of p(x) = e^{-6x} / Z on [0,1] = 0.165638


def p2_variances() -> tuple[float, float]:
    """Problem 2 single-sample variances for ``int_0^1 e^{-8x} dx``.

    Uniform: ``(1 - e^{-16})/16 - I^2 = 0.046885``. Importance sampling with
    ``p ~ e^{-6x}``: ``f/p = Z e^{-2x}``, so ``Z (1 - e^{-10})/10 - I^2 =
    1.010e-3``; the RMSE ratio is ``sqrt(0.046885 / 0.001010) = 6.81``.
    """
    truth = _p2_truth()
    uniform = (1 - math.exp(-16)) / 16 - truth**2
    importance = _p2_normaliser() * (1 - math.exp(-10)) / 10 - truth**2
    return uniform, importance


def p3_uniform_variance() -> float:
    """Problem 3: variance of ``2 pi cos(theta)`` with ``cos`` ~ U[0,1]
    (uniform hemisphere): ``4 pi^2 / 3 - pi^2 = pi^2 / 3 = 3.2899``."""
    return math.pi**2 / 3


# Problem 4: p_A = N(0, 0.6^2) ("BRDF"), p_B = N(2, 0.4^2) ("light").
P4_A = (0.0, 0.6)
P4_B = (2.0, 0.4)


def _gaussian_pdf(x, mean: float, sigma: float):
    return np.exp(-0.5 * ((x - mean) / sigma) ** 2) / (sigma * math.sqrt(2 * math.pi))


def p4_densities_at(x):
    """Problem 4 densities ``(p_A(x), p_B(x))``; at x=1: 0.16580 and 0.04382."""
    return _gaussian_pdf(x, *P4_A), _gaussian_pdf(x, *P4_B)


def _p4_integrand(x):
    p_a, p_b = p4_densities_at(x)
    return p_a * p_b


def p4_true_value() -> float:
    """``int p_A p_B dx = N(mu_A - mu_B; 0, s_A^2 + s_B^2) = 0.011818``."""
    (mu_a, s_a), (mu_b, s_b) = P4_A, P4_B
    var = s_a**2 + s_b**2
    return math.exp(-0.5 * (mu_a - mu_b) ** 2 / var) / math.sqrt(2 * math.pi * var)


def p4_predicted_variances(n_total: int) -> dict[str, float]:
    """Variance of each Problem 4 estimator using ``n_total`` samples.

    Single strategy ``i``: ``(int f^2/p_i - I^2) / N``. Multi-sample MIS with
    ``n = N/2`` per technique: ``sum_i (int w_i^2 f^2/p_i - (int w_i f)^2) / n``.
    The integrals are trapezoid sums on a fine grid over ``[-8, 10]``
    (exponentially accurate for these smooth, fast-decaying integrands).
    At N=8192 the RMSEs are 0.00073 (BRDF), 0.00030 (light), 0.00026 (balance).
    """
    x = np.linspace(-8.0, 10.0, 40_001)
    f = _p4_integrand(x)
    p_a, p_b = p4_densities_at(x)
    truth = p4_true_value()

    def second_moment(weight, pdf):
        return np.trapezoid(weight**2 * np.divide(f**2, pdf, out=np.zeros_like(f),
                                                  where=pdf > 0), x)

    ones = np.ones_like(x)
    out = {
        "brdf": (second_moment(ones, p_a) - truth**2) / n_total,
        "light": (second_moment(ones, p_b) - truth**2) / n_total,
    }
    n_each = n_total // 2
    for heuristic in ("balance", "power"):
        w_a, w_b = mis_weights(p_a, p_b, heuristic)
        var = sum(second_moment(w, p) - np.trapezoid(w * f, x) ** 2
                  for w, p in ((w_a, p_a), (w_b, p_b)))
        out[heuristic] = var / n_each
    return out


def rr_added_variance(value: float, q: float) -> float:
    """Problem 5: Russian roulette on a constant ``X`` adds ``X^2 (1-q)/q``
    (16.67 for X=5, q=0.6)."""
    return value**2 * (1 - q) / q


def rr_expected_extra_bounces(q: float) -> float:
    """Problem 5: surviving bounces under constant survival ``q`` are geometric,
    mean ``q/(1-q)`` (1.5 for q=0.6); the continuation length counting the
    current bounce is ``1/(1-q)``."""
    return q / (1 - q)


# --------------------------------------------------------------------------
# Samplers and estimators
# --------------------------------------------------------------------------
def _trial_estimates(estimate: Callable, rng, n_trials: int, n_samples: int) -> np.ndarray:
    """``n_trials`` independent ``estimate(rng, k, n_samples)`` results, computed
    ``k`` trials at a time so no temporary exceeds ``CHUNK_ELEMENTS``."""
    per_chunk = max(1, CHUNK_ELEMENTS // n_samples)
    chunks = [estimate(rng, min(per_chunk, n_trials - start), n_samples)
              for start in range(0, n_trials, per_chunk)]
    return np.concatenate(chunks)


def _p1_estimate(rng, k, n):
    return np.exp(rng.random((k, n))).mean(axis=1)


def _p2_uniform_values(rng, shape):
    return np.exp(-8.0 * rng.random(shape))


def _p2_importance_values(rng, shape):
    # Inverse CDF of the truncated exponential p(x) = e^{-6x}/Z on [0,1].
    x = -np.log1p(-rng.random(shape) * (1 - math.exp(-6))) / 6
    pdf = np.exp(-6 * x) / _p2_normaliser()
    return np.exp(-8 * x) / pdf


def sample_uniform_hemisphere(rng, n: int) -> np.ndarray:
    """``n`` unit vectors uniform on the ``z >= 0`` hemisphere, pdf ``1/(2 pi)``.

    Isotropic Gaussian vectors, normalised, are uniform on the sphere;
    folding ``z`` to ``|z|`` maps that onto the hemisphere. This route is
    independent of the inverse-CDF formula, so it checks it rather than
    restating it.
    """
    v = rng.standard_normal((n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    v[:, 2] = np.abs(v[:, 2])
    return v


def sample_cosine_hemisphere(rng, n: int) -> np.ndarray:
    """``n`` unit vectors with pdf ``cos(theta)/pi`` (Malley's method): a
    uniform point on the unit disk lifted onto the hemisphere."""
    r = np.sqrt(rng.random(n))
    phi = 2 * math.pi * rng.random(n)
    x, y = r * np.cos(phi), r * np.sin(phi)
    z = np.sqrt(np.maximum(0.0, 1.0 - x**2 - y**2))
    return np.stack([x, y, z], axis=1)


def _irradiance_values(directions, pdf):
    """Per-sample ``L_i cos(theta) / p`` for unit incident radiance, normal +z.
    Zero-pdf samples contribute 0 (the integrand vanishes there too)."""
    cos_theta = directions @ np.array([0.0, 0.0, 1.0])
    return np.divide(cos_theta, pdf, out=np.zeros_like(cos_theta), where=pdf > 0)


def _p4_single_estimate(technique):
    mean, sigma = technique

    def estimate(rng, k, n):
        x = rng.normal(mean, sigma, (k, n))
        return (_p4_integrand(x) / _gaussian_pdf(x, mean, sigma)).mean(axis=1)

    return estimate


def _p4_mis_estimate(heuristic):
    """Multi-sample MIS: ``n/2`` samples from each technique, weighted."""

    def estimate(rng, k, n):
        n_each = n // 2
        total = np.zeros(k)
        for which, (mean, sigma) in enumerate((P4_A, P4_B)):
            x = rng.normal(mean, sigma, (k, n_each))
            p_a, p_b = p4_densities_at(x)
            weight = mis_weights(p_a, p_b, heuristic)[which]
            pdf = p_a if which == 0 else p_b
            total += (weight * _p4_integrand(x) / pdf).sum(axis=1) / n_each
        return total

    return estimate


def _russian_roulette(rng, n, value, q):
    """``X/q`` with probability ``q``, else 0."""
    return np.where(rng.random(n) < q, value / q, 0.0)


def _surviving_bounces(rng, n, q):
    """Simulate ``n`` roulette chains bounce by bounce; count survivals."""
    bounces = np.zeros(n, dtype=np.int64)
    alive = np.arange(n)
    while alive.size:
        alive = alive[rng.random(alive.size) < q]
        bounces[alive] += 1
    return bounces


# --------------------------------------------------------------------------
# Rows: prediction vs measurement
# --------------------------------------------------------------------------
def _problem1(rng, n):
    sigma2 = p1_sigma2()
    truth = math.e - 1
    trials = n["p1"]
    note = f"T={trials} trials, tol {TOL_SE:g} SE"
    rows = [_variance_row("P1", "sigma2", sigma2, np.exp(rng.random(n["var"])),
                          f"{n['var']} samples, tol {TOL_SE:g} SE")]
    sizes = [16, 256, 4096, 65536]
    rmse, se = [], []
    for size in sizes:
        est = _trial_estimates(_p1_estimate, rng, trials, size)
        row, r, s = _rmse_row("P1", f"rmse_N{size}", math.sqrt(sigma2 / size), est, truth, note)
        if size in (16, 65536):
            rows.append(row)
        rmse.append(r)
        se.append(s)
    rows.append(_ratio_row("P1", "rmse_ratio_N16/N65536", 64.0,
                           rmse[0], se[0], rmse[-1], se[-1], note))
    rows.append(_slope_row(sizes, rmse, se, note))
    return rows


def _slope_row(sizes, rmse, se, note):
    """Log-log slope of RMSE vs N (predicted -1/2). The slope is linear in the
    log errors, ``sum_i c_i log(rmse_i)``, so its SE is ``sqrt(sum c_i^2 rel_se_i^2)``."""
    slope = metrics.loglog_slope(sizes, rmse)
    log_n = np.log(sizes)
    c = (log_n - log_n.mean()) / np.sum((log_n - log_n.mean()) ** 2)
    slope_se = math.sqrt(np.sum(c**2 * (np.asarray(se) / np.asarray(rmse)) ** 2))
    return _row("P1", "loglog_slope_rmse_vs_N", -0.5, slope, TOL_SE * slope_se,
                note + ", N=16..65536")


def _problem2(rng, n):
    var_u, var_is = p2_variances()
    truth, size, trials = _p2_truth(), 4096, n["p2"]
    note = f"N={size}, T={trials} trials, tol {TOL_SE:g} SE"
    var_note = f"{n['var']} samples, tol {TOL_SE:g} SE"
    rows = [
        _variance_row("P2", "var_uniform", var_u,
                      _p2_uniform_values(rng, n["var"]), var_note),
        _variance_row("P2", "var_importance", var_is,
                      _p2_importance_values(rng, n["var"]), var_note),
    ]
    uniform = _trial_estimates(lambda g, k, m: _p2_uniform_values(g, (k, m)).mean(1),
                               rng, trials, size)
    importance = _trial_estimates(lambda g, k, m: _p2_importance_values(g, (k, m)).mean(1),
                                  rng, trials, size)
    row_u, r_u, se_u = _rmse_row("P2", "rmse_uniform", math.sqrt(var_u / size),
                                 uniform, truth, note)
    row_i, r_i, se_i = _rmse_row("P2", "rmse_importance", math.sqrt(var_is / size),
                                 importance, truth, note)
    rows += [row_u, row_i,
             _ratio_row("P2", "rmse_ratio_uniform/is", math.sqrt(var_u / var_is),
                        r_u, se_u, r_i, se_i, note)]
    return rows


def _problem3(rng, n):
    count = n["p3"]
    note = f"{count} directions, tol {TOL_SE:g} SE"
    fp_note = "exact up to rounding, tol 1e-12 (squared for variances)"
    cos_dirs = sample_cosine_hemisphere(rng, count)
    cos_theta = cos_dirs[:, 2]
    cosine = _irradiance_values(cos_dirs, cos_theta / math.pi)
    uniform = _irradiance_values(sample_uniform_hemisphere(rng, count),
                                 np.full(count, 1 / (2 * math.pi)))
    return [
        _mean_row("P3", "E_cos[cos]", 2 / 3, cos_theta, note),
        _mean_row("P3", "E_cos[cos^2]", 1 / 2, cos_theta**2, note),
        _row("P3", "irradiance_cosine", math.pi, np.mean(cosine), FP_TOL, fp_note),
        _row("P3", "var_cosine", 0.0, metrics.mc_variance(cosine), FP_TOL**2, fp_note),
        _mean_row("P3", "irradiance_uniform", math.pi, uniform, note),
        _variance_row("P3", "var_uniform", p3_uniform_variance(), uniform, note),
    ]


def _problem4(rng, n):
    rows = []
    p_a, p_b = p4_densities_at(1.0)
    for heuristic, beta in (("balance", 1.0), ("power", 2.0)):
        w_a, w_b = mis_weights(p_a, p_b, heuristic)
        exact_a = p_a**beta / (p_a**beta + p_b**beta)  # the textbook formula, directly
        note = "exact up to rounding"
        rows += [_row("P4", f"w_{heuristic}_A(x=1)", exact_a, w_a, FP_TOL, note),
                 _row("P4", f"w_{heuristic}_B(x=1)", 1 - exact_a, w_b, FP_TOL, note)]

    size, trials, truth = 8192, n["p4"], p4_true_value()
    note = f"N={size} (MIS: {size // 2}+{size // 2}), T={trials} trials, tol {TOL_SE:g} SE"
    predicted = p4_predicted_variances(size)
    estimators = {"brdf": _p4_single_estimate(P4_A), "light": _p4_single_estimate(P4_B),
                  "balance": _p4_mis_estimate("balance"), "power": _p4_mis_estimate("power")}
    results = {}
    for name, estimate in estimators.items():
        est = _trial_estimates(estimate, rng, trials, size)
        row, r, s = _rmse_row("P4", f"rmse_{name}", math.sqrt(predicted[name]), est, truth, note)
        rows.append(row)
        results[name] = (est, r, s)
    rows.insert(4, _mean_row("P4", "mean_balance (truth)", truth, results["balance"][0], note))
    _, r_b, se_b = results["balance"]
    _, r_l, se_l = results["light"]
    rows.append(_ratio_row("P4", "rmse_ratio_balance/light",
                           math.sqrt(predicted["balance"] / predicted["light"]),
                           r_b, se_b, r_l, se_l, note))
    return rows


def _problem5(rng, n, value=5.0, q=0.6):
    trials = n["p5"]
    note = f"X={value:g}, q={q:g}, {trials} trials, tol {TOL_SE:g} SE"
    rr = _russian_roulette(rng, trials, value, q)
    bounces = _surviving_bounces(rng, trials, q)
    return [
        _mean_row("P5", "rr_mean", value, rr, note),
        _variance_row("P5", "rr_variance", rr_added_variance(value, q), rr, note),
        _mean_row("P5", "extra_bounces", rr_expected_extra_bounces(q), bounces, note),
    ]


def run_all(seed: int = 0, quick: bool = False) -> list[dict]:
    """Run Problems 1-8 and return one row per predicted quantity.

    Each row is ``{"problem", "quantity", "predicted", "measured",
    "tolerance", "note"}``. Each problem draws from its own child of
    ``SeedSequence(seed)``, so rows are reproducible and independent of
    problem order. ``quick=True`` uses ~10x fewer trials (for
    CI); the default uses the full trial counts (4000, 4000, 1e5,
    3000, 2e6, 1e6, 1e6, 4000 chains), processed in chunks to bound memory.
    """
    counts = _QUICK if quick else _DEFAULT
    problems = (_problem1, _problem2, _problem3, _problem4, _problem5, problem6, problem7, problem8)
    children = np.random.SeedSequence(seed).spawn(len(problems))
    rows = []
    for problem, child in zip(problems, children, strict=True):
        rows += problem(np.random.default_rng(child), counts)
    return rows


def check(rows: list[dict]) -> list[dict]:
    """Rows whose ``|measured - predicted|`` exceeds their ``tolerance`` (NaN fails)."""
    return [row for row in rows
            if not abs(row["measured"] - row["predicted"]) <= row["tolerance"]]


def format_table(rows: list[dict]) -> str:
    """Plain-text table: problem, quantity, predicted, measured, tolerance, ok."""
    failing = {id(row) for row in check(rows)}
    header = ("problem", "quantity", "predicted", "measured", "tolerance", "ok")
    lines = [[row["problem"], row["quantity"], f"{row['predicted']:.6g}",
              f"{row['measured']:.6g}", f"{row['tolerance']:.2g}",
              "no" if id(row) in failing else "yes"] for row in rows]
    widths = [max(len(str(cell)) for cell in column) for column in zip(header, *lines, strict=True)]
    fmt = "  ".join(f"{{:<{w}}}" for w in widths)
    out = [fmt.format(*header), fmt.format(*("-" * w for w in widths))]
    out += [fmt.format(*line) for line in lines]
    return "\n".join(out)
