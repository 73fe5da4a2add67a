"""tests/plugins/test_photon.py's convergence on the Cornell box with direct light by photons (the
suite keeps direct light by NEE), with the module's own test:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_photon_matrix.py
"""
import pytest

import test_photon

pytestmark = pytest.mark.slow


def test_error_falls_with_passes_on_the_cornell_box_with_photons_for_direct_light():
    test_photon.test_error_falls_with_passes_on_the_cornell_box("photons")
