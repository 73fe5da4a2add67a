"""The defaults a user gets from ``<integrator type="lab_vcm"/>`` (and lab_bdpt, lab_photon).

* The first merging radius is one pixel's width at the first surfaces the camera sees
  (``footprint.py``) where light vertices are not sparse (``density_radius.py`` and
  test_density_radius.py for where they are: the Cornell box keeps the footprint): on a wall facing the camera it is the wall's distance times the pixel's
  angular width (perspective, thin lens), or the view's width over the film's (orthographic),
  on a non-square film; it follows the film's resolution; a null-BSDF surface in front (a medium's
  boundary, such as a fog box around the camera) is looked through. Tolerance 4%: off-axis pixels of a
  20-degree view see the wall a little farther and at a little smaller angle.
* lab_vcm in mode vcm runs its pilot (counted costs, up to 16 light subpaths), merges from the
  camera's second vertex and aims 0.9 of its light subpaths at the specular shapes; in other modes
  no pilot, and the mode's aim (``params.VCM_AIM_DEFAULTS``: lab_bdpt's 0.5 in bpt and lt, none in
  bpm and ppm, where merging carries the direct light). lab_bdpt and lab_photon aim 0.5. A scene
  without specular shapes renders the same image with and without aim (aiming changes nothing there).
"""
import math

import mitsuba as mi
import numpy as np
import pytest

from mitsuba_lab.plugins.integrators.common.footprint import pixel_footprint
from mitsuba_lab.scene import load_scene, make_integrator

WALL_DISTANCE = 5.0


def wall_scene(sensor):
    wall = mi.ScalarTransform4f().translate([0, 0, WALL_DISTANCE]).scale(100)
    return mi.load_dict({"type": "scene", "sensor": sensor,
                         "wall": {"type": "rectangle", "to_world": wall},
                         "light": {"type": "constant"}})


def cornell_scene(res):
    return load_scene("scenes/cornell_box.xml", res=res)


def film(width, height):
    return {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}}


@pytest.mark.parametrize("kind", ["perspective", "thinlens"])
@pytest.mark.parametrize("width, height", [(40, 30), (80, 60), (30, 40)])
def test_the_footprint_is_a_pixels_width_on_a_facing_wall(kind, width, height):
    sensor = {"type": kind, "fov": 20, "film": film(width, height)}
    if kind == "thinlens":
        sensor.update(aperture_radius=0.1, focus_distance=WALL_DISTANCE)
    scene = wall_scene(sensor)
    # fov spans the film's width (fov_axis x)
    expected = WALL_DISTANCE * 2 * math.tan(math.radians(10)) / width
    assert pixel_footprint(scene, scene.sensors()[0]) == pytest.approx(expected, rel=0.04)


def test_the_footprint_looks_through_a_medium_boundary():
    # a null-BSDF sheet (a fog box's wall) at half the wall's distance, and one nested behind it
    scene = wall_scene({"type": "perspective", "fov": 20, "film": film(40, 30)})
    sheets = {f"sheet_{i}": {"type": "rectangle", "bsdf": {"type": "null"},
                            "to_world": mi.ScalarTransform4f().translate([0, 0, z]).scale(100)}
              for i, z in enumerate((WALL_DISTANCE / 2, WALL_DISTANCE * 0.75))}
    fogged = mi.load_dict({"type": "scene", "sensor": scene.sensors()[0], **sheets,
                           "wall": {"type": "rectangle",
                                    "to_world": mi.ScalarTransform4f().translate([0, 0, WALL_DISTANCE]).scale(100)}})
    expected = WALL_DISTANCE * 2 * math.tan(math.radians(10)) / 40
    assert pixel_footprint(fogged, fogged.sensors()[0]) == pytest.approx(expected, rel=0.04)


def test_the_footprint_of_an_orthographic_view_is_its_width_over_the_films():
    scene = wall_scene({"type": "orthographic", "film": film(40, 30),
                        "to_world": mi.ScalarTransform4f().scale([3, 3, 1])})
    assert pixel_footprint(scene, scene.sensors()[0]) == pytest.approx(6.0 / 40, rel=1e-4)


