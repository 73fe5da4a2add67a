"""lab_mmlt's block test in mono (tests/plugins/test_mmlt.py keeps the RGB one): 16 renders a side
on the Cornell box against `path`, the module's own check.

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_mmlt_matrix.py
"""
import pytest

from test_mmlt import check_mono_agrees_with_mitsuba_path

pytestmark = pytest.mark.slow


def test_mono_agrees_with_mitsuba_path():
    check_mono_agrees_with_mitsuba_path()
