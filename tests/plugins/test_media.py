"""The path family (lab_naive, lab_nee, lab_mis) in participating media agrees with Mitsuba's
`volpath` in expectation, in rgb, mono and spectral, on the scenes of tests/media_scenes.py
(fog behind a null boundary, a point light and the camera inside forward-scattering fog,
a chromatic medium in glass, heterogeneous smoke with a spot light and a masked card).

Tolerance: |z| <= Z_BOUND (tests/agreement.py) for every 8x8 block mean and every image
channel mean, 16 seeds a side (Welch, about 30 degrees of freedom); power: a 3% error in the
free-flight weight, or in the shadow rays' transmittance, passes the bound.
"""
import numpy as np
import pytest

import mitsuba as mi
import backend
import media_scenes
import mitsuba_lab
from agreement import SEEDS_LAB, SEEDS_REF, Z_BOUND, assert_agrees, pixel_problem, renders, z_scores
from mitsuba_lab.scene import SceneTraits, equivalent_strategies, make_integrator, strategy_applicability

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier

SPP = 16
DEPTH = 6


def reference(scene, max_depth=DEPTH):
    return renders(scene, make_integrator("volpath", {"max_depth": max_depth}), SPP, SEEDS_REF)


def lab(scene, kind="lab_mis", max_depth=DEPTH, **params):
    return renders(scene, make_integrator(kind, {"max_depth": max_depth, **params}), SPP, SEEDS_LAB)


@pytest.mark.parametrize("name", ["fog_box", "point_in_fog", "chromatic_in_glass", "smoke"])
def test_lab_mis_agrees_with_volpath(name):
    scene = mi.load_dict(media_scenes.SCENES[name]())
    assert_agrees(lab(scene), reference(scene), f"lab_mis on {name}")


@pytest.mark.parametrize("kind, name", [("lab_nee", "smoke"), ("lab_naive", "fog_box")])
def test_lab_nee_and_lab_naive_agree_with_volpath(kind, name):
    scene = mi.load_dict(media_scenes.SCENES[name]())
    assert_agrees(lab(scene, kind), reference(scene), f"{kind} on {name}")


@pytest.mark.parametrize("kind, sampling, name", [
    ("lab_mis", "distance", "fog_box"), ("lab_mis", "equiangular", "fog_box"),
    ("lab_mis", "equiangular", "point_in_fog"), ("lab_nee", "mis", "fog_box"), ("lab_nee", "equiangular", "point_in_fog")])
def test_every_medium_sampling_agrees_with_volpath(kind, sampling, name):
    """Free flights alone, equi-angular sampling alone (with phase-function hits for lab_mis), and
    both (lab_mis's default, tested above; lab_nee weighs its two light samples by balance)."""
    scene = mi.load_dict(media_scenes.SCENES[name]())
    assert_agrees(lab(scene, kind, medium_sampling=sampling), reference(scene), f"{kind} {sampling} on {name}")


def test_delta_tracking_shadow_rays_agree_with_volpath():
    scene = mi.load_dict(media_scenes.smoke())
    assert_agrees(lab(scene, transmittance="delta"), reference(scene), "lab_mis transmittance=delta on smoke")


@pytest.mark.parametrize("max_depth", [1, 3])
def test_depth_counts_medium_vertices_and_not_null_boundaries(max_depth):
    """max_depth as volpath counts it: a scattering event in a medium is a vertex, crossing a
    null boundary is not (with 1, the light is seen through the fog box's boundary)."""
    scene = media_scenes.fog_box()
    scene["environment"] = media_scenes.environment(0.5)        # seen through the box at max_depth 1
    scene = mi.load_dict(scene)
    images = lab(scene, max_depth=max_depth)
    assert images.mean() > 0.05
    assert_agrees(images, reference(scene, max_depth), f"lab_mis max_depth {max_depth}")


@pytest.mark.parametrize("kind, name", [("ad_mono", "chromatic_smoke"), ("ad_spectral", "chromatic_in_glass")])
def test_mono_and_spectral_variants_agree_with_volpath(kind, name):
    variant = backend.variant(kind)
    if variant not in mi.variants():
        pytest.skip(f"{variant} is not in this Mitsuba build")
    mitsuba_lab.use_variant(variant)
    try:
        scene = mi.load_dict(media_scenes.SCENES[name]())
        images = lab(scene)
        assert pixel_problem(images, kind == "ad_spectral") == ""
        result = z_scores(images, reference(scene))
        print(f"lab_mis on {name} in {variant}: max |z| {result.max_abs_z:.2f}, relative difference "
              f"{result.rel_diff.round(4)}")
        assert result.max_abs_z <= Z_BOUND
    finally:
        mitsuba_lab.use_variant(backend.HOME)


