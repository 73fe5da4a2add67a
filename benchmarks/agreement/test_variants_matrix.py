"""tests/plugins/test_variants.py's checks over every estimator (``ESTIMATORS``) and every sampler
(``SAMPLERS``) in every variant (45 cases; tolerance and false-failure odds: that module's
docstring). The fixture takes the variants as its params, so pytest runs a variant's cases
together and renders its reference once:

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_variants_matrix.py
"""
import pytest

from test_variants import (ESTIMATORS, SAMPLERS, VARIANTS, check_bias_is_caught, check_estimator, check_sampler,
                           in_variant)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module", params=VARIANTS)
def variant(request):
    yield from in_variant(request.param)


@pytest.mark.parametrize("strategy", ESTIMATORS)
def test_estimators_agree_with_path_in_every_variant(variant, strategy):
    check_estimator(variant, strategy)


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_samplers_agree_with_independent_in_every_variant(variant, sampler):
    check_sampler(variant, sampler)


def test_a_three_percent_bias_is_caught_in_every_variant(variant):
    check_bias_is_caught(variant)
