"""The worked problems of mitsuba_lab.theory: analytic numbers, a quick simulated run, MIS weights.

Analytic values are compared to their known digits (rounded the same way). Simulated rows carry their own tolerances (4 standard errors, see
``theory.TOL_SE``); the run uses seed 0 and ``quick=True``.
"""
import itertools
import math
import warnings

import numpy as np
import pytest

from mitsuba_lab import metrics, theory, theory_media


@pytest.fixture(scope="module")
def quick_rows():
    return theory.run_all(seed=0, quick=True)


def _measured(rows):
    return {row["quantity"]: row["measured"] for row in rows}


# ------------------------------------------------------------- simulated run
@pytest.mark.slow
def test_quick_run_matches_every_prediction(quick_rows):
    failures = theory.check(quick_rows)
    assert failures == [], theory.format_table(failures)


@pytest.mark.slow
def test_rows_are_well_formed(quick_rows):
    keys = {"problem", "quantity", "predicted", "measured", "tolerance", "note"}
    assert {row["problem"] for row in quick_rows} == {"P1", "P2", "P3", "P4", "P5", "P6", "P7", "P8"}
    for row in quick_rows:
        assert set(row) == keys
        assert math.isfinite(row["measured"]) and row["tolerance"] > 0


def test_mis_beats_both_single_strategies(quick_rows):
    m = _measured(quick_rows)
    best_single = min(m["rmse_brdf"], m["rmse_light"])
    assert m["rmse_balance"] < best_single
    assert m["rmse_power"] < best_single


def test_check_flags_out_of_tolerance_and_nan():
    good = {"predicted": 1.0, "measured": 1.05, "tolerance": 0.1}
    bad = {"predicted": 1.0, "measured": 1.2, "tolerance": 0.1}
    nan = {"predicted": 1.0, "measured": math.nan, "tolerance": 0.1}
    assert theory.check([good, bad, nan]) == [bad, nan]


def test_format_table(quick_rows):
    table = theory.format_table(quick_rows)
    assert table.splitlines()[0].split() == ["problem", "quantity", "predicted",
                                             "measured", "tolerance", "ok"]
    assert len(table.splitlines()) == len(quick_rows) + 2
    assert "rmse_N16" in table


def test_chunking_does_not_change_results(monkeypatch):
    # Trials are drawn row by row, so chunk size must not alter the stream.
    def run():
        return theory._trial_estimates(theory._p1_estimate, np.random.default_rng(1), 10, 1000)

    whole = run()
    monkeypatch.setattr(theory, "CHUNK_ELEMENTS", 3000)  # 3 trials per chunk
    np.testing.assert_array_equal(run(), whole)


# -------------------------------------------------- analytic numbers (seed)
def test_problem1_numbers():
    sigma2 = theory.p1_sigma2()
    assert round(sigma2, 5) == 0.24204
    assert round(math.sqrt(sigma2 / 16), 5) == 0.12299
    assert round(math.sqrt(sigma2 / 65536), 6) == 0.001922


def test_problem2_numbers():
    var_u, var_is = theory.p2_variances()
    assert round(var_u, 6) == 0.046885
    assert round(var_is, 6) == 0.001010
    assert round(math.sqrt(var_u / var_is), 2) == 6.81


def test_problem3_numbers():
    assert round(theory.p3_uniform_variance(), 4) == 3.2899


def test_problem4_numbers():
    p_a, p_b = theory.p4_densities_at(1.0)
    assert (round(float(p_a), 5), round(float(p_b), 5)) == (0.16580, 0.04382)
    w_a, w_b = theory.mis_weights(p_a, p_b, "balance")
    assert (round(float(w_a), 4), round(float(w_b), 4)) == (0.7909, 0.2091)
    w_a, w_b = theory.mis_weights(p_a, p_b, "power", beta=2.0)
    assert (round(float(w_a), 4), round(float(w_b), 4)) == (0.9347, 0.0653)
    assert round(theory.p4_true_value(), 6) == 0.011818


