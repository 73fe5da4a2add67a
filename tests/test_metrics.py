"""Metrics on tiny arrays with hand-computed answers, plus edge cases.

Exact identities use pytest.approx's default (relative 1e-6). The few
statistical checks use fixed seeds and a 4-standard-error band.
"""
import math

import numpy as np
import pytest

from mitsuba_lab import metrics


# ---------------------------------------------------------------- image error
def test_mse_hand_computed():
    img = np.array([[1.0, 2.0], [3.0, 4.0]])
    assert metrics.mse(img, np.zeros_like(img)) == 7.5  # (1+4+9+16)/4


def test_mse_averages_over_channels():
    img = np.zeros((1, 2, 3))
    img[0, 0] = [3.0, 0.0, 0.0]  # one squared error of 9 among 6 values
    assert metrics.mse(img, np.zeros_like(img)) == pytest.approx(1.5)


def test_rel_mse_hand_computed():
    ref = np.array([[0.0, 1.0]])
    img = np.array([[1.0, 3.0]])
    # (1/(0+0.01) + 4/(1+0.01)) / 2
    assert metrics.rel_mse(img, ref) == pytest.approx((100 + 4 / 1.01) / 2)
    assert metrics.rel_mse(img[:, 1:], ref[:, 1:], eps=0.0) == 4.0
    assert isinstance(metrics.rel_mse(img, ref), float)


# ---------------------------------------------------------- variance and bias
def test_per_pixel_variance_and_helpers():
    stack = np.array([[[1.0, 5.0]], [[3.0, 5.0]]])  # R=2, H=1, W=2
    np.testing.assert_allclose(metrics.per_pixel_variance(stack), [[2.0, 0.0]])  # ddof=1
    assert metrics.mean_variance(stack) == 1.0
    np.testing.assert_allclose(metrics.variance_of_mean(stack), [[1.0, 0.0]])


def test_per_pixel_variance_needs_two_renders():
    with pytest.raises(ValueError):
        metrics.per_pixel_variance(np.zeros((1, 2, 2)))


def test_bias_squared_constant_offset():
    ref = np.zeros((4, 4, 3))
    stack = np.stack([ref + 0.5, ref + 0.5])  # no noise, bias 0.5 everywhere
    est, se = metrics.bias_squared(stack, ref)
    assert est == pytest.approx(0.25)
    assert se == 0.0


def test_bias_squared_subtracts_variance_of_mean():
    ref = np.zeros((2, 2))
    stack = np.stack([ref + 1.0, ref - 1.0])  # mean exact, s^2 = 2, s^2/R = 1
    est, _ = metrics.bias_squared(stack, ref)
    assert est == pytest.approx(-1.0)  # unbiased estimate may go negative
    est, _ = metrics.bias_squared(stack, ref, ref_floor=0.5)
    assert est == pytest.approx(-1.5)


@pytest.mark.parametrize("bias", [0.0, 0.3])
def test_bias_squared_recovers_bias_statistically(bias):
    rng = np.random.default_rng(7)
    truth = rng.random((48, 48, 3))
    stack = truth + bias + rng.normal(0.0, 1.0, (8, 48, 48, 3))
    ref_noise_var = 0.01
    ref = truth + rng.normal(0.0, math.sqrt(ref_noise_var), truth.shape)
    est, se = metrics.bias_squared(stack, ref, ref_floor=ref_noise_var)
    assert abs(est - bias**2) < 4 * se  # 4 standard errors
    assert 0 < se < 0.01


# ----------------------------------------------------------------- efficiency
def test_efficiency():
    assert metrics.efficiency(0.5, 2.0) == 1.0
    assert metrics.efficiency(0.0, 1.0) == math.inf
    assert metrics.efficiency(1.0, 0.0) == math.inf
    assert math.isnan(metrics.efficiency(math.nan, 1.0))
    with pytest.raises(ValueError):
        metrics.efficiency(-1.0, 1.0)


# ------------------------------------------------------------------- log-log
def test_loglog_slope_exact_power_laws():
    t = np.array([1.0, 2.0, 4.0, 10.0])
    slope, intercept = metrics.loglog_fit(t, 3.0 / t)
    assert slope == pytest.approx(-1.0)
    assert intercept == pytest.approx(math.log(3.0))
    assert metrics.loglog_slope(t, 0.1 * t**-0.5) == pytest.approx(-0.5)


@pytest.mark.parametrize("times, errors", [([1.0], [1.0]), ([1.0, 1.0], [1.0, 2.0]),
                                           ([1.0, 2.0], [1.0, 0.0]), ([0.0, 2.0], [1.0, 1.0])])
def test_loglog_fit_rejects_degenerate_input(times, errors):
    with pytest.raises(ValueError):
        metrics.loglog_fit(times, errors)


