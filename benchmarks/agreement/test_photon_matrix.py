"""tests/plugins/test_photon.py's convergence on the Cornell box with direct light by photons (the
suite keeps direct light by NEE), and test_photon_scenes.py's blackbody light in spectral (the
suite keeps spectral convergence on plain spectra), with the modules' own checks:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_photon_matrix.py
"""
import mitsuba as mi
import pytest

import test_photon
import test_photon_scenes
from backend import variant
from test_photon_scenes import variant_switch  # noqa: F401 (the fixture)

pytestmark = pytest.mark.slow


def test_error_falls_with_passes_on_the_cornell_box_with_photons_for_direct_light():
    test_photon.test_error_falls_with_passes_on_the_cornell_box("photons")


@pytest.mark.skipif(variant("ad_spectral") not in mi.variants(), reason="no spectral variant")
def test_spectral_emitters_that_importance_sample_wavelengths(variant_switch):  # noqa: F811
    test_photon_scenes.check_spectral_emitters_that_importance_sample_wavelengths(variant_switch)
