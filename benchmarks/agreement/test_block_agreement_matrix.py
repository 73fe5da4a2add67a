"""tests/plugins/test_block_agreement.py's checks at full size: every estimator on the material
grid (``ALL_GRID_CASES``), the power proof (as benchmarks/power/test_block_power.py runs it), and
the mask's and the instances' findings at 64 seeds a side, not the suite's 16:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_block_agreement_matrix.py
"""
import pytest

from test_block_agreement import (  # noqa: F401  (assets: a fixture)
    ALL_GRID_CASES, SEEDS_LAB, SEEDS_REF, assets, check_grid, check_instances, check_light_tracing_bias_fails, check_mask)
from test_block_agreement import _scenes  # noqa: F401  (so the suite's conftest drops its scenes)

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("kind, params", ALL_GRID_CASES)
def test_material_grid_under_a_point_light_agrees_with_direct_lighting(assets, kind, params):  # noqa: F811
    check_grid(assets, kind, params)


def test_a_three_percent_bias_on_one_strategy_fails_the_block_test(assets, monkeypatch):  # noqa: F811
    check_light_tracing_bias_fails(assets, monkeypatch)


def test_mitsuba_path_drops_light_gathered_on_a_mask(assets):  # noqa: F811
    check_mask(assets, SEEDS_LAB, SEEDS_REF)


def test_instanced_shape_groups_agree_with_mitsuba_path(assets):  # noqa: F811
    check_instances(assets, SEEDS_LAB, SEEDS_REF)
