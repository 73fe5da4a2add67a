"""tests/plugins/test_user_scenes.py's checks over its full lists: the whole Latin square
(``ALL_LATIN_CASES``), lab_photon's lobe check on all three boxes (``ALL_LOBE_CASES``) and its
convergence on every scene (``ALL_PHOTON_CASES``), every path tracer on both scenes in mono and
spectral (``ALL_OTHER_VARIANT_CASES``), and both power proofs (x 1.03, one bounce too few):

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_user_scenes_matrix.py

The `path` references here have REF_FACTOR = 8 x the scene's spp, the suite's 4 (the measured
largest |z| at each: test_user_scenes' docstring).
"""
import pytest

from test_user_scenes import (  # noqa: F401  (assets, variant: fixtures)
    ALL_LATIN_CASES, ALL_LOBE_CASES, ALL_OTHER_VARIANT_CASES, ALL_PHOTON_CASES, RGB, assets, check_latin_slot,
    check_one_bounce_too_few_fails, check_other_variant, check_photon_converges, check_photon_lobe,
    check_three_percent_fails, other_variant_params, variant)

pytestmark = pytest.mark.slow

REF_FACTOR = 8


@pytest.mark.parametrize("variant, name, slot", ALL_LATIN_CASES, indirect=["variant"])
def test_path_tracers_agree_with_path(variant, assets, name, slot):  # noqa: F811
    check_latin_slot(variant, assets, name, slot, REF_FACTOR)


@pytest.mark.parametrize("variant", [RGB], indirect=True)
def test_a_biased_renderer_fails(variant, assets):  # noqa: F811
    check_three_percent_fails(variant, assets, REF_FACTOR)
    check_one_bounce_too_few_fails(variant, assets, REF_FACTOR)


@pytest.mark.parametrize("variant", [RGB], indirect=True)
@pytest.mark.parametrize("name, shape_id", ALL_LOBE_CASES)
def test_photon_keeps_the_light_of_every_lobe(variant, assets, name, shape_id):  # noqa: F811
    check_photon_lobe(variant, assets, name, shape_id, REF_FACTOR)


@pytest.mark.parametrize("variant, name", ALL_PHOTON_CASES, indirect=["variant"])
def test_photon_converges_to_path(variant, assets, name):  # noqa: F811
    check_photon_converges(variant, assets, name, REF_FACTOR)


@pytest.mark.parametrize("variant, name, estimator", other_variant_params(ALL_OTHER_VARIANT_CASES),
                         indirect=["variant"])
def test_path_tracers_agree_under_mono_and_spectral(variant, assets, name, estimator):  # noqa: F811
    check_other_variant(variant, assets, name, estimator, REF_FACTOR)
