"""BDPT step 2: light subpaths and the t = 1 strategy (light tracing) against Mitsuba.

Agreement in expectation is tested by z-scores of 8x8 block means and image means
(tests/agreement.py) over 16 renders a side with disjoint fixed seeds; under agreement each z
is about standard normal, and the bound is |z| <= 5 (about 200 z's per comparison, so a
false failure has probability < 1e-4). Power: the same stacks with the lab's image scaled
by 1.03 exceed the bound.
"""
import mitsuba as mi
import numpy as np
import pytest

from mitsuba_lab.plugins.integrators.bdpt.light_subpath import render_light_tracing
from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights
from agreement import Z_BOUND, renders, z_scores

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

SEEDS_LAB = range(16)
SEEDS_REF = range(1000, 1016)
SPP = 16


def lab_stack(scene, max_depth, spp=SPP, seeds=SEEDS_LAB):
    return np.stack([np.array(render_light_tracing(scene, seed=s, spp=spp, max_depth=max_depth))
                     for s in seeds])


def mitsuba_stack(scene, kind, max_depth, spp=SPP):
    return renders(scene, mi.load_dict({"type": kind, "max_depth": max_depth}), spp, SEEDS_REF)


@pytest.fixture(scope="module")
def cornell():
    return mi.load_file("scenes/cornell_box.xml", res=32)


@pytest.fixture(scope="module")
def cornell_stacks(cornell):
    return {d: lab_stack(cornell, d) for d in (1, 2, 5)}


@pytest.mark.parametrize("max_depth", [1, 2, 5])
def test_cornell_agrees_with_ptracer(cornell, cornell_stacks, max_depth):
    """max_depth 1: only the emitter seen directly (s = 1, t = 1); 2: direct light; 5."""
    ref = mitsuba_stack(cornell, "ptracer", max_depth)
    agreement = z_scores(cornell_stacks[max_depth], ref)
    assert agreement.max_abs_z <= Z_BOUND, agreement
    # power: a 3 % bias is seen
    assert z_scores(cornell_stacks[max_depth] * 1.03, ref).max_abs_z > Z_BOUND


def test_cornell_agrees_with_path(cornell, cornell_stacks):
    ref = mitsuba_stack(cornell, "path", 5, spp=32)
    agreement = z_scores(cornell_stacks[5], ref)
    assert agreement.max_abs_z <= Z_BOUND, agreement
    assert z_scores(cornell_stacks[5] * 1.03, ref).max_abs_z > Z_BOUND


def _floor_scene(emitter, sensor_type="perspective", extra=None):
    scene = {
        "type": "scene",
        "sensor": {"type": sensor_type, "fov": 45,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 2.5, 3.5], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 32, "rfilter": {"type": "box"}},
                   **(extra or {})},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90).scale(2),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.5, 0.3]}}},
        "cube": {"type": "cube", "to_world": mi.ScalarTransform4f().translate([0.3, 0.35, 0]).scale(0.35),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.3, 0.6, 0.4]}}},
        "light": emitter,
    }
    return mi.load_dict(scene)


def test_point_light_agrees_with_path():
    """A delta-position emitter: no s = 1 splat, the subpath starts with a uniform direction."""
    scene = _floor_scene({"type": "point", "position": [-0.8, 1.5, 0.6],
                          "intensity": {"type": "rgb", "value": [4.0, 4.0, 4.0]}})
    lab, ref = lab_stack(scene, 3, spp=64), mitsuba_stack(scene, "path", 3, spp=16)
    agreement = z_scores(lab, ref)
    assert agreement.max_abs_z <= Z_BOUND, agreement
    assert z_scores(lab * 1.03, ref).max_abs_z > Z_BOUND


@pytest.mark.parametrize("emitter", [{"type": "directional", "direction": [0.3, -1, -0.2]},
                                     {"type": "spot", "cutoff_angle": 30.0, "to_world": mi.ScalarTransform4f()
                                      .look_at(origin=[0.5, 2, 1], target=[0, 0, 0], up=[0, 1, 0])}])
def test_emitters_at_infinity_and_spot_agree_with_ptracer(emitter):
    """Light subpaths from a delta direction (rays from a disk of the scene's bounding radius)
    or a cone. (An environment seen directly is a camera-side strategy: Mitsuba's ptracer
    renders it with camera rays, light tracing alone cannot; lab_bdpt's agreement on
    scenes/stiff/environment_only.xml covers environments, tests/plugins/test_bdpt.py.)"""
    scene = _floor_scene(emitter)
    lab = lab_stack(scene, 3)
    agreement = z_scores(lab, mitsuba_stack(scene, "ptracer", 3))
    assert agreement.max_abs_z <= Z_BOUND, agreement


def test_thin_lens_diffuse_floor_agrees_with_ptracer():
    """A thin-lens camera (importance sampled on the lens) over a diffuse floor, area light seen
    directly (s = 1, t = 1)."""
    light = {"type": "rectangle",
             "to_world": mi.ScalarTransform4f().translate([-0.6, 1.2, -0.4]).rotate([1, 0, 0], 60).scale(0.4),
             "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6.0, 6.0, 6.0]}}}
    scene = _floor_scene(light, "thinlens", {"aperture_radius": 0.05, "focus_distance": 4.0})
    lab = lab_stack(scene, 3)
    for kind, spp in (("ptracer", SPP), ("path", 16)):
        agreement = z_scores(lab, mitsuba_stack(scene, kind, 3, spp=spp))
        assert agreement.max_abs_z <= Z_BOUND, (kind, agreement)


def test_weights_plumbing(cornell):
    """Light-only MIS multiplies every splat by 1 (same image, same seed, as the preset given
    explicitly, up to the order of float atomics); with all strategies enabled the splats are multiplied by weights in [0, 1]
    (pixelwise no brighter, darker overall), so the running quantities reach the splat. Bad
    arguments are refused with one line."""
    a = np.array(render_light_tracing(cornell, seed=3, spp=2, max_depth=4))
    b = np.array(render_light_tracing(cornell, seed=3, spp=2, max_depth=4,
                                      weights=BdptWeights(strategies=["light"])))
    c = np.array(render_light_tracing(cornell, seed=3, spp=2, max_depth=4, weights=BdptWeights()))
    assert np.isfinite(a).all() and (a >= 0).all() and np.isfinite(c).all()
    # splats are summed by float atomics in any order: equal up to rounding
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)
    assert (c <= a * (1 + 1e-4) + 1e-6).all() and c.mean() < 0.9 * a.mean()
    with pytest.raises(ValueError, match="lab_bdpt: max_depth"):
        render_light_tracing(cornell, max_depth=0)
    with pytest.raises(ValueError, match="lab_bdpt: spp"):
        render_light_tracing(cornell, spp=0)
