"""tests/plugins/test_consistency.py's checks over its full lists: every estimator on every scene
against `path` (``ALL_CASES``, 19) and all three direct-only cases against `direct`
(``ALL_DIRECT_CASES``); the module's bias test runs here as it is:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_consistency_matrix.py
"""
import pytest

import test_consistency
from test_consistency import ALL_CASES, ALL_DIRECT_CASES, check_agreement, check_direct_only
from test_consistency import _cache  # noqa: F401  (so the suite's conftest drops its scenes)

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("scene_name, strategy", ALL_CASES)
def test_agrees_with_mitsuba_path(scene_name, strategy):
    check_agreement(scene_name, strategy)


@pytest.mark.parametrize("case", ALL_DIRECT_CASES)
def test_direct_only_agrees_with_mitsuba_direct(case):
    check_direct_only(case)


test_a_three_percent_bias_is_caught = test_consistency.test_a_three_percent_bias_is_caught
