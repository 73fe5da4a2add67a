"""The automatic first merging radius where light vertices are sparse (``common/density_radius.py``).

* On a floor seen from 1 cm above it (stiff/grazing_camera.xml at 16x16), an iteration's light
  vertices are so sparse that a pixel-wide disc holds one about once in 10^5 merges: lab_vcm's
  ppm at the old default (the footprint, given as ``radius``) renders the floor black at 32 spp,
  and at the new default merges light some of its pixels (at least 3 of 128; about 10 expected).
  The radius is a function of the scene and the settings: the same value on every call.
* ``density_radii`` on vertices of a known density: uniform on a plane, rho per unit area, the
  disc that holds ``need`` of them has radius sqrt(need / (pi rho)); tolerance 25% (a
  16-neighbour estimate); vertices facing the other way are not counted.
* A scene with participating media keeps the footprint (the probe traces no media).
"""
import math

import numpy as np
import pytest

from mitsuba_lab.plugins.integrators.common import density_radius
from mitsuba_lab.scene import load_scene, make_integrator

RES, SPP = 16, 32


def floor_rows(image):
    """The lower half of the film: the floor, from 4 cm to a few units in front of the camera."""
    return np.asarray(image)[RES // 2:, :, :].mean(axis=2)


def test_ppm_lights_a_floor_that_light_vertices_barely_reach():
    scene = load_scene("scenes/stiff/grazing_camera.xml", res=RES)
    sensor = scene.sensors()[0]
    ppm = make_integrator("lab_vcm", {"mode": "ppm", "max_depth": 4})
    lit = floor_rows(ppm.render(scene, seed=3, spp=SPP))
    probe = ppm.radius_probe
    assert probe.radius > 50 * probe.footprint and probe.radius == ppm.default_radius(scene, sensor)
    old = make_integrator("lab_vcm", {"mode": "ppm", "max_depth": 4, "radius": probe.footprint})
    black = floor_rows(old.render(scene, seed=3, spp=SPP))
    assert (black > 0).mean() == 0.0                     # (the power: the old radius finds nothing here)
    # (the median probe pixel's disc holds 1/64 of a vertex per iteration, the floor's nearer rows less:
    # 5-9% of these pixels lit at 32 spp over seeds 0-3, about 10 of them)
    assert (lit > 0).sum() >= 3


def test_the_radius_is_the_same_on_every_call():
    scene = load_scene("scenes/stiff/grazing_camera.xml", res=RES)
    sensor = scene.sensors()[0]
    radii = [density_radius.first_radius(scene, sensor, RES * RES, 7) for _ in range(2)]
    assert radii[0] == radii[1] and radii[0].radius > radii[0].footprint


@pytest.mark.parametrize("need", [0.001, 0.01, 0.1])
def test_the_density_radius_of_uniform_vertices_is_the_discs(need):
    rng = np.random.default_rng(5)
    count, side = 5000, 10.0
    points = np.column_stack([rng.uniform(-side / 2, side / 2, count), np.zeros(count),
                              rng.uniform(-side / 2, side / 2, count)])
    up = np.tile([0.0, 1.0, 0.0], (count, 1))
    weights = np.full(count, 1.0 / count)                # one light subpath's worth in all
    hits = np.column_stack([rng.uniform(-2, 2, 50), np.zeros(50), rng.uniform(-2, 2, 50)])
    radii = density_radius.density_radii(hits, np.tile([0.0, 1.0, 0.0], (50, 1)), points, up, weights, need)
    expected = math.sqrt(need / (math.pi / side ** 2))
    assert np.median(radii) == pytest.approx(expected, rel=0.25)
    # the same vertices facing down are not merged with at a floor's hits
    assert np.isinf(density_radius.density_radii(hits, np.tile([0.0, 1.0, 0.0], (50, 1)), points, -up, weights,
                                                 need)).all()


def test_a_scene_with_media_keeps_the_footprint():
    # (the probe traces no media: fog_lantern's floor gets its photons after a bounce from the fog, which
    # a probe through clear air never brings there; it would take the cap, 20x the footprint)
    scene = load_scene("scenes/fog_lantern.xml", res=RES)
    probe = density_radius.first_radius(scene, scene.sensors()[0], 20000, 7, first_segment=2)
    assert probe.radius == probe.footprint and math.isnan(probe.density)