def test_problem4_predicted_rmse_ordering():
    rmse = {k: math.sqrt(v) for k, v in theory.p4_predicted_variances(8192).items()}
    assert round(rmse["brdf"], 5) == 0.00073  # the analytic value
    assert rmse["balance"] < rmse["power"] < rmse["light"] < rmse["brdf"]


def test_problem5_numbers():
    assert round(theory.rr_added_variance(5.0, 0.6), 2) == 16.67
    assert theory.rr_expected_extra_bounces(0.6) == pytest.approx(1.5)


def test_problem6_numbers():
    pred = theory_media.p6_predicted()
    assert round(pred["transmittance"], 6) == 0.182684                # exp(-1.7)
    assert round(pred["var_delta"], 6) == 0.149310
    assert round(pred["var_ratio"], 6) == 0.083841
    assert round(pred["lookups_delta"], 3) == 1.179 and pred["lookups_ratio"] == pytest.approx(2.4)
    # The closed forms against brute quadrature of sigma_t on a fine grid.
    x = np.linspace(0.0, theory_media.P6_LENGTH, 400_001)
    sigma = theory_media.p6_sigma_t(x)
    tau = np.trapezoid(sigma, x)
    assert pred["transmittance"] == pytest.approx(math.exp(-tau), rel=1e-9)
    second = math.exp(-np.trapezoid(2 * sigma - sigma**2 / theory_media.P6_MAJORANT, x))
    assert pred["var_ratio"] == pytest.approx(second - math.exp(-2 * tau), rel=1e-8)


def test_poisson_product_identity():
    """E[prod f(x_i)] = exp(-int s (1 - f)) for a Poisson process of rate s, the identity P6's
    predictions rest on, summed directly over the number of points (Poisson weights, exact)."""
    s, length = 1.2, 2.0
    x = np.linspace(0.0, length, 200_001)
    f = (1 - theory_media.p6_sigma_t(x) / s) ** 2                             # ratio tracking's square
    mean_f = np.trapezoid(f, x) / length
    n = np.arange(60)
    poisson = np.exp(-s * length + n * math.log(s * length) - np.array([math.lgamma(k + 1) for k in n]))
    assert np.sum(poisson * mean_f**n) == pytest.approx(math.exp(-np.trapezoid(s * (1 - f), x)), rel=1e-12)


def test_problem7_numbers():
    pred = theory_media.p7_predicted()
    assert round(pred["truth"], 5) == 0.12751
    assert round(pred["var_distance"] / pred["var_equiangular"]) == 465   # equi-angular wins clearly
    assert pred["var_equiangular"] < pred["var_mis"] < pred["var_distance"]
    t = np.linspace(0.0, theory_media.P7_TMAX, 2_000_001)                    # the densities, on a plain grid
    assert np.trapezoid(theory_media.p7_equiangular_pdf(t), t) == pytest.approx(1.0, abs=1e-9)
    escape = math.exp(-theory_media.P7_SIGMA_T * theory_media.P7_TMAX)
    assert np.trapezoid(theory_media.p7_distance_pdf(t), t) == pytest.approx(1 - escape, abs=1e-9)
    assert np.trapezoid(theory_media.p7_integrand(t), t) == pytest.approx(pred["truth"], rel=1e-6)


def test_equiangular_samples_follow_their_density():
    t = theory_media.sample_equiangular(np.random.default_rng(3), 400_000)
    assert t.min() >= 0 and t.max() <= theory_media.P7_TMAX
    edges = np.array([0.0, 1.0, 1.4, 1.5, 1.6, 2.0, theory_media.P7_TMAX])
    grid = np.linspace(0.0, theory_media.P7_TMAX, 400_001)
    cdf = np.concatenate([[0], np.cumsum(np.diff(grid) * 0.5 * (theory_media.p7_equiangular_pdf(grid)[1:] +
                                                                 theory_media.p7_equiangular_pdf(grid)[:-1]))])
    expected = np.diff(np.interp(edges, grid, cdf))
    counts = np.histogram(t, edges)[0] / t.size
    assert np.all(np.abs(counts - expected) <= 4 * np.sqrt(expected * (1 - expected) / t.size))   # 4 SE


