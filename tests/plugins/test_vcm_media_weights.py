"""lab_vcm's MIS weights with merging at medium vertices (``vcm/volume_merging.py``): merging at
a medium vertex x_i has density p_L(x_0..x_i) p_C(x_i..x_k) (4/3) pi r_v^3 N_light with volume
densities there (g = sigma_t), at a surface vertex the disc's pi r^2 N_light. The recursion
(each vertex folds its own eta into dvc; dvm is kept relative to the surfaces' eta, and a merge
in a ball rescales its sums) must give every technique the brute force's weight.

Random paths (test_bdpt_weights.py's with media: medium vertices with probability 0.4, their
g = sigma_t in 1e-3 .. 1e3, segment transmittances 1e-4 .. 1; k = 1 .. 7 segments, 4000 paths a
length, fixed seeds), disc and ball sizes drawn over 1e-4 .. 1e4 each. Tolerance: weights equal
the brute force within 1e-9 relative and sum to 1 within 1e-9 (float64). Power: a merge at a
medium vertex whose sums are not rescaled to the ball (``_volume_ratio`` 1) misses both by far.
"""
import numpy as np
import pytest

from test_bdpt_weights import MERGE_SUBSETS, N, RTOL, _max_rel, area_densities, random_paths
from test_bdpt_weights import recursive_weights as bdpt_recursive_weights
from mitsuba_lab.plugins.integrators.bdpt import recursion
from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights, brute_force_weights, feasible


def recursive_weights(g, mis):
    """Every connection technique's weight, then merging's at x_1 .. x_{k-1}, by the recursion,
    each call told which of its vertices lie in a medium."""
    return bdpt_recursive_weights(g, mis, media_calls=True)


def worst_errors(subset, beta, merge_from):
    """(max relative error against the brute force, max |sum - 1|, medium vertices) over k = 1 .. 7."""
    worst, worst_sum, mediums = 0.0, 0.0, 0
    for k in range(1, 8):
        g = random_paths(k, seed=4600 * k + int(beta) + 10 * merge_from, media=True)
        sizes = np.exp(np.random.default_rng(k).uniform(np.log(1e-4), np.log(1e4), 2))
        mis = BdptWeights("power", beta, strategies=subset, light_paths=g["light_paths"], merge_area=sizes[0],
                          merge_from=merge_from, merge_volume=sizes[1])
        p_light, p_camera = area_densities(g)
        with np.errstate(all="ignore"):
            got = recursive_weights(g, mis)
            ref = brute_force_weights(p_light, p_camera, g["delta"], beta, subset, g["nee"], g["light_paths"],
                                      sizes[0], merge_from, merge_volume=sizes[1], medium=g["medium"])
        worst = max(worst, _max_rel(got, ref))
        reach = ref.sum(axis=0) > 0
        worst_sum = max(worst_sum, float(np.abs(got.sum(axis=0)[reach] - 1.0).max(initial=0.0)))
        mediums += int(g["medium"][1:k].sum())
    return worst, worst_sum, mediums


@pytest.mark.parametrize("merge_from", [1, 2])
@pytest.mark.parametrize("subset", MERGE_SUBSETS)
@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_merges_at_medium_vertices_equal_brute_force_and_sum_to_one(subset, beta, merge_from):
    worst, worst_sum, mediums = worst_errors(subset, beta, merge_from)
    print(f"{'+'.join(subset)}, beta {beta}, merge_from {merge_from}: {mediums} medium vertices, max relative "
          f"error {worst:.2e}, max |sum - 1| {worst_sum:.2e}")
    assert worst < RTOL and worst_sum < RTOL and mediums > 10000


def test_a_merge_in_a_ball_counted_as_a_disc_is_caught(monkeypatch):
    monkeypatch.setattr(recursion.Recursion, "_volume_ratio", lambda self, medium: 1.0)
    worst, worst_sum, _ = worst_errors(MERGE_SUBSETS[0], 2.0, 2)
    print(f"ball not rescaled: max relative error {worst:.2e}, max |sum - 1| {worst_sum:.2e}")
    assert worst > 1e3 * RTOL and worst_sum > 1e3 * RTOL
