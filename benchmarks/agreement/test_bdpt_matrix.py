"""The cases of tests/plugins/test_bdpt.py's agreement matrices that the suite no longer runs (the
suite's cases plus these are the matrices as they stood at 6b50876), with the same helpers:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_bdpt_matrix.py
"""
import pytest

import test_bdpt
from test_bdpt import MOVED_LIGHT_PATHS_CASES, MOVED_SCENES, MOVED_USER_SCENES, user_assets  # noqa: F401


def test_spectral_variant_agrees_with_mitsuba_path(tmp_path):
    """lab_bdpt in the spectral variant (the suite covers the engine in spectral through lab_vcm's
    mode vcm, tests/plugins/test_vcm.py)."""
    test_bdpt.check_spectral_variant_agrees_with_mitsuba_path(tmp_path)


@pytest.mark.parametrize("name", MOVED_SCENES)
def test_agrees_with_mitsuba_path(name):
    test_bdpt.test_agrees_with_mitsuba_path(name)


@pytest.mark.parametrize("name", MOVED_USER_SCENES)
def test_users_scenes_agree_with_mitsuba_path(user_assets, name):  # noqa: F811
    test_bdpt.test_users_scenes_agree_with_mitsuba_path(user_assets, name)


@pytest.mark.parametrize("name, light_paths", MOVED_LIGHT_PATHS_CASES)
def test_light_paths_ratio_agrees_with_mitsuba_path(name, light_paths):
    test_bdpt.test_light_paths_ratio_agrees_with_mitsuba_path(name, light_paths)
