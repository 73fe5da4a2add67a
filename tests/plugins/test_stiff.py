"""The stiff and extreme scenes (scenes/stiff/): no NaN, Inf or negative pixel from any
applicable lab strategy, and agreement with Mitsuba's `path` where it is affordable.

Three kinds of evidence, cheapest first:

1. Every scene x every applicable strategy (``STRATEGIES``, applicability from
   ``strategy_applicability``) at 24 x 24, 16 spp: all pixels finite and >= 0.
2. lab_mis with the power heuristic draws the same random numbers in the same order
   as Mitsuba's `path` wherever a scene has a smooth BSDF, so for one seed the two
   images agree to float rounding (rtol 1e-5, atol 1e-6): an exact check of the whole
   loop (Russian roulette, MIS weights, emitter sampling) on every such scene.
3. The other strategies against `path` in expectation (tests/agreement.py: 8 x 8
   block and whole-image z-scores, |z| <= Z_BOUND, 12 seeds each, disjoint seed ranges)
   on the scenes where their variance can be estimated from 12 renders. Left out, by
   design: lab_naive on tiny_bright_light (a BSDF ray hits a light of radius 5e-4
   about once in 1e7) and near_delta_glossy; lab_nee on near_delta_glossy (an
   emitter sample lands in a GGX 1e-4 lobe about once in 1e5); both estimators are
   unbiased there but their estimated variance is meaningless at any affordable spp.
   Also lab_naive on grazing_camera: the floor right under the camera sees the light
   with a BSDF-sampling probability of about 6e-5 per path; 12 x 32 spp renders see
   none of it (block means exactly 0, against 6e-4 from `path`, |z| = 595).
"""
import glob
import os

import numpy as np
import pytest

from agreement import Z_BOUND, renders, z_scores
from mitsuba_lab.render import render
from mitsuba_lab.scene import SceneTraits, load_scene, make_integrator, strategy_applicability

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STIFF = sorted(os.path.basename(p) for p in glob.glob(os.path.join(ROOT, "scenes", "stiff", "*.xml")))
RES = 24
SEEDS = 12

STRATEGIES = {
    "naive": ("lab_naive", {}),
    "nee": ("lab_nee", {}),
    "mis_power": ("lab_mis", {"heuristic": "power"}),
    "mis_balance": ("lab_mis", {"heuristic": "balance"}),
    "mis_max_nl2": ("lab_mis", {"heuristic": "max", "emitter_samples": 2}),
    "mis_power10": ("lab_mis", {"heuristic": "power", "beta": 10.0}),
}
MAX_DEPTH = 8

_scenes = {}


def scene(name):
    if name not in _scenes:
        _scenes[name] = load_scene(os.path.join(ROOT, "scenes", "stiff", name), res=RES)
    return _scenes[name]


def test_the_suite_has_the_cases_of_the_issue():
    assert len(STIFF) >= 10
    for name in ("tiny_bright_light", "huge_dim_light", "near_delta_glossy", "delta_lights_only",
                 "environment_only", "all_specular", "light_in_glass", "closed_box_albedo_099",
                 "scaled_1e4", "scaled_1e-4", "grazing_camera", "zero_emitters"):
        assert f"{name}.xml" in STIFF


#: Every scene x every strategy (72 renders): benchmarks/agreement/test_stiff_matrix.py. The suite
#: keeps every scene with lab_naive, lab_nee and one of lab_mis's four settings, rotating over the
#: scenes (36 renders).
ALL_SAFETY_CASES = [(s, k) for s in STIFF for k in STRATEGIES]
MIS_SETTINGS = [k for k in STRATEGIES if k.startswith("mis")]
SAFETY_CASES = [(s, k) for i, s in enumerate(STIFF) for k in ("naive", "nee", MIS_SETTINGS[i % len(MIS_SETTINGS)])]


@pytest.mark.parametrize("scene_name, strategy", SAFETY_CASES)
def test_no_nan_inf_or_negative_pixels(scene_name, strategy):
    check_pixels(scene_name, strategy)


