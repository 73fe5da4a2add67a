"""Aimed emission (``aim``, ``aim_at``; plugins/integrators/common/aim.py): an area light sends a share
of its directions at the bounding spheres of chosen shapes.

* The mixture's weight factor (cos / pi) / p(d | y) has expectation exactly 1 under p (the
  cosine density integrates to 1 over the hemisphere), and p integrates to 1 over the sphere of
  directions: both checked on sds.xml's light, which aims at the glass sphere but not at the
  pane (too wide a cone), on the same light with a looser cone limit (the pane aimed at from some
  of its points only), and on light_in_glass.xml's, inside its target's sphere (nothing aimed
  at); |z| <= 5 over 2^20 samples, and an aimed density 10% off fails both (power).
* In expectation: lab_bdpt, lab_vcm (bpt and vcm) with ``aim`` agree with Mitsuba's ``path``
  (the z-test of tests/agreement.py, |z| <= 5); lab_photon with and without it have the same
  expectation (same radii). (On the caustic's floor lab_bdpt's mean is the same with and
  without, and a 10% error in the aimed density, used by the weights and the MIS, fails
  that by |z| > 10: a power proof of 38 CPU s, benchmarks/power/test_aim_power.py.)
* ``aim = 0``, or no target in the scene, renders exactly the image without it.
"""
import importlib
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from agreement import SEEDS_LAB, SEEDS_REF, Z_BOUND, assert_agrees, path_reference, renders, scene_path
from mitsuba_lab.errors import one_line
from mitsuba_lab.scene import load_scene, make_integrator

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

RES = 24
MAX_DEPTH = 8
N = 1 << 20      # directions per mean check



def aim_class():
    """aim.py's class as the plugins use it now: a variant switch (an earlier test's) reloads the
    module, so a class imported before it would take monkeypatches the plugins never see."""
    return importlib.import_module("mitsuba_lab.plugins.integrators.common.aim").AimedEmission

def light_points(scene, n, seed=1):
    """n points (and normals) on the scene's first area light, uniform by area."""
    emitter = [e for e in scene.emitters() if e.get_shape() is not None][0]
    rng = mi.PCG32(n, seed)
    ps, _ = emitter.sample_position(0.0, mi.Point2f(rng.next_float32(), rng.next_float32()))
    return ps.p, ps.n, rng


def mean_z(values, expected):
    values = np.array(values, dtype=np.float64)
    error, se = values.mean() - expected, values.std(ddof=1) / math.sqrt(len(values))
    if se == 0:      # a constant: exact or infinitely far off (light_in_glass's factors are all 1)
        return 0.0 if abs(error) < 1e-6 else math.inf
    return error / se


def factor_and_density_z(scene, aim):
    """z of E[factor] = 1 under the mixture, and of E[4 pi p(d | y)] = 1 for uniform d."""
    y, n, rng = light_points(scene, N)
    d_cos = mi.Frame3f(n).to_world(mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(),
                                                                                      rng.next_float32())))
    _, factor = aim.sample(y, n, d_cos, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()))
    d = mi.warp.square_to_uniform_sphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    density = 4 * math.pi * aim.pdf(dr.maximum(dr.dot(n, d), 0.0), y, d)
    return mean_z(factor, 1.0), mean_z(density, 1.0)


def aimed_counts(scene, aim):
    """The distinct K(y), how many targets are aimed at from y, over the light's points."""
    y, _, _ = light_points(scene, 1 << 14)
    return set(np.unique(np.array(aim._cones(y)[1])).tolist())


@pytest.mark.parametrize("name, cos_narrowest, counts", [
    ("sds.xml", 0.5, {1}),                 # the sphere (0.14 sr from the light); the pane (5 sr) is too wide
    ("sds.xml", 0.2, {1, 2}),              # the pane too from some of the light's points, not others
    ("stiff/light_in_glass.xml", 0.5, {0})])  # the light inside its target: nothing to aim at
def test_the_mixture_is_a_density_and_its_weights_have_mean_one(name, cos_narrowest, counts, monkeypatch):
    monkeypatch.setattr(aim_class(), "COS_NARROWEST", cos_narrowest)
    scene = load_scene(scene_path(name), res=16)
    aim = aim_class()(scene, 0.5)
    assert aim.enabled and aimed_counts(scene, aim) == counts
    z_factor, z_density = factor_and_density_z(scene, aim)
    print(f"{name}: z of E[factor] - 1 {z_factor:+.2f}, of E[4 pi p] - 1 {z_density:+.2f}")
    assert abs(z_factor) <= Z_BOUND and abs(z_density) <= Z_BOUND


def test_a_light_inside_its_target_emits_as_without_aim():
    """light_in_glass.xml: its light sits inside the glass, so every direction reaches it anyway;
    the cosine direction is kept with weight factor 1."""
    scene = load_scene(scene_path("stiff/light_in_glass.xml"), res=16)
    y, n, rng = light_points(scene, 1 << 12)
    d_cos = mi.Frame3f(n).to_world(mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(),
                                                                                      rng.next_float32())))
    d, factor = aim_class()(scene, 0.9).sample(y, n, d_cos, rng.next_float32(),
                                                 mi.Point2f(rng.next_float32(), rng.next_float32()))
    np.testing.assert_array_equal(np.array(d), np.array(d_cos))
    np.testing.assert_allclose(np.array(factor), 1.0, rtol=1e-6)


