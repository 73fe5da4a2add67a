"""SceneTraits, strategy applicability and equivalence on the stiff scenes, and the
traits-driven kernels: code a scene cannot use is left out, and the ray counters show it.

Equivalence is checked where it is provable *per seed*: when two strategies compile the
same kernel for a scene (same sampler dimensions in the same order), their images for
one seed are bit-identical. That is stronger than agreement in expectation.
"""
import dataclasses
import os

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from backend import HOME, variant
from mitsuba_lab.plugins.integrators.common.mis_weight import mis_weight
from mitsuba_lab.plugins.integrators.path import KernelPlan
from mitsuba_lab.plugins.integrators.common.roulette import rr_scale, russian_roulette, survival_probability
from mitsuba_lab.render import render
from mitsuba_lab.scene import (SceneTraits, equivalent_strategies, load_scene, make_integrator,
                               strategy_applicability)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STRATEGIES = {
    "naive": ("lab_naive", {}),
    "nee": ("lab_nee", {}),
    "mis_power": ("lab_mis", {}),
    "mis_balance": ("lab_mis", {"heuristic": "balance", "count_rays": False}),
    "mis_max": ("lab_mis", {"heuristic": "max"}),
    "mis_power_b1": ("lab_mis", {"heuristic": "power", "beta": 1.0}),
    "mis_nl2": ("lab_mis", {"emitter_samples": 2}),
    "nee_depth4": ("lab_nee", {"max_depth": 4}),
    "path": ("path", {}),
}


def traits(name, **params):
    return SceneTraits.from_scene(load_scene(os.path.join(ROOT, "scenes", "stiff", name), **params))


# -- SceneTraits ---------------------------------------------------------------------------

def test_traits_of_the_stiff_scenes():
    t = traits("delta_lights_only.xml")
    assert t.emitter_kinds == {"delta"} and t.delta_emitters == ("point", "spot", "directional")
    assert not t.hittable_emitters and t.smooth_bsdf and not t.media and t.emits_light
    t = traits("environment_only.xml")
    assert t.emitter_kinds == {"environment"} and t.hittable_emitters
    t = traits("all_specular.xml")
    assert t.all_bsdfs_delta and not t.smooth_bsdf and t.emitter_kinds == {"area"}
    t = traits("zero_emitters.xml")
    assert set(t.dark_emitters) == {"zero_area_light", "zero_radiance_light"} and t.emits_light
    assert sum("emits nothing" in w for w in t.warnings()) == 2
    t = traits("near_delta_glossy.xml")
    assert t.smooth_bsdf and not t.all_bsdfs_delta          # GGX 1e-4 is glossy, not delta
    assert traits("scaled_1e4.xml").extent == pytest.approx(2e4 * 3 ** 0.5, rel=0.01)
    assert traits("scaled_1e-4.xml").extent == pytest.approx(2e-4 * 3 ** 0.5, rel=0.01)
    for name in os.listdir(os.path.join(ROOT, "scenes", "stiff")):
        if name.endswith(".xml"):                          # (regions files live there too)
            assert not traits(name).far_clip_problems, name


def test_far_clip_problem_is_found():
    t = traits("scaled_1e4.xml", far_clip=1e4)      # Mitsuba's default far_clip
    assert len(t.far_clip_problems) == 1 and "beyond far_clip = 1e+04" in t.warnings()[0]


def test_media_are_reported():
    scene = mi.load_dict({"type": "scene", "ball": {
        "type": "sphere", "bsdf": {"type": "null"},
        "interior": {"type": "homogeneous", "albedo": 0.5, "sigma_t": 1.0}},
        "light": {"type": "constant"}})
    t = SceneTraits.from_scene(scene)
    assert t.media and any("participating media" in w for w in t.warnings())
    applies, reason = strategy_applicability(t, "lab_mmlt", {})
    assert not applies and "participating media" in reason and "volpath" in reason
    assert strategy_applicability(t, "lab_bdpt", {}) == (True, "")     # homogeneous media: rendered
    assert strategy_applicability(t, "lab_photon", {}) == (True, "")   # volumetric photons
    assert strategy_applicability(t, "lab_mis", {}) == (True, "")      # the path family renders media
    assert strategy_applicability(t, "volpath", {}) == (True, "")


def test_no_emitter_at_all():
    scene = mi.load_dict({"type": "scene", "ball": {"type": "sphere"}})
    t = SceneTraits.from_scene(scene)
    assert t.emitters == 0 and not t.emits_light and "every image is black" in t.warnings()[-1]
    assert len(set(equivalent_strategies(t, STRATEGIES).values())) == 2   # the lab's, and path


# -- Applicability -------------------------------------------------------------------------

