"""The lab's plugins in every variant of the run's backend that this Mitsuba build offers (rgb,
mono, spectral and their polarized forms; llvm_ad_* unless MITSUBA_LAB_VARIANT names a
cuda_ad_* variant, tests/backend.py): every unbiased lab estimator and every lab sampler agrees with
Mitsuba's `path` (with the independent sampler) in expectation, with no NaN, Inf or negative
pixel.

Tolerance: |z| <= Z_BOUND (tests/agreement.py) for every 8x8 block mean and every whole-image channel mean
(Welch, 16 seeds a side, about 30 degrees of freedom; at most 4 x 3 blocks x 3 channels + 3 =
39 z-scores a case, 20 cases here, 45 in benchmarks/agreement/test_variants_matrix.py). Under agreement P(|t_30| > 5) = 2.3e-5, so the whole file fails
by chance with probability < 0.04 (fewer in fact: the z-scores of a case are correlated);
seeds are fixed, so a run is deterministic. Power: a 3% bias gives |z| > 5 in every variant
(test_a_three_percent_bias_is_caught_in_every_variant).
"""
import pytest

import mitsuba as mi
import backend
import mitsuba_lab
from agreement import Z_BOUND, pixel_problem, renders, z_scores
from mitsuba_lab.scene import make_integrator

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

SEEDS = 16
REF_SEEDS = range(1000, 1000 + SEEDS)
LAB_SEEDS = range(SEEDS)
SPP = 32
VARIANTS = [v for v in (backend.variant(kind) for kind in ("ad_rgb", "ad_mono", "ad_spectral", "ad_mono_polarized",
                                                           "ad_spectral_polarized")) if v in mi.variants()]
ESTIMATORS = {"lab_naive": {}, "lab_nee": {}, "lab_mis": {"heuristic": "power"},
              "lab_mis_balance_nl2": {"heuristic": "balance", "emitter_samples": 2}}
SAMPLERS = {"lab_stratified": {}, "lab_sobol": {}, "lab_zsobol": {"width": 32}, "lab_halton": {}}
#: Shared by the reference and every estimator.
DEPTH = {"max_depth": 5}


def box(sampler: dict | None = None) -> dict:
    """The Cornell box on a 32x24 film, with a rough-plastic sphere (a glossy, coloured
    lobe and a diffuse one) and the area light (which lab_naive can hit)."""
    scene = mi.cornell_box()
    scene["sensor"]["film"].update(width=32, height=24)
    scene["sensor"]["sampler"] = sampler or {"type": "independent"}
    scene["sphere"] = {"type": "sphere", "radius": 0.3,
                       "to_world": mi.ScalarTransform4f().translate([0.3, -0.7, 0.2]),
                       "bsdf": {"type": "roughplastic", "alpha": 0.2,
                                "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.8]}}}
    return scene


#: The suite keeps, per variant, lab_mis (whose stack the bias test scales), one other estimator and
#: one sampler, rotating so that every estimator and every sampler runs in some variant and every
#: variant runs three lab stacks against its reference (9 before). Every estimator (``ESTIMATORS``)
#: and every sampler (``SAMPLERS``) in every variant: benchmarks/agreement/test_variants_matrix.py.
OTHER_ESTIMATORS = [e for e in ESTIMATORS if e != "lab_mis"]
ESTIMATOR_CASES = [(v, e) for i, v in enumerate(VARIANTS) for e in ("lab_mis", OTHER_ESTIMATORS[i % len(OTHER_ESTIMATORS)])]
SAMPLER_CASES = [(v, list(SAMPLERS)[i % len(SAMPLERS)]) for i, v in enumerate(VARIANTS)]


#: Per variant, the stacks rendered (numpy, kept for the module: pytest does not keep the cases of
#: one variant together across the three test functions, so the fixture is set up once per run of
#: consecutive cases, and the reference and lab_mis's stack would otherwise be rendered again).
_stacks: dict = {}


@pytest.fixture(scope="module")
def variant(request):
    yield from in_variant(request.param)


def in_variant(name):
    """The body of a `variant` fixture: the variant switched on, with its stacks; the run's own
    variant back at teardown."""
    mitsuba_lab.use_variant(name)
    cache = _stacks.setdefault(name, {})
    cache.pop("scene", None)               # (a scene belongs to one activation of its variant)
    yield name, cache
    cache.pop("scene", None)
    mitsuba_lab.use_variant(backend.HOME)


def reference(cache):
    if "scene" not in cache:
        cache["scene"] = mi.load_dict(box())
    if "ref" not in cache:
        cache["ref"] = renders(cache["scene"], make_integrator("path", DEPTH), SPP, REF_SEEDS)
    return cache["ref"]


def assert_agrees(images, ref, label, variant):
    problem = pixel_problem(images, "spectral" in variant)
    assert not problem, f"{label}: {problem}"
    result = z_scores(images, ref)
    assert result.max_abs_z <= Z_BOUND, (f"{label}: max |z| {result.max_abs_z:.2f}, image z {result.image_z}, "
                                       f"relative difference of means {result.rel_diff}")


def estimator_images(cache, strategy):
    """The estimator's renders of the box (once per variant: the bias test reuses lab_mis's)."""
    if strategy not in cache:
        kind = "lab_mis" if strategy.startswith("lab_mis") else strategy
        cache[strategy] = renders(cache["scene"], make_integrator(kind, {**DEPTH, **ESTIMATORS[strategy]}), SPP,
                                  LAB_SEEDS)
    return cache[strategy]


@pytest.mark.parametrize("variant, strategy", ESTIMATOR_CASES, indirect=["variant"])
def test_estimators_agree_with_path_in_every_variant(variant, strategy):
    check_estimator(variant, strategy)


def check_estimator(variant, strategy):
    """The estimator's renders of the box in the variant against `path`'s: |z| <= Z_BOUND, sound pixels."""
    name, cache = variant
    ref = reference(cache)
    images = estimator_images(cache, strategy)
    assert images.shape == ref.shape
    assert_agrees(images, ref, f"{strategy} in {name}", name)


@pytest.mark.parametrize("variant, sampler", SAMPLER_CASES, indirect=["variant"])
def test_samplers_agree_with_independent_in_every_variant(variant, sampler):
    check_sampler(variant, sampler)


def check_sampler(variant, sampler):
    """lab_mis with the sampler in the variant against `path` with the independent one."""
    name, cache = variant
    ref = reference(cache)
    scene = mi.load_dict(box({"type": sampler, **SAMPLERS[sampler]}))
    images = renders(scene, make_integrator("lab_mis", DEPTH), SPP, LAB_SEEDS)
    assert_agrees(images, ref, f"lab_mis with {sampler} in {name}", name)


@pytest.mark.parametrize("variant", VARIANTS, indirect=True)
def test_a_three_percent_bias_is_caught_in_every_variant(variant):
    check_bias_is_caught(variant)


def check_bias_is_caught(variant):
    """lab_mis's renders x 1.03 fail the agreement check."""
    name, cache = variant
    ref = reference(cache)
    images = estimator_images(cache, "lab_mis")       # (the renders that agree, scaled by 1.03)
    assert z_scores(images * 1.03, ref).max_abs_z > Z_BOUND, name
