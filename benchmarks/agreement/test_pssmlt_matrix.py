"""The lab_pssmlt agreement checks too heavy for tests/plugins/test_pssmlt.py: the fog box against
volpath (media through lab_mis's path loop) and the spectral variant's block test against `path`,
with the module's own checks:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_pssmlt_matrix.py
"""
import pytest

from test_pssmlt import check_fog_box_agrees_with_volpath, check_spectral_blocks_agree_with_mitsuba_path

pytestmark = pytest.mark.slow


def test_fog_box_agrees_with_volpath():
    check_fog_box_agrees_with_volpath()


def test_spectral_blocks_agree_with_mitsuba_path():
    check_spectral_blocks_agree_with_mitsuba_path()