def test_naive_is_left_out_where_it_cannot_reach_the_lights():
    applies, reason = strategy_applicability(traits("delta_lights_only.xml"), "lab_naive", {})
    assert not applies
    assert reason == ("lab_naive cannot reach delta lights (point, spot, directional): "
                      "the scene has no other emitter")
    for name in ("delta_lights_only.xml", "all_specular.xml", "tiny_bright_light.xml"):
        for kind in ("lab_nee", "lab_mis", "path"):
            assert strategy_applicability(traits(name), kind, {}) == (True, "")


def test_naive_with_delta_and_area_lights_is_biased():
    scene = mi.load_dict({"type": "scene", "floor": {"type": "rectangle"},
                          "lamp": {"type": "point", "position": [0, 0, 2]}, "sky": {"type": "constant"}})
    applies, reason = strategy_applicability(SceneTraits.from_scene(scene), "lab_naive", {})
    assert not applies and "(point)" in reason and "biased" in reason


def test_naive_is_left_out_under_a_point_light_whose_only_smooth_vertices_are_in_a_medium():
    """A point light in fog inside a null box, no other surface: the phase function is smooth,
    so NEE reaches the light from medium vertices and lab_naive cannot (|z| 264 when rendered)."""
    scene = mi.load_dict({"type": "scene", "box": {"type": "cube", "bsdf": {"type": "null"},
                                                   "interior": {"type": "homogeneous", "sigma_t": 0.5}},
                          "lamp": {"type": "point", "position": [0, 0, 0]}})
    t = SceneTraits.from_scene(scene)
    assert t.media and not t.smooth_bsdf
    applies, reason = strategy_applicability(t, "lab_naive", {})
    assert not applies and "cannot reach delta lights (point)" in reason


# -- Equivalence ---------------------------------------------------------------------------

def test_equivalences_on_an_ordinary_scene():
    same = equivalent_strategies(traits("tiny_bright_light.xml"), STRATEGIES)
    assert same["mis_power_b1"] == "mis_balance"             # power with beta 1 is balance
    others = {k: v for k, v in same.items() if k != "mis_power_b1"}
    assert all(k == v for k, v in others.items())


def test_equivalences_with_delta_lights_only():
    same = equivalent_strategies(traits("delta_lights_only.xml"), STRATEGIES)
    for name in ("mis_power", "mis_balance", "mis_max", "mis_power_b1"):
        assert same[name] == "nee"                           # every MIS weight is 1
    assert same["mis_nl2"] == "mis_nl2"                      # two shadow rays: another estimator
    assert same["nee_depth4"] == "nee_depth4" and same["naive"] == "naive" and same["path"] == "path"


def test_equivalences_when_every_bsdf_is_delta():
    same = equivalent_strategies(traits("all_specular.xml"), STRATEGIES)
    for name in ("nee", "mis_power", "mis_balance", "mis_max", "mis_power_b1", "mis_nl2"):
        assert same[name] == "naive"
    assert same["nee_depth4"] == "nee_depth4" and same["path"] == "path"


def test_max_depth_one_and_zero():
    t = traits("delta_lights_only.xml")
    one = {k: (kind, {**p, "max_depth": 1}) for k, (kind, p) in STRATEGIES.items() if kind != "path"}
    assert set(equivalent_strategies(t, one).values()) == {"naive"}
    zero = {k: (kind, {**p, "max_depth": 0}) for k, (kind, p) in one.items()}
    assert set(equivalent_strategies(t, zero).values()) == {"naive"}


def image(scene, kind, params, seed=3, spp=8):
    return render(scene, make_integrator(kind, {"max_depth": 8, **params}), spp=spp, seed=seed)


@pytest.mark.slow
@pytest.mark.parametrize("scene_name", ["all_specular.xml", "delta_lights_only.xml"])
def test_equivalent_strategies_render_identical_images(scene_name):
    """The equivalence classes hold per seed: the kernels are the same code."""
    scene = load_scene(os.path.join(ROOT, "scenes", "stiff", scene_name), res=16)
    same = equivalent_strategies(SceneTraits.from_scene(scene), STRATEGIES)
    for name, canonical in same.items():
        if name != canonical and STRATEGIES[name][0] != "path":
            ours, _ = image(scene, *STRATEGIES[name])
            theirs, _ = image(scene, *STRATEGIES[canonical])
            assert np.array_equal(ours, theirs), (name, canonical)


# -- Traits-driven kernels -----------------------------------------------------------------