def test_media_problems_match_their_predictions():
    """P6 and P7 alone (fast; the whole run is the slow test above)."""
    counts = theory._QUICK
    children = np.random.SeedSequence(0).spawn(7)
    rows = (theory_media.problem6(np.random.default_rng(children[5]), counts) +
            theory_media.problem7(np.random.default_rng(children[6]), counts))
    assert theory.check(rows) == [], theory.format_table(theory.check(rows))
    measured = _measured(rows)
    assert measured["var_ratio"] < measured["var_delta"]                # ratio tracking's gain
    assert measured["lookups_delta"] < measured["lookups_ratio"]       # at more look-ups
    assert measured["var_equiangular"] * 100 < measured["var_distance"]


@pytest.mark.parametrize("sampler", [theory.sample_uniform_hemisphere,
                                     theory.sample_cosine_hemisphere])
def test_hemisphere_samplers_give_upper_unit_vectors(sampler):
    v = sampler(np.random.default_rng(0), 1000)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    assert np.all(v[:, 2] >= 0)


# ------------------------------------------------------------ MIS robustness
EXTREME_PDFS = [0.0, 1e-320, 1e-30, 0.5, 1.0, 1e30, 1e300, math.inf]
HEURISTICS = ["balance", "power", "max", "average"]


@pytest.mark.parametrize("heuristic", HEURISTICS)
def test_mis_weights_never_nan_and_sum_to_one(heuristic):
    pairs = np.array(list(itertools.product(EXTREME_PDFS, repeat=2)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any overflow/invalid warning fails
        w_a, w_b = theory.mis_weights(pairs[:, 0], pairs[:, 1], heuristic, n_a=2, n_b=3)
    assert not np.any(np.isnan(w_a) | np.isnan(w_b))
    assert np.all((w_a >= 0) & (w_a <= 1) & (w_b >= 0) & (w_b <= 1))
    either = (pairs[:, 0] > 0) | (pairs[:, 1] > 0)
    np.testing.assert_allclose((w_a + w_b)[either], 1.0, rtol=1e-12)
    assert np.all(w_a[pairs[:, 0] == 0] == 0) and np.all(w_b[pairs[:, 1] == 0] == 0)


@pytest.mark.parametrize("heuristic", ["balance", "power", "max"])
@pytest.mark.parametrize("finite", [0.0, 1e-30, 1.0, 1e300])
def test_infinite_pdf_takes_all_weight(heuristic, finite):
    w_a, w_b = theory.mis_weights(math.inf, finite, heuristic)
    assert (w_a, w_b) == (1.0, 0.0)
    w_a, w_b = theory.mis_weights(finite, math.inf, heuristic)
    assert (w_a, w_b) == (0.0, 1.0)


def test_mis_weight_formulas():
    p_a, p_b = np.array([0.2, 3.0]), np.array([0.6, 1.0])
    w_a, _ = theory.mis_weights(p_a, p_b, "balance", n_a=3, n_b=1)
    np.testing.assert_allclose(w_a, 3 * p_a / (3 * p_a + p_b))
    w_a, _ = theory.mis_weights(p_a, p_b, "power", beta=3.0)
    np.testing.assert_allclose(w_a, p_a**3 / (p_a**3 + p_b**3))
    np.testing.assert_allclose(theory.mis_weights(p_a, p_b, "power", beta=1.0)[0],
                               theory.mis_weights(p_a, p_b, "balance")[0])
    np.testing.assert_array_equal(theory.mis_weights(p_a, p_b, "max")[0], [0.0, 1.0])
    np.testing.assert_array_equal(theory.mis_weights(1.0, 1.0, "max")[0], 0.5)
    # average: the plain average of the two estimators, 1/2 each whatever the sample counts
    np.testing.assert_allclose(theory.mis_weights(p_a, p_b, "average", n_a=1, n_b=3)[0], 0.5)
    assert theory.mis_weights(0.0, 0.0, "balance") == (0.0, 0.0)


@pytest.mark.parametrize("args", [(-1.0, 1.0, "balance"), (math.nan, 1.0, "power"),
                                  (1.0, 1.0, "median"), (1.0, 1.0, "power", 0.0)])
def test_mis_weights_reject_bad_input(args):
    with pytest.raises(ValueError):
        theory.mis_weights(*args)


def test_theory_uses_the_plugins_mis_weight(monkeypatch):
    """theory.mis_weights is the plugins' one MIS weight on n_i p_i, not a copy of it."""
    from mitsuba_lab.plugins.integrators.common import mis_weight as shared

    calls = []

    def spy(pdf_self, pdf_other, heuristic, beta):
        calls.append((np.asarray(pdf_self).tolist(), np.asarray(pdf_other).tolist(), heuristic, beta))
        return shared.mis_weight(pdf_self, pdf_other, heuristic, beta)

    monkeypatch.setattr(theory, "mis_weight", spy)
    w_a, w_b = theory.mis_weights(np.array([0.2]), np.array([0.6]), "power", beta=3.0, n_a=2, n_b=1)
    assert calls == [([0.2], [0.3], "power", 3.0), ([0.3], [0.2], "power", 3.0)]   # scaled by 1/max(n)
    np.testing.assert_allclose(w_a, shared.mis_weight(0.4, 0.6, "power", 3.0))


# ------------------------------------------------------------- problem 8 (Metropolis-Hastings)
def test_problem8_predictions_do_not_depend_on_the_grid():
    from mitsuba_lab import theory_mlt

    coarse = [theory_mlt.p8_predicted(s, l, cells=250) for s, l in theory_mlt.P8_MIXING]
    fine = [theory_mlt.p8_predicted(s, l, cells=theory_mlt.P8_GRID) for s, l in theory_mlt.P8_MIXING]
    for a, b in zip(coarse, fine):
        assert abs(a["tau"] / b["tau"] - 1) < 2e-3 and abs(a["acceptance"] - b["acceptance"]) < 1e-3
    # the kernel's rows are probabilities and the target is its stationary law (detailed balance)
    x, pi, P = theory_mlt.p8_kernel(0.05, 0.3, 200)
    assert np.allclose(P.sum(axis=1), 1) and (P >= 0).all()
    assert np.allclose(pi @ P, pi, atol=1e-12)


def test_problem8_catches_a_chain_that_forgets_its_rejections():
    """Power: a chain whose rejected steps are not counted as repeats of the current state (a
    common mistake: only accepted states averaged) weights each state by its acceptance
    probability, which differs between the narrow and the wide peak; its mean of g misses
    E_pi[g] by many times the tolerance of P8's mean row, which the right chain meets."""
    from mitsuba_lab import theory_mlt
    from mitsuba_lab.theory_rows import TOL_SE

    chains, steps, sigma = 2000, 200, 0.2
    rng = np.random.default_rng(3)
    x = theory_mlt._sample_target(rng, chains)
    g_sum, accepted = np.zeros(chains), np.zeros(chains)
    for _ in range(steps):
        y = (x + sigma * rng.standard_normal(chains)) % 1.0
        move = rng.random(chains) * theory_mlt.p8_target(x) < theory_mlt.p8_target(y)
        x = np.where(move, y, x)
        g_sum += move & (x < 0.5)
        accepted += move
    wrong = g_sum / np.maximum(accepted, 1)
    truth = theory_mlt.p8_predicted(sigma, 0.0, steps)["mean_g"]
    _, right = theory_mlt.run_chains(np.random.default_rng(4), chains, steps, sigma)
    assert abs(right.mean() - truth) <= TOL_SE * metrics.standard_error(right)
    assert abs(wrong.mean() - truth) > 3 * TOL_SE * metrics.standard_error(wrong), (wrong.mean(), truth)