def test_a_view_of_nothing_falls_back_to_the_scenes_size_over_the_films():
    scene = mi.load_dict({"type": "scene", "sensor": {"type": "perspective", "film": film(32, 16)},
                          "ball": {"type": "sphere", "center": [0, 0, -10], "radius": 2.0}})
    assert pixel_footprint(scene, scene.sensors()[0]) == pytest.approx(4 * math.sqrt(3) / 32, rel=1e-4)


def test_lab_vcm_with_no_parameters_pilots_aims_and_merges_after_the_first_vertex():
    settings = make_integrator("lab_vcm", {}).settings()
    assert (settings["mode"], settings["pilot"], settings["light_paths_max"], settings["aim"],
            settings["merge_first"], settings["pilot_costs"], settings["radius"]) == \
        ("vcm", True, 16.0, 0.9, False, "counted", 0.0)
    bpt = make_integrator("lab_vcm", {"mode": "bpt"}).settings()
    assert (bpt["pilot"], bpt["light_paths_max"]) == (False, 0.0)
    assert {mode: make_integrator("lab_vcm", {"mode": mode}).settings()["aim"]
            for mode in ("vcm", "bpt", "lt", "bpm", "ppm", "pt")} == \
        {"vcm": 0.9, "bpt": 0.5, "lt": 0.5, "bpm": 0.0, "ppm": 0.0, "pt": 0.0}
    # what the runner records (params.resolve) is what the plugin renders with, in every mode
    from mitsuba_lab.plugins import params
    for given in ({}, {"mode": "bpt"}, {"mode": "ppm"}, {"mode": "vcm", "pilot": False}, {"light_paths": 32}):
        resolved = params.resolve("lab_vcm", given)
        assert {k: resolved[k] for k in ("pilot", "aim", "light_paths_max")} == \
            {k: make_integrator("lab_vcm", given).settings()[k] for k in ("pilot", "aim", "light_paths_max")}, given
    assert params.resolve("lab_vcm", {"mode": "bpt"})["aim"] == 0.5
    # a given aim wins in every mode
    assert make_integrator("lab_vcm", {"mode": "ppm", "aim": 0.3}).settings()["aim"] == 0.3
    assert make_integrator("lab_vcm", {"aim": 0.0}).settings()["aim"] == 0.0
    # a pilot given with more light subpaths than the default's maximum chooses from them up
    assert make_integrator("lab_vcm", {"light_paths": 32}).settings()["light_paths_max"] == 32.0
    for plugin in ("lab_bdpt", "lab_photon"):
        assert make_integrator(plugin, {}).settings()["aim"] == 0.5


def test_the_default_radius_is_the_footprint():
    scene = cornell_scene(16)
    expected = pixel_footprint(scene, scene.sensors()[0])
    vcm = make_integrator("lab_vcm", {"pilot": False, "max_depth": 3})
    vcm.render(scene, seed=1, spp=2)
    photon = make_integrator("lab_photon", {"photons_per_pass": 1000, "passes": 1, "max_depth": 3})
    photon.render(scene, seed=1, spp=1)
    assert vcm.bdpt_stats()["radius_first"] == pytest.approx(expected, rel=1e-6)
    assert photon.photon_stats()["radius_first"] == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("plugin", ["lab_bdpt", "lab_photon"])
def test_aim_changes_nothing_without_specular_shapes(plugin):
    scene = cornell_scene(16)
    extra = {"photons_per_pass": 2000, "passes": 1} if plugin == "lab_photon" else {}
    images = [np.array(make_integrator(plugin, {"aim": aim, "max_depth": 3, **extra}).render(scene, seed=2, spp=2))
              for aim in (0.0, 0.5)]
    np.testing.assert_allclose(images[0], images[1], rtol=0, atol=1e-5)