def test_no_shadow_rays_where_no_vertex_can_use_them():
    scene = load_scene(os.path.join(ROOT, "scenes", "stiff", "all_specular.xml"), res=16)
    t = SceneTraits.from_scene(scene)
    assert (t.hittable_emitters, t.emitters > 0, t.smooth_bsdf) == (True, True, False)
    plan = KernelPlan.of(t, make_integrator("lab_mis", {}).estimator)
    # emitter hits, no NEE, every hit delta; Mitsuba's ray offsets
    assert dataclasses.astuple(plan) == (True, False, True, 1.0, False)
    counts = {}
    for kind, params in (("lab_naive", {}), ("lab_nee", {}), ("lab_mis", {"emitter_samples": 3})):
        _, stats = image(scene, kind, params)
        counts[kind] = stats.rays
        assert stats.rays["shadow"] == 0 and stats.rays["extension"] > 0
    assert counts["lab_nee"] == counts["lab_mis"] == counts["lab_naive"]


@pytest.mark.slow
def test_kernels_leave_out_what_the_scene_lacks():
    """Smaller kernels: lab_mis on the all-specular scene compiles no emitter sampling or
    emitter-pdf code, on the delta-light scene no emitter-hit code."""
    def kernel_size(scene, kind, params):
        integrator = make_integrator(kind, {"max_depth": 8, **params})
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()
        dr.eval(mi.render(scene, integrator=integrator, spp=1, seed=0))
        dr.sync_thread()
        history = dr.kernel_history()
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        return max(k.get("ir", "").count("\n") if isinstance(k.get("ir"), str) else k.get("operation_count", 0)
                   for k in history)

    specular = load_scene(os.path.join(ROOT, "scenes", "stiff", "all_specular.xml"), res=8)
    ordinary = load_scene(os.path.join(ROOT, "scenes", "stiff", "tiny_bright_light.xml"), res=8)
    naive = kernel_size(specular, "lab_naive", {})
    mis_specular = kernel_size(specular, "lab_mis", {})
    mis_ordinary = kernel_size(ordinary, "lab_mis", {})
    assert mis_specular == naive < mis_ordinary


# -- Extreme values in the shared pieces ---------------------------------------------------

def test_mis_weight_ignores_a_broken_other_density():
    nan = float("nan")
    w = np.array(mis_weight(mi.Float([1.0, 1.0, 1e-30]), mi.Float([nan, -2.0, nan]), "power"))
    assert np.array_equal(w, [1.0, 1.0, 1.0])


def test_russian_roulette_at_extreme_throughputs():
    beta = mi.Spectrum(mi.Float([0.0, 1e-30, 1e30, float("inf"), float("nan")]))
    q = survival_probability(beta, mi.Float(1.0))
    values = np.array(q)
    assert np.all(np.isfinite(values)) and np.all((values >= 0) & (values <= 0.95))
    assert values[0] == 0.0 and values[1] == pytest.approx(1e-30, rel=1e-6) and values[2] == 0.95
    scale = np.array(rr_scale(q))
    assert scale[0] == 0.0 and np.all(np.isfinite(scale))


def test_russian_roulette_for_camera_paths_and_photons():
    """One rule: q = min(max(beta) / start * eta^2, 0.95); survivors are divided by q."""
    beta = mi.Spectrum(mi.Float([0.5, 0.5, 2.0]), mi.Float([0.2, 0.2, 1.0]), mi.Float([0.1, 0.1, 1.0]))
    q_camera = np.array(survival_probability(beta, eta=mi.Float([1.0, 1.5, 1.0])))
    np.testing.assert_allclose(q_camera, [0.5, 0.95, 0.95], rtol=1e-6)      # 0.5 * 1.5^2 > 0.95
    q_photon = np.array(survival_probability(beta, start=mi.Float(4.0)))
    np.testing.assert_allclose(q_photon, [0.125, 0.125, 0.5], rtol=1e-6)
    rr_active = mi.Bool([True, True, False])
    out, survives = russian_roulette(beta, mi.Float([0.1, 0.9, 0.9]), rr_active, eta=mi.Float(1.0))
    assert list(np.array(survives)) == [True, False, True]                 # u < q, or no roulette
    np.testing.assert_allclose(np.array(out)[0], [1.0, 0.5 / 0.5, 2.0], rtol=1e-6)


@pytest.mark.slow
def test_a_grey_rgb_emitter_is_not_dark_in_a_spectral_variant():
    """In spectral variants an RGB emission becomes sigmoid-polynomial coefficients times D65,
    and a grey of 0.5 has all-zero coefficients: that is light, not a zero factor."""
    import mitsuba_lab

    try:
        mitsuba_lab.use_variant(variant("ad_spectral"))
        scene = mi.load_dict({"type": "scene", "floor": {"type": "rectangle"},
                              "light": {"type": "point", "position": [0, 0, 1],
                                        "intensity": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}})
        t = SceneTraits.from_scene(scene)
        assert not t.dark_emitters and not any("emits nothing" in w for w in t.warnings())
    finally:
        mitsuba_lab.use_variant(HOME)