def test_interpolate_at_time_is_loglog_linear():
    times, errors = [4.0, 1.0, 16.0], [0.25, 1.0, 1 / 16]  # error = 1/t, unsorted
    assert metrics.interpolate_at_time(times, errors, 2.0) == pytest.approx(0.5)
    assert metrics.interpolate_at_time(times, errors, 8.0) == pytest.approx(0.125)
    assert metrics.interpolate_at_time(times, errors, 1.0) == pytest.approx(1.0)
    assert metrics.interpolate_at_time(times, errors, 16.0) == pytest.approx(1 / 16)


@pytest.mark.parametrize("t", [0.5, 17.0, 0.0, -1.0])
def test_interpolate_at_time_outside_range_is_nan(t):
    assert math.isnan(metrics.interpolate_at_time([1.0, 16.0], [1.0, 0.1], t))


# -------------------------------------------------------------------- regions
def test_region_crop():
    img = np.arange(12).reshape(3, 4)
    np.testing.assert_array_equal(metrics.region(img, (1, 0, 3, 2)), [[1, 2], [5, 6]])
    rgb = np.zeros((3, 4, 3))
    assert metrics.region(rgb, (0, 1, 4, 3)).shape == (2, 4, 3)


@pytest.mark.parametrize("rect", [(0, 0, 5, 1), (2, 0, 2, 1), (0, -1, 1, 1), (3, 0, 1, 1)])
def test_region_rejects_bad_rect(rect):
    with pytest.raises(ValueError):
        metrics.region(np.zeros((3, 4)), rect)


def test_fraction_rect_to_pixels():
    assert metrics.fraction_rect_to_pixels((0.25, 0.5, 0.75, 1.0), 8, 4) == (2, 2, 6, 4)
    assert metrics.fraction_rect_to_pixels((0.0, 0.0, 1.0, 1.0), 640, 480) == (0, 0, 640, 480)
    assert metrics.fraction_rect_to_pixels((0.3, 0.3, 0.6, 0.6), 10, 10) == (3, 3, 6, 6)
    assert metrics.fraction_rect_to_pixels((0.25, 0.35, 0.45, 0.55), 10, 10) == (3, 4, 5, 6)
    # A sliver still keeps one pixel, and edges are clamped to the image.
    assert metrics.fraction_rect_to_pixels((0.5, 0.5, 0.5, 0.5), 10, 10) == (5, 5, 6, 6)
    assert metrics.fraction_rect_to_pixels((-0.2, 1.0, 1.5, 1.2), 10, 10) == (0, 9, 10, 10)


# ----------------------------------------------------------------- statistics
def test_z_score_welch():
    assert metrics.z_score(1.0, 1.0, 1, 0.0, 3.0, 1) == pytest.approx(0.5)  # 1/sqrt(1+3)
    assert metrics.z_score(2.0, 4.0, 4, 2.0, 9.0, 9) == 0.0
    assert metrics.z_score(1.0, 0.0, 5, 1.0, 0.0, 5) == 0.0
    assert metrics.z_score(0.0, 0.0, 5, 1.0, 0.0, 5) == -math.inf


def test_rmse_and_variances_hand_computed():
    assert metrics.rmse_from_trials([1.0, 3.0], 2.0) == 1.0
    assert metrics.mc_variance([1.0, 2.0, 3.0, 4.0]) == pytest.approx(5 / 3)  # ddof=1
    assert metrics.standard_error([1.0, 2.0, 3.0, 4.0]) == pytest.approx(math.sqrt(5 / 12))
    assert metrics.variance_standard_error(np.full(10, 2.0)) == 0.0
    assert metrics.rmse_standard_error([2.0, 2.0], 2.0) == 0.0


def test_rmse_standard_error_matches_normal_theory():
    # Normal errors: SE(RMSE) = RMSE / sqrt(2T); the plug-in agrees to ~2%.
    rng = np.random.default_rng(3)
    trials = 20_000
    est = rng.normal(1.0, 0.2, trials)
    expected = metrics.rmse_from_trials(est, 1.0) / math.sqrt(2 * trials)
    assert metrics.rmse_standard_error(est, 1.0) == pytest.approx(expected, rel=0.05)


def test_variance_standard_error_matches_spread_of_variances():
    # 2000 groups of 200 exponentials: the spread of their sample variances
    # should match the plug-in SE; 2000 groups pin the spread to ~2%, so 10%.
    rng = np.random.default_rng(5)
    groups = rng.exponential(1.0, (2000, 200))
    spread = np.std([metrics.mc_variance(g) for g in groups], ddof=1)
    plug_in = np.mean([metrics.variance_standard_error(g) for g in groups])
    assert plug_in == pytest.approx(spread, rel=0.1)