def check_pixels(scene_name, strategy):
    """The strategy's render of the scene: finite and >= 0 everywhere (or the strategy does not apply)."""
    sc = scene(scene_name)
    kind, params = STRATEGIES[strategy]
    applies, reason = strategy_applicability(SceneTraits.from_scene(sc), kind, params)
    if not applies:
        assert "delta lights" in reason          # the only exclusion in this suite
        return
    depth = -1 if scene_name == "closed_box_albedo_099.xml" else MAX_DEPTH
    image, stats = render(sc, make_integrator(kind, {"max_depth": depth, **params}), spp=16, seed=7)
    assert np.isfinite(image).all(), f"{strategy} on {scene_name}: {np.sum(~np.isfinite(image))} non-finite"
    assert (image >= 0).all(), f"{strategy} on {scene_name}: min {image.min()}"
    assert stats.rays["camera"] == RES * RES * 16


def mitsuba_offsets(traits) -> bool:
    """The lab's ray offsets are Mitsuba's (scene coordinates reach 1; ``spawn.offset_floor``)."""
    return max(abs(v) for v in (*traits.bbox_min, *traits.bbox_max)) >= 1


SMOOTH_SCENES = [s for s in STIFF if SceneTraits.from_scene(scene(s)).smooth_bsdf
                 and mitsuba_offsets(SceneTraits.from_scene(scene(s)))]


@pytest.mark.parametrize("scene_name", SMOOTH_SCENES)
def test_mis_power_reproduces_mitsuba_path_for_the_same_seed(scene_name):
    sc = scene(scene_name)
    depth = {"max_depth": -1 if scene_name == "closed_box_albedo_099.xml" else MAX_DEPTH}
    ours, _ = render(sc, make_integrator("lab_mis", depth), spp=16, seed=5)
    theirs, _ = render(sc, make_integrator("path", depth), spp=16, seed=5)
    np.testing.assert_allclose(ours, theirs, rtol=1e-5, atol=1e-6)


ALL_AGREEMENT_CASES = [  # (scene, strategy, spp): affordable and with estimable variance
    ("closed_box_albedo_099.xml", "nee", 32),      # unbounded depth: Russian roulette
    ("closed_box_albedo_099.xml", "naive", 32),
    ("delta_lights_only.xml", "mis_max_nl2", 32),
    ("environment_only.xml", "naive", 32),
    ("environment_only.xml", "nee", 32),
    ("environment_only.xml", "mis_balance", 32),
    ("huge_dim_light.xml", "nee", 32),
    ("zero_emitters.xml", "nee", 32),
    ("zero_emitters.xml", "mis_max_nl2", 32),
    ("all_specular.xml", "naive", 32),
    ("light_in_glass.xml", "nee", 64),
    ("grazing_camera.xml", "mis_balance", 32),
    ("scaled_1e4.xml", "nee", 32),
    ("tiny_bright_light.xml", "nee", 32),
    ("tiny_bright_light.xml", "mis_balance", 32),
    ("huge_dim_light.xml", "naive", 32),
    ("huge_dim_light.xml", "mis_power10", 32),
    ("near_delta_glossy.xml", "mis_balance", 32),
    ("light_in_glass.xml", "naive", 64),
]
#: The suite keeps one case per scene (each stiff scene is its own feature; the references are per
#: scene, so these 11 of the 19 cost all 11 references and 11 lab stacks, not 19); the full list
#: runs in benchmarks/agreement/test_stiff_matrix.py.
KEPT = {"closed_box_albedo_099.xml": "nee", "delta_lights_only.xml": "mis_max_nl2", "environment_only.xml": "naive",
        "huge_dim_light.xml": "mis_power10", "zero_emitters.xml": "nee", "all_specular.xml": "naive",
        "light_in_glass.xml": "nee", "grazing_camera.xml": "mis_balance", "scaled_1e4.xml": "nee",
        "tiny_bright_light.xml": "mis_balance", "near_delta_glossy.xml": "mis_balance"}