@pytest.mark.parametrize("what", ["free_flight", "transmittance", "equiangular_pdf"])
def test_a_three_percent_error_in_a_medium_estimator_is_caught(monkeypatch, what):
    """Power: the free flights' weight or the shadow rays' transmittance 3% too high, or the
    equi-angular density that the other techniques' MIS weights see 30% too high (the weights
    then no longer sum to 1)."""
    from mitsuba_lab.plugins.integrators.common import media

    original = getattr(media, what)

    def biased(*args, **kwargs):
        out = original(*args, **kwargs)
        if what == "free_flight":
            mei, scattered, weight = out
            return mei, scattered, weight * 1.03
        return out * (1.3 if what == "equiangular_pdf" else 1.03)

    monkeypatch.setattr(media, what, biased)
    scene = mi.load_dict(media_scenes.fog_box())
    result = z_scores(lab(scene), reference(scene))
    print(f"{what} too high: max |z| {result.max_abs_z:.1f}, relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z > Z_BOUND


@pytest.mark.parametrize("case", ["dense_albedo_0999", "extinction_1e-4", "grazing"])
def test_stiff_media_give_finite_non_negative_pixels(case):
    """A dense medium of albedo 0.999 (long random walks), one of extinction 1e-4 (almost no
    collision), and a camera grazing the fog box's top face."""
    if case == "dense_albedo_0999":
        scene = media_scenes.fog_box(albedo=0.999, sigma_t=20.0)
    elif case == "extinction_1e-4":
        scene = media_scenes.fog_box(sigma_t=1e-4)
    else:
        scene = media_scenes.fog_box()
        scene["sensor"]["to_world"] = media_scenes.T().look_at(origin=[0, 1.2, 4], target=[0, 1.2, 0], up=[0, 1, 0])
    images = renders(mi.load_dict(scene), make_integrator("lab_mis", {"max_depth": -1}), 16, range(2))
    assert pixel_problem(images, False) == ""
    assert images.mean() > 0


def test_the_planner_runs_the_path_family_on_media_and_leaves_the_others_out():
    traits = SceneTraits.from_scene(mi.load_dict(media_scenes.fog_box()))
    for kind in ("lab_naive", "lab_nee", "lab_mis", "lab_bdpt"):
        assert strategy_applicability(traits, kind, {}) == (True, ""), kind
    for kind in ("lab_photon", "lab_vcm"):
        applies, reason = strategy_applicability(traits, kind, {})
        assert not applies and "participating media" in reason and "lab_mis" in reason, kind


def test_a_medium_makes_the_estimators_differ_where_every_bsdf_is_delta():
    """Only null and glass surfaces: without a medium lab_naive, lab_nee and lab_mis are one
    estimator; a medium's phase function is smooth, so in chromatic_in_glass-like scenes they
    are not."""
    scene = media_scenes.chromatic_in_glass()
    scene["floor"]["bsdf"] = {"type": "conductor"}
    scene["light"]["bsdf"] = {"type": "null"}
    traits = SceneTraits.from_scene(mi.load_dict(scene))
    assert not traits.smooth_bsdf and traits.media
    strategies = {"naive": ("lab_naive", {}), "nee": ("lab_nee", {}), "mis": ("lab_mis", {})}
    assert equivalent_strategies(traits, strategies) == {"naive": "naive", "nee": "nee", "mis": "mis"}
    del scene["ball"]["interior"]
    traits = SceneTraits.from_scene(mi.load_dict(scene))
    assert set(equivalent_strategies(traits, strategies).values()) == {"naive"}


def test_equivalent_strategies_in_media():
    """With only a point light, lab_mis with free flights alone is lab_nee (every weight 1), but
    with medium_sampling = mis its heuristic weighs NEE against equi-angular sampling; without a
    medium the medium parameters change nothing."""
    strategies = {"nee": ("lab_nee", {}), "mis_distance": ("lab_mis", {"medium_sampling": "distance"}),
                  "mis": ("lab_mis", {}), "nee_mis": ("lab_nee", {"medium_sampling": "mis"})}
    fog = SceneTraits.from_scene(mi.load_dict(media_scenes.fog_box_point()))
    assert equivalent_strategies(fog, strategies) == {"nee": "nee", "mis_distance": "nee", "mis": "mis",
                                                      "nee_mis": "nee_mis"}
    clear = media_scenes.fog_box_point()
    del clear["box"]["interior"]
    clear = SceneTraits.from_scene(mi.load_dict(clear))
    assert set(equivalent_strategies(clear, strategies).values()) == {"nee"}
