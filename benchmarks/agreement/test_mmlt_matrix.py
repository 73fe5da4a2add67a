"""lab_mmlt's block test in mono and spectral (tests/plugins/test_mmlt.py keeps the RGB one and a
cheap spectral image-mean check): 16 renders a side on the Cornell box against `path`, the
module's own check.

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_mmlt_matrix.py
"""
import pytest

from test_mmlt import check_variant_agrees_with_mitsuba_path

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("kind", ["ad_mono", "ad_spectral"])
def test_variant_agrees_with_mitsuba_path(kind):
    check_variant_agrees_with_mitsuba_path(kind)
