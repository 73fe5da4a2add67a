"""Every unbiased lab estimator agrees with Mitsuba's own `path` (and `direct`) in expectation.

Tolerance: |z| <= Z_BOUND (tests/agreement.py, with its false-failure probability) for every
8x8 block mean and every whole-image channel mean (about 50 z-scores per case). Power: the
whole-image mean
has a relative standard error of about 0.3-0.6% here, so an estimator 3% off
gives |z| > 5 (checked by test_a_three_percent_bias_is_caught).
"""
import os

import pytest

from agreement import Z_BOUND, renders, z_scores
from mitsuba_lab.scene import load_scene, make_integrator

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RES = 32
SEEDS = 16
REF_SEEDS = range(1000, 1000 + SEEDS)
LAB_SEEDS = range(SEEDS)

SCENES = {  # scene -> (spp, shared integrator parameters)
    "cornell_box.xml": (128, {"max_depth": 6}),
    "glossy_small_light.xml": (128, {"max_depth": 6}),
    # The tiny directly visible lights (radiance 901) would dominate the image mean with
    # sub-pixel coverage noise; hiding them (Mitsuba's meaning: camera rays pass through area
    # emitters) leaves the plates' glossy reflections, which are what the scene is about.
    "veach_mis.xml": (128, {"max_depth": 4, "hide_emitters": True}),
}
STRATEGIES = {
    "nee": ("lab_nee", {}),
    "mis_power": ("lab_mis", {"heuristic": "power"}),
    "mis_balance": ("lab_mis", {"heuristic": "balance"}),
    "mis_max": ("lab_mis", {"heuristic": "max"}),
    "mis_average": ("lab_mis", {"heuristic": "average"}),
    "mis_power3_nl2": ("lab_mis", {"heuristic": "power", "beta": 3.0, "emitter_samples": 2}),
    "naive": ("lab_naive", {}),
}
# lab_naive is unbiased on these scenes (area lights only) but heavy-tailed where the light is
# tiny: 8 seeds cannot estimate its variance there, so it is checked where its noise is tame.
NAIVE_SCENES = {"cornell_box.xml"}

_cache = {}


def scene_for(name):
    if name not in _cache:
        _cache[name] = load_scene(os.path.join(ROOT, "scenes", name), res=RES)
    return _cache[name]


def reference(name):
    key = ("ref", name)
    if key not in _cache:
        spp, shared = SCENES[name]
        _cache[key] = renders(scene_for(name), make_integrator("path", shared), spp, REF_SEEDS)
    return _cache[key]


def lab_stack(name, strategy):
    """The strategy's renders of the scene (once: the bias test scales mis_power's on the box)."""
    key = ("lab", name, strategy)
    if key not in _cache:
        spp, shared = SCENES[name]
        kind, params = STRATEGIES[strategy]
        _cache[key] = renders(scene_for(name), make_integrator(kind, {**shared, **params}), spp, LAB_SEEDS)
    return _cache[key]


#: The full scene x strategy matrix (19 cases): benchmarks/agreement/test_consistency_matrix.py.
ALL_CASES = [(scene, strategy) for scene in SCENES for strategy in STRATEGIES
             if strategy != "naive" or scene in NAIVE_SCENES]
#: The suite keeps one case per estimator on the box (lab_naive, lab_nee, lab_mis with the power
#: heuristic, whose stack the bias test scales) and one lab_mis case per other scene (the balance
#: heuristic under the small light; power with beta 3 and two emitter samples on Veach's plates):
#: every estimator and every scene.
CASES = [("cornell_box.xml", "naive"), ("cornell_box.xml", "nee"), ("cornell_box.xml", "mis_power"),
         ("glossy_small_light.xml", "mis_balance"), ("veach_mis.xml", "mis_power3_nl2")]


@pytest.mark.parametrize("scene_name, strategy", CASES)
def test_agrees_with_mitsuba_path(scene_name, strategy):
    check_agreement(scene_name, strategy)


def check_agreement(scene_name, strategy):
    """The strategy's renders of the scene against `path`'s: |z| <= Z_BOUND."""
    result = z_scores(lab_stack(scene_name, strategy), reference(scene_name))
    assert result.max_abs_z <= Z_BOUND, (
        f"{strategy} on {scene_name}: max |z| = {result.max_abs_z:.2f}, image z = {result.image_z}, "
        f"relative difference of means = {result.rel_diff}")


ALL_DIRECT_CASES = {  # lab strategy -> Mitsuba `direct` parameters that make the same estimator family
    "lab_mis_nl2": (("lab_mis", {"emitter_samples": 2}), {"emitter_samples": 2, "bsdf_samples": 1}),
    "lab_nee": (("lab_nee", {}), {"emitter_samples": 1, "bsdf_samples": 0}),
    "lab_naive": (("lab_naive", {}), {"emitter_samples": 0, "bsdf_samples": 1}),
}


#: The suite keeps lab_mis's (lab_nee's and lab_naive's run in the matrix).
DIRECT_CASES = ["lab_mis_nl2"]


@pytest.mark.parametrize("case", DIRECT_CASES)
def test_direct_only_agrees_with_mitsuba_direct(case):
    check_direct_only(case)


def check_direct_only(case):
    """The case's lab estimator at max_depth 2 against Mitsuba's `direct`: |z| <= Z_BOUND."""
    # max_depth 2 = emitters seen directly + one bounce of direct light (no delta BSDFs here,
    # where Mitsuba's `direct` and lab_nee would differ by design).
    (kind, params), direct_params = ALL_DIRECT_CASES[case]
    scene = scene_for("cornell_box.xml")
    lab = renders(scene, make_integrator(kind, {"max_depth": 2, **params}), 128, LAB_SEEDS)
    ref = renders(scene, make_integrator("direct", direct_params), 128, REF_SEEDS)
    result = z_scores(lab, ref)
    assert result.max_abs_z <= Z_BOUND, f"{case}: max |z| = {result.max_abs_z:.2f}, image z = {result.image_z}"


def test_a_three_percent_bias_is_caught():
    """The test above has the power it claims: a 3% error fails it."""
    lab = lab_stack("cornell_box.xml", "mis_power")      # (the renders that agree, scaled by 1.03)
    result = z_scores(lab * 1.03, reference("cornell_box.xml"))
    assert result.max_abs_z > Z_BOUND


