"""The cases of tests/plugins/test_vcm.py's agreement matrices that the suite no longer runs (the
suite's cases plus these are the matrices as they stood at 6b50876), with the same helpers:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_vcm_matrix.py
"""
import pytest

import test_vcm
from test_vcm import MOVED_MERGING_CASES, MOVED_STIFF_CASES


@pytest.mark.parametrize("name, mode, merge_first", MOVED_MERGING_CASES)
def test_merging_agrees_with_mitsuba_path(name, mode, merge_first):
    test_vcm.test_merging_agrees_with_mitsuba_path(name, mode, merge_first)


def test_the_constant_kernel_agrees_with_mitsuba_path():
    test_vcm.test_the_constant_kernel_agrees_with_mitsuba_path("cornell_box.xml")


def test_more_light_paths_agree_with_mitsuba_path():
    test_vcm.test_more_light_paths_agree_with_mitsuba_path("cornell_box.xml")


def test_fewer_light_paths_agree_with_mitsuba_path():
    test_vcm.test_fewer_light_paths_agree_with_mitsuba_path("caustic.xml")


@pytest.mark.parametrize("name, merge_first, merge_vertices", MOVED_STIFF_CASES)
def test_no_nan_inf_or_negative_on_stiff_scenes(name, merge_first, merge_vertices):
    test_vcm.test_no_nan_inf_or_negative_on_stiff_scenes(name, merge_first, merge_vertices)
