"""tests/plugins/test_emitters_and_materials.py's agreement check over every strategy on both
emitter scenes (``ALL_CASES``, 11), and the module's other test as it is:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_emitters_and_materials_matrix.py
"""
import pytest

import test_emitters_and_materials
from test_emitters_and_materials import ALL_CASES, check_agreement
from test_emitters_and_materials import _cache  # noqa: F401  (so the suite's conftest drops its scenes)

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("scene_name, strategy", ALL_CASES)
def test_agrees_with_mitsuba_path(scene_name, strategy):
    check_agreement(scene_name, strategy)


test_naive_misses_delta_lights = test_emitters_and_materials.test_naive_misses_delta_lights
