"""lab_bdpt's MIS weights in heterogeneous media (``common/subpath_media.py``): the distance
densities are unknown there, so every strategy weighs a path with deterministic stand-ins, g =
sigma_t(x) at a medium vertex and ``stand_in`` for each segment's transmittance. The weights sum
to 1 only if every place that evaluates a segment gives it the same value: the light subpath's
flight from x_i to x_{i+1}, the camera subpath's flight back, and the connections' walk
(``common.media.transmittance`` with ``stand_in``).

Random paths (test_bdpt_weights.py's, k = 1 .. 6 segments, 4000 a length, fixed seeds) get their
medium vertices and segments from a real heterogeneous medium (tests/media_scenes.py's smoke):
vertices at random points inside it, sigma_t evaluated there, and the three evaluations of each
segment's stand-in above, in float32. Tolerance: the weights sum to 1 within 1e-4 and equal the
brute force (over the light side's values) within 1e-4 relative (float32 stand-ins; the
recursion itself is exact to 1e-9, test_bdpt_weights.py). Power: a stand-in that reads sigma_t
at the piece's start instead of its midpoint (so a segment's two directions disagree) misses
the sum by far more.
"""
import numpy as np
import pytest

import drjit as dr
import mitsuba as mi
import media_scenes
from test_bdpt_weights import N, _max_rel, _reference, random_paths, recursive_weights
from mitsuba_lab.plugins.integrators.common import subpath_media
from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights, feasible
from mitsuba_lab.plugins.integrators.common import media, spawn
from mitsuba_lab.scene import SceneTraits

TOL = 1e-4


def _smoke():
    scene = mi.load_dict(media_scenes.smoke())
    medium = next(s.interior_medium() for s in scene.shapes() if s.interior_medium() is not None)
    return scene, medium


def _point(xyz):
    return mi.Point3f(*(mi.Float(np.ascontiguousarray(c, dtype=np.float32)) for c in xyz))


def heterogeneous_path(k, seed, scene, medium):
    """``random_paths(k, media=True)`` with its medium vertices' sigma_t and its segments'
    transmittances (light side ``T``, camera side ``T_camera``, connections ``T_connect``) from
    ``medium``, the vertices at random points of the smoke's box (all segments in one call)."""
    g = random_paths(k, seed, media=True)
    rng = np.random.default_rng(seed + 1)
    lo, hi = np.array([-0.75, 0.05, -0.75]), np.array([0.75, 1.55, 0.75])
    x = lo[:, None, None] + (hi - lo)[:, None, None] * rng.random((3, k + 1, N))
    n = k * N
    floor = spawn.offset_floor(SceneTraits.from_scene(scene))
    sampler = subpath_media.RngSampler()
    sampler.rng.seed(dr.arange(mi.UInt32, n), dr.opaque(mi.UInt32, seed))
    channel = dr.zeros(mi.UInt32, n)
    wavelengths = dr.zeros(mi.Ray3f, n).wavelengths
    on = dr.full(mi.Bool, True, n)
    ptr = dr.select(on, mi.MediumPtr(medium), dr.zeros(mi.MediumPtr))
    mei = dr.zeros(mi.MediumInteraction3f, n)
    mei.p = _point(x[:, 1:].reshape(3, -1))
    sigma = np.ones((k + 1, N))
    sigma[1:] = subpath_media.sigma_t_channel(ptr, mei, channel, on).numpy().reshape(k, N)
    # a medium vertex's g is its sigma_t; the test needs it positive (the smoke's empty corners are not)
    medium_vertex = g["medium"] & (sigma > 0)
    g["cos_l"] = np.where(medium_vertex, sigma, np.where(g["medium"], 1.0, g["cos_l"]))
    g["cos_c"] = np.where(medium_vertex, sigma, np.where(g["medium"], 1.0, g["cos_c"]))
    a, b = _point(x[:, :-1].reshape(3, -1)), _point(x[:, 1:].reshape(3, -1))
    g["T"] = subpath_media.stand_in(ptr, a, b, wavelengths, channel, on).numpy().reshape(k, N)
    g["T_camera"] = subpath_media.stand_in(ptr, b, a, wavelengths, channel, on).numpy().reshape(k, N)
    # connections walk from the camera vertex to the light vertex (t = 1: to the sensor)
    last = dr.arange(mi.UInt32, n) >= (k - 1) * N
    it = dr.zeros(mi.Interaction3f, n)
    it.p, it.wavelengths = dr.select(last, a, b), wavelengths
    _, T_det = media.transmittance(scene, ptr, it, dr.select(last, b, a), sampler, channel, floor, on,
                                   stand_in=subpath_media.stand_in)
    g["T_connect"] = T_det.numpy().reshape(k, N)
    return g


@pytest.fixture(scope="module")
def smoke():
    return _smoke()


def _check(smoke, beta=2.0):
    worst_sum, worst_ref, mediums = 0.0, 0.0, 0
    for k in range(1, 7):
        g = heterogeneous_path(k, 7700 + k, *smoke)
        mediums += int(g["medium"].sum())
        mis = BdptWeights("power", beta, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            got, ref = recursive_weights(g, mis), _reference(g, beta)
        buildable = feasible(g["delta"]).any(axis=0)
        worst_sum = max(worst_sum, float(np.abs(got.sum(axis=0)[buildable] - 1.0).max()))
        worst_ref = max(worst_ref, _max_rel(got, ref))
    return worst_sum, worst_ref, mediums


def test_stand_ins_give_weights_that_sum_to_one(smoke):
    worst_sum, worst_ref, mediums = _check(smoke)
    print(f"{mediums} medium vertices: max |sum - 1| {worst_sum:.2e}, max relative error vs brute force "
          f"{worst_ref:.2e}")
    assert worst_sum < TOL and worst_ref < TOL and mediums > 10000


def test_an_asymmetric_stand_in_is_caught(smoke, monkeypatch):
    """Power: sigma_t read at the piece's start, so a segment's two directions disagree."""
    def at_start(medium, start, end, wavelengths, channel, active):
        mei = dr.zeros(mi.MediumInteraction3f)
        mei.p, mei.wavelengths = start, wavelengths
        tau = dr.norm(end - start) * subpath_media.sigma_t_channel(medium, mei, channel, active)
        return dr.select(active, dr.exp(-dr.minimum(tau, subpath_media.TAU_CAP)), 1.0)

    monkeypatch.setattr(subpath_media, "stand_in", at_start)
    worst_sum, _, _ = _check(smoke)
    print(f"sigma_t at the start: max |sum - 1| {worst_sum:.2e}")
    assert worst_sum > 100 * TOL
