"""tests/plugins/test_bdpt_media.py's agreement with volpath over its full scene lists: every
homogeneous scene (fog behind a null box at sigma_t 2.5, a point light inside fog, a chromatic
medium inside glass, fog_shafts.xml at 24 x 24) and every heterogeneous case (a spot into smoke in rgb with global
majorants, a point light inside the plume in mono with the majorant grid). Same tolerance and
seeds as the suite's cases.

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_bdpt_media_matrix.py
"""
import pytest

from test_bdpt_media import ALL_HETEROGENEOUS, ALL_HOMOGENEOUS, check_heterogeneous, check_homogeneous

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("name", ALL_HOMOGENEOUS)
def test_lab_bdpt_agrees_with_volpath(name):
    check_homogeneous(name)


@pytest.mark.parametrize("kind, name, params", ALL_HETEROGENEOUS)
def test_lab_bdpt_agrees_with_volpath_in_heterogeneous_media(kind, name, params):
    check_heterogeneous(kind, name, params)
