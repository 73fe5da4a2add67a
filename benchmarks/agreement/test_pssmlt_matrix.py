"""The lab_pssmlt agreement check that left tests/plugins/test_pssmlt.py for its cost: the fog box
against volpath (media through lab_mis's path loop), with the module's own check:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_pssmlt_matrix.py
"""
import pytest

from test_pssmlt import check_fog_box_agrees_with_volpath

pytestmark = pytest.mark.slow


def test_fog_box_agrees_with_volpath():
    check_fog_box_agrees_with_volpath()
