"""The cases of tests/plugins/test_vcm.py's agreement matrices that the suite no longer runs (the
suite's cases plus these are the matrices as they stood at 6b50876), with the same helpers; and,
since 2026-11-28, ppm's variance against lab_photon's and the pilot's own choice against `path`:

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


def test_merging_has_lab_photons_variance_at_equal_light_vertices():
    """The suite's size of the check (8 seeds a side, bound 0.6); benchmarks/vcm_variance.py runs it
    at 24 seeds and a bound of 0.2."""
    test_vcm.check_merging_has_lab_photons_variance_at_equal_light_vertices()


def test_the_pilots_own_choice_agrees_with_mitsuba_path():
    import test_vcm_choices

    test_vcm_choices.check_the_pilots_own_choice_agrees_with_mitsuba_path()
