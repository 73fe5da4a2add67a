"""The one MIS weight (plugins/integrators/common/mis_weight.py) at extreme densities, on Dr.Jit arrays
as the plugins trace it and on numpy arrays as mitsuba_lab.theory uses it."""
import itertools

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mitsuba_lab.plugins.integrators.common.mis_weight import HEURISTICS, mis_weight

# Dr.Jit flushes float32 denormals (< 1.18e-38) to zero, so the smallest density tested is normal.
EXTREMES = [0.0, 1.2e-38, 1e-30, 1e-3, 0.5, 1.0, 3.0, 7e3, 1e7, 1.8e19, 1e30, 3.4e38, float("inf")]
BETAS = [0.5, 1.0, 2.0, 3.0, 10.0]


def weights(heuristic, beta):
    a, b = zip(*itertools.product(EXTREMES, EXTREMES))
    a, b = mi.Float(a), mi.Float(b)
    w_ab = np.array(mis_weight(a, b, heuristic, beta))
    w_ba = np.array(mis_weight(b, a, heuristic, beta))
    return np.array(a), np.array(b), w_ab, w_ba


@pytest.mark.parametrize("heuristic, beta", [(h, b) for h in HEURISTICS for b in BETAS])
def test_weights_are_finite_in_range_and_sum_to_one(heuristic, beta):
    a, b, w_ab, w_ba = weights(heuristic, beta)
    assert np.all(np.isfinite(w_ab)) and np.all((w_ab >= 0) & (w_ab <= 1))
    some = (a > 0) | (b > 0)
    np.testing.assert_allclose((w_ab + w_ba)[some], 1.0, atol=1e-6)
    assert np.all(w_ab[a == 0] == 0)                       # a technique that cannot sample x


@pytest.mark.parametrize("heuristic", ["balance", "power", "max"])   # average is 1/2 by definition
def test_infinite_against_finite_density_gets_weight_one(heuristic):
    inf = mi.Float(float("inf"))
    for finite in (0.0, 1e-30, 1.0, 1e30, 3.4e38):
        assert mis_weight(inf, mi.Float(finite), heuristic)[0] == 1.0
        assert mis_weight(mi.Float(finite), inf, heuristic)[0] == 0.0


def test_power_heuristic_matches_formula_where_pdf_beta_is_representable():
    # mitsuba_lab.theory, Problem 4: p_A(1) = 0.16580, p_B(1) = 0.04382.
    pa, pb = mi.Float(0.16580), mi.Float(0.04382)
    assert mis_weight(pa, pb, "balance")[0] == pytest.approx(0.7909, abs=1e-4)
    assert mis_weight(pa, pb, "power", 2.0)[0] == pytest.approx(0.9347, abs=1e-4)
    assert mis_weight(pb, pa, "power", 2.0)[0] == pytest.approx(0.0653, abs=1e-4)


def test_power_heuristic_does_not_overflow():
    # 1e20^2 overflows float32; the naive p^2 / (p^2 + q^2) gives inf/inf = NaN (Mitsuba's own
    # path integrator maps that to 0, losing the sample). The ratio form keeps the limit.
    w = mis_weight(mi.Float(1e20), mi.Float(1e19), "power", 2.0)[0]
    assert w == pytest.approx(100 / 101, rel=1e-6)
    w10 = mis_weight(mi.Float(8e3), mi.Float(4e3), "power", 10.0)[0]
    assert w10 == pytest.approx(1 / (1 + 2.0 ** -10), rel=1e-6)


def test_max_and_average():
    a, b = mi.Float([2.0, 1.0, 1.0, 1.0]), mi.Float([1.0, 2.0, 1.0, 0.0])
    assert list(np.array(mis_weight(a, b, "max"))) == [1.0, 0.0, 0.5, 1.0]
    assert list(np.array(mis_weight(a, b, "average"))) == [0.5, 0.5, 0.5, 1.0]


def test_unknown_heuristic():
    with pytest.raises(ValueError, match="unknown MIS heuristic 'foo'"):
        mis_weight(mi.Float(1.0), mi.Float(1.0), "foo")


@pytest.mark.parametrize("heuristic, beta", [(h, b) for h in HEURISTICS for b in BETAS])
def test_numpy_and_drjit_give_the_same_weights(heuristic, beta):
    """One formula on two array types: float32 Dr.Jit weights equal float64 numpy weights of
    the same (float32-representable) densities, up to float32 rounding."""
    a, b, w_ab, _ = weights(heuristic, beta)
    w_np = mis_weight(a.astype(np.float64), b.astype(np.float64), heuristic, beta)
    assert isinstance(w_np, np.ndarray) and w_np.dtype == np.float64
    np.testing.assert_allclose(w_ab, w_np, rtol=1e-5, atol=1e-6)


def test_average_is_one_half_wherever_both_techniques_can_sample():
    """The plain average of the two estimators: 1/2 each for any densities (n_i p_i), 1 where
    only this technique can sample, 0 where it cannot."""
    a = np.array([1.0, 1e-30, 3.0, 0.0, 2.0])
    b = np.array([3.0, 1e30, 3.0, 1.0, 0.0])
    np.testing.assert_array_equal(mis_weight(a, b, "average"), [0.5, 0.5, 0.5, 0.0, 1.0])


def test_bad_power_exponent():
    with pytest.raises(ValueError, match="beta must be > 0"):
        mis_weight(1.0, 1.0, "power", 0.0)
