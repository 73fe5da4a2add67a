"""tests/plugins/test_stiff.py's checks over its full lists: every stiff scene x every strategy
for NaN, Inf and negative pixels (``ALL_SAFETY_CASES``) and all 19 agreement cases with `path`
(``ALL_AGREEMENT_CASES``); the module's other tests run here as they are, so this file is the
whole stiff matrix in one run:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_stiff_matrix.py
"""
import pytest

import test_stiff
from test_stiff import ALL_AGREEMENT_CASES, ALL_SAFETY_CASES, check_agreement, check_pixels
from test_stiff import _scenes  # noqa: F401  (so the suite's conftest drops its scenes)

pytestmark = pytest.mark.slow

test_the_suite_has_the_cases_of_the_issue = test_stiff.test_the_suite_has_the_cases_of_the_issue


@pytest.mark.parametrize("scene_name, strategy", ALL_SAFETY_CASES)
def test_no_nan_inf_or_negative_pixels(scene_name, strategy):
    check_pixels(scene_name, strategy)


test_mis_power_reproduces_mitsuba_path_for_the_same_seed = \
    test_stiff.test_mis_power_reproduces_mitsuba_path_for_the_same_seed


@pytest.mark.parametrize("scene_name, strategy, spp", ALL_AGREEMENT_CASES)
def test_agrees_with_mitsuba_path(scene_name, strategy, spp):
    check_agreement(scene_name, strategy, spp)


test_scaling_by_1e4_changes_nothing = test_stiff.test_scaling_by_1e4_changes_nothing
test_scaling_by_1e_4_changes_nothing = test_stiff.test_scaling_by_1e_4_changes_nothing
test_mitsuba_path_is_dark_on_the_tiny_box = test_stiff.test_mitsuba_path_is_dark_on_the_tiny_box
