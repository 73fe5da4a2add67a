"""A heterogeneous medium that bounds nothing (the sensor's smoke, no shape around it) under a sky:
it is empty outside its grid, so every lab plugin renders it as its bounded twin (the same grid
inside a null box), which Mitsuba's volpath renders. Before 2026-11-29 rays that left the scene in
it carried 0 / 0 (tracking to an infinite distance), light subpaths from the sky started
extinguished, and lab_bdpt's weights gave the escaping piece a capped optical depth while its
next-event estimation tracked the grid: image means 0.07 (path family), 0.51 (lab_bdpt) against the
twin's 0.698.

Tolerance: |z| <= Z_BOUND (5, tests/agreement.py) for each image mean (4 seeds x 64 spp against volpath's 4 x 256 on the twin;
the renders' spread about 0.1-0.2%); the bug missed by z 170-1000.
"""
import numpy as np
import pytest

import mitsuba as mi
import backend  # noqa: F401 (the variant)
import media_scenes
from agreement import Z_BOUND
from mitsuba_lab.scene import make_integrator

_cache = {}


def image_mean(scene, name, params, spp, seeds):
    means = [float(np.array(mi.render(scene, integrator=make_integrator(name, {"max_depth": 6, **params}),
                                      spp=spp, seed=s)).mean()) for s in seeds]
    return np.mean(means), np.std(means, ddof=1) / np.sqrt(len(means))


def twin_mean():
    if "twin" not in _cache:
        _cache["twin"] = image_mean(mi.load_dict(media_scenes.sky_in_unbounded_smoke_twin()), "volpath", {}, 256,
                                    range(100, 104))
    return _cache["twin"]


@pytest.mark.slow
@pytest.mark.parametrize("name, params", [("lab_mis", {}), ("lab_bdpt", {}), ("lab_photon", {})])
def test_a_sky_seen_through_unbounded_smoke_is_its_bounded_twins(name, params):
    scene = mi.load_dict(media_scenes.sky_in_unbounded_smoke())
    mean, se = image_mean(scene, name, params, 64, range(4))
    ref, ref_se = twin_mean()
    z = (mean - ref) / np.hypot(se, ref_se)
    assert abs(z) <= Z_BOUND, f"{name}: {mean:.5f} +- {se:.5f} against the twin's {ref:.5f} +- {ref_se:.5f} (z {z:.1f})"


def test_a_flight_that_leaves_the_scene_in_smoke_passes_it_with_weight_one():
    """Delta tracking along a ray that meets no surface ends where it leaves the grid: a ray that
    misses the grid passes with weight exactly 1 (it gave 0, tracking to an infinite distance)."""
    from mitsuba_lab.plugins.integrators.common import media

    scene = mi.load_dict(media_scenes.sky_in_unbounded_smoke())
    medium = scene.sensors()[0].get_medium()
    ray = mi.Ray3f(mi.Point3f(0, 3, 5), mi.Vector3f(0, 0, -1))         # above the grid, no surface ahead
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(0, 1)
    _, scattered, weight, _, _ = media.free_flight(mi.MediumPtr(medium), ray, mi.Float(np.inf), sampler, mi.UInt32(0),
                                                   mi.Bool(True))
    assert not scattered[0] and np.allclose(np.array(weight), 1.0)