def test_a_wrong_aimed_density_fails_the_mean_check(monkeypatch):
    # The pane is aimed at too, from every point outside its bounding sphere: the sphere's cone
    # alone holds ~1% of the cosine weight, too little for the factor's mean to show the error.
    monkeypatch.setattr(aim_class(), "COS_NARROWEST", -1.0)
    scene = load_scene(scene_path("sds.xml"), res=16)
    aim = aim_class()(scene, 0.5)
    right = aim_class()._aimed_pdf
    monkeypatch.setattr(aim_class(), "_aimed_pdf", lambda self, y, d: 1.1 * right(self, y, d))
    z_factor, z_density = factor_and_density_z(scene, aim)
    print(f"aimed density x 1.1: z {z_factor:+.1f}, {z_density:+.1f}")
    assert abs(z_factor) > Z_BOUND and abs(z_density) > 2 * Z_BOUND


def test_targets_are_the_specular_shapes_or_the_named_ones():
    scene = load_scene(scene_path("sds.xml"), res=16)
    spheres = aim_class()(scene, 0.5).spheres                  # glass sphere and pane
    assert [r for _, r in spheres] == pytest.approx([0.5, math.hypot(2.5, 0.6)], rel=1e-3)
    assert aim_class()(scene, 0.5, "glass-sphere").spheres == spheres[:1]
    assert not aim_class()(load_scene(scene_path("cornell_box.xml"), res=16), 0.5).enabled
    with pytest.raises(ValueError, match="lab_vcm: parameter 'aim_at' names shape 'nosuch', which the scene "
                                         "does not have .*glass-sphere, pane"):
        aim_class()(scene, 0.5, "glass-sphere, nosuch")


def path_stack(name, spp=64):
    """`path` on scenes/``name`` at RES, spp x SEEDS_REF: rendered once per run and variant
    (``agreement.path_reference``; the same stack serves test_bdpt, test_vcm, test_aim)."""
    return path_reference(name, RES, spp, MAX_DEPTH, SEEDS_REF)


AIMED_PLUGINS = [("lab_bdpt", {}), ("lab_vcm", {"mode": "bpt"}),
                 ("lab_vcm", {"radius": 0.02, "light_paths": 2, "pilot": False})]
#: One scene per plugin (both scenes in the suite; their `path` stacks are test_bdpt's too); every
#: plugin on both scenes: benchmarks/agreement/test_aim_matrix.py.
AIMED_CASES = [("caustic.xml", *AIMED_PLUGINS[0]), ("stiff/light_in_glass.xml", *AIMED_PLUGINS[1]),
               ("caustic.xml", *AIMED_PLUGINS[2])]


@pytest.mark.parametrize("name, plugin, params", AIMED_CASES)
def test_aimed_emission_agrees_with_mitsuba_path(name, plugin, params):
    """(Not sds.xml: its light seen through the pane is sampled by path tracing alone and is
    heavy-tailed in 16 seeds, with or without aim.) lab_vcm's mode vcm without its pilot (on by
    default since issue 41): the pilot chose path tracing alone for some seeds of the caustic, so
    their renders were lab_mis's, which has no aimed emission to test, at 4x the cost."""
    scene = load_scene(scene_path(name), res=RES)
    lab = renders(scene, make_integrator(plugin, {"max_depth": MAX_DEPTH, "aim": 0.5, **params}), 16, SEEDS_LAB)
    assert_agrees(lab, path_stack(name), f"{plugin} {params} aim=0.5 on {name}")


def test_lab_photon_keeps_its_expectation():
    """The same radii with and without aim: the same blur, so the same expectation."""
    scene = load_scene(scene_path("caustic.xml"), res=RES)
    settings = {"max_depth": MAX_DEPTH, "radius": 0.05, "passes": 4, "photons_per_pass": 20000}
    plain = renders(scene, make_integrator("lab_photon", settings), 4, SEEDS_LAB)
    aimed = renders(scene, make_integrator("lab_photon", {**settings, "aim": 0.5}), 4, SEEDS_REF)
    assert_agrees(aimed, plain, "lab_photon aim=0.5 against aim=0 on caustic.xml")


@pytest.mark.parametrize("plugin", ["lab_bdpt", "lab_vcm"])     # (lab_photon: test_aim_matrix.py)
def test_no_target_renders_the_same_image(plugin):
    """The default aim (on) and aim 0 render the same image where nothing is aimed at: the Cornell
    box has no specular shape (same random numbers, the light emits as Mitsuba samples it)."""
    scene = load_scene(scene_path("cornell_box.xml"), res=16)
    base = {"max_depth": MAX_DEPTH, **({"pilot": False} if plugin == "lab_vcm" else {})}
    images = [np.array(mi.render(scene, integrator=make_integrator(plugin, p), spp=4, seed=5))
              for p in (base, {**base, "aim": 0.0})]
    # (splats add with float atomics: ~1e-6 from run to run)
    np.testing.assert_allclose(images[0], images[1], rtol=2e-4, atol=1e-5, err_msg=f"{plugin} default aim on the box")


@pytest.mark.parametrize("plugin", ["lab_bdpt", "lab_vcm", "lab_photon"])
def test_refusals_are_one_line(plugin):
    for params, match in (({"aim": 1.0}, "parameter 'aim' must be a number in \\[0, 1\\), got 1.0"),
                          ({"aim": -0.1}, "parameter 'aim' must be"),
                          ({"aim_at": " "}, "parameter 'aim_at' must be 'specular' or shape ids"),
                          ({"aim_at": "a,,b"}, "parameter 'aim_at' must be")):
        with pytest.raises(Exception, match=match):
            make_integrator(plugin, params)
    scene = load_scene(scene_path("sds.xml"), res=8)
    with pytest.raises(Exception) as caught:
        mi.render(scene, integrator=make_integrator(plugin, {"aim": 0.5, "aim_at": "floor"}), spp=1)
    assert one_line(caught.value).startswith(f"{plugin}: parameter 'aim_at' names shape 'floor', which the "
                                             f"scene does not have")
