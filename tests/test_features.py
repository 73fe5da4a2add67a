"""The table of what Mitsuba's integrators ignore (mitsuba_lab.features) holds what it says:
measured, not assumed. 16x16 images, few spp, fixed seeds."""
import mitsuba as mi
import numpy as np
import pytest

from mitsuba_lab.features import (DEFAULT_REFERENCES, MITSUBA_IGNORES, default_reference, ignored_features,
                                  mitsuba_applicability, scene_features)
from mitsuba_lab.scene import SceneTraits, load_scene, strategy_applicability


def ball_scene(medium: bool):
    """A glass ball (with a homogeneous medium inside, or empty) over a diffuse floor, lit by a
    constant environment and a point light."""
    ball = {"type": "sphere", "radius": 0.6, "bsdf": {"type": "dielectric"}}
    if medium:
        ball["interior"] = {"type": "homogeneous", "albedo": 0.8, "sigma_t": 3.0}
    return mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}}},
        "ball": ball,
        "floor": {"type": "rectangle", "bsdf": {"type": "diffuse"},
                  "to_world": mi.ScalarTransform4f().translate([0, 0, -1]).scale(3)},
        "sky": {"type": "constant"},
        "lamp": {"type": "point", "position": [1, 1, 2], "intensity": 5.0}})


_scenes = {}


def scenes():
    if not _scenes:
        _scenes.update(medium=ball_scene(True), empty=ball_scene(False))
    return _scenes


@pytest.mark.slow
@pytest.mark.parametrize("integrator", sorted(MITSUBA_IGNORES))
def test_what_ignores_media_renders_the_same_without_it(integrator):
    """Same seed, with and without the medium: bit-identical images exactly for the integrators
    the table says ignore media."""
    params = {"type": integrator, **({"aovs": "dd:depth"} if integrator == "aov" else {})}
    plugin = mi.load_dict(params)
    images = [np.array(mi.render(scenes()[kind], integrator=plugin, spp=4, seed=3)) for kind in ("medium", "empty")]
    assert np.array_equal(*images) == ("media" in MITSUBA_IGNORES[integrator])


def test_direct_renders_what_path_renders_with_two_segments():
    """direct (and direct_projective) = path with max_depth 2, and less than unbounded path:
    they ignore indirect light. Cornell box 16x16, 256 spp: means agree to 1e-3."""
    scene = load_scene("scenes/cornell_box.xml", res=16)
    mean = lambda params: float(np.mean(mi.render(scene, integrator=mi.load_dict(params), spp=256, seed=1)))
    two = mean({"type": "path", "max_depth": 2})
    for name in ("direct", "direct_projective"):
        assert "indirect light" in MITSUBA_IGNORES[name]
        assert mean({"type": name}) == pytest.approx(two, rel=1e-3)
    assert mean({"type": "path", "max_depth": -1}) > 1.2 * two


def test_features_and_the_default_reference():
    medium, cornell = (SceneTraits.from_scene(s) for s in (scenes()["medium"],
                                                          load_scene("scenes/cornell_box.xml", res=8)))
    assert scene_features(medium) == ("media", "indirect light")
    assert scene_features(cornell) == ("indirect light",)
    assert default_reference(medium) == "volpathmis" and default_reference(cornell) == DEFAULT_REFERENCES[0] == "path"
    assert ignored_features(medium, "path") == ("media",)
    assert ignored_features(medium, "direct") == ("media", "indirect light")
    assert ignored_features(medium, "lab_mis") == ()
    assert ignored_features(medium, "lab_bdpt") == ()               # homogeneous media: rendered
    assert ignored_features(medium, "lab_vcm") == ()                # (merging at medium vertices too)
    assert ignored_features(medium, "lab_photon") == ()             # (volumetric photons)
    assert ignored_features(medium, "lab_mmlt") == ("media",)
    assert ignored_features(medium, "volpath") == ()
    assert ignored_features(medium, "aov", {"aovs": "d:depth", "inner": {"type": "volpath"}}) == ()
    assert ignored_features(medium, "my_own_plugin") is None           # unknown: not judged
    assert mitsuba_applicability(medium, "my_own_plugin") == (True, "")
    assert strategy_applicability(medium, "direct", {}) == (
        False, "direct ignores participating media and indirect light (the scene has a medium; light reaches "
               "the camera after more than one bounce): use volpath or volpathmis")
    assert strategy_applicability(cornell, "path", {}) == (True, "")
    assert strategy_applicability(cornell, "direct", {})[1].startswith("direct ignores indirect light")