AGREEMENT_CASES = [case for case in ALL_AGREEMENT_CASES if KEPT.get(case[0]) == case[1]]
assert len(AGREEMENT_CASES) == len(KEPT)
_refs = {}


def reference(scene_name, spp):
    key = (scene_name, spp)
    if key not in _refs:
        depth = -1 if scene_name == "closed_box_albedo_099.xml" else MAX_DEPTH
        _refs[key] = renders(scene(scene_name), make_integrator("path", {"max_depth": depth}), spp,
                             range(1000, 1000 + SEEDS))
    return _refs[key]


@pytest.mark.parametrize("scene_name, strategy, spp", AGREEMENT_CASES)
def test_agrees_with_mitsuba_path(scene_name, strategy, spp):
    check_agreement(scene_name, strategy, spp)


def check_agreement(scene_name, strategy, spp):
    """The strategy's renders of the scene against `path`'s: |z| <= Z_BOUND."""
    kind, params = STRATEGIES[strategy]
    depth = -1 if scene_name == "closed_box_albedo_099.xml" else MAX_DEPTH
    lab = renders(scene(scene_name), make_integrator(kind, {"max_depth": depth, **params}), spp, range(SEEDS))
    result = z_scores(lab, reference(scene_name, spp))
    assert result.max_abs_z <= Z_BOUND, (f"{strategy} on {scene_name}: max |z| {result.max_abs_z:.2f}, "
                                       f"image z {result.image_z}, relative difference {result.rel_diff}")


def test_scaling_by_1e4_changes_nothing():
    """Radiance is scale-free: the Cornell box scaled by 1e4 renders the same image."""
    plain = load_scene(os.path.join(ROOT, "scenes", "cornell_box.xml"), res=RES)
    big = scene("scaled_1e4.xml")
    a, _ = render(plain, make_integrator("lab_mis", {"max_depth": MAX_DEPTH}), spp=16, seed=2)
    b, _ = render(big, make_integrator("lab_mis", {"max_depth": MAX_DEPTH}), spp=16, seed=2)
    assert abs(a.mean() / b.mean() - 1) < 2e-3


TWIN_STRATEGIES = ("naive", "nee", "mis_power")


@pytest.mark.parametrize("strategy", TWIN_STRATEGIES)
def test_scaling_by_1e_4_changes_nothing(strategy):
    """The Cornell box scaled by 1e-4 renders like the unscaled box (its twin, rendered by
    Mitsuba's `path`): the lab's ray offsets shrink with the scene (``spawn.py``)."""
    kind, params = STRATEGIES[strategy]
    tiny = renders(scene("scaled_1e-4.xml"), make_integrator(kind, {"max_depth": MAX_DEPTH, **params}), 32,
                   range(SEEDS))
    result = z_scores(tiny, unscaled_reference())
    assert result.max_abs_z <= Z_BOUND, (f"{strategy} on scaled_1e-4: max |z| {result.max_abs_z:.2f}, "
                                       f"relative difference {result.rel_diff}")


def test_mitsuba_path_is_dark_on_the_tiny_box():
    """Why the test above compares with the twin: Mitsuba 3.9's own `path` is off at this
    scale (ray offsets of at least 8.9e-5 in a box 2e-4 across): 3-12% dark by channel; the same
    z-test that passes the lab's estimators fails it."""
    tiny = renders(scene("scaled_1e-4.xml"), make_integrator("path", {"max_depth": MAX_DEPTH}), 32,
                   range(SEEDS))
    result = z_scores(tiny, unscaled_reference())
    assert result.max_abs_z > 3 * Z_BOUND and result.rel_diff.mean() < -0.05, result.rel_diff


def unscaled_reference():
    if "twin" not in _refs:
        plain = load_scene(os.path.join(ROOT, "scenes", "cornell_box.xml"), res=RES)
        _refs["twin"] = renders(plain, make_integrator("path", {"max_depth": MAX_DEPTH}), 32,
                                range(1000, 1000 + SEEDS))
    return _refs["twin"]
