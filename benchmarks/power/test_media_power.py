"""Power proofs that left tests/plugins/test_media.py (each renders a stack of its own; the suite
keeps the free-flight x 1.03 proof, which shares fog_box's reference, and the majorant grid at 0.4
against quadrature, which renders nothing). Same code as the suite's before 2026-11-28 round 2;
each prints its max |z| (recorded in experiments/results/2026-11-28-power-proofs.md; the NEE at
infinity proof's in 2026-11-28-media-shafts-clear-housing.md).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/power/test_media_power.py
"""
import mitsuba as mi
import pytest

import media_scenes
from agreement import Z_BOUND, z_scores
from test_media import lab, reference


@pytest.mark.parametrize("what", ["transmittance", "equiangular_pdf"])
def test_a_three_percent_error_in_a_medium_estimator_is_caught(monkeypatch, what):
    """The shadow rays' transmittance 3% too high, or the equi-angular density that the other
    techniques' MIS weights see 30% too high (the weights then no longer sum to 1)."""
    from mitsuba_lab.plugins.integrators.common import equiangular, media

    module = equiangular if what == "equiangular_pdf" else media
    original = getattr(module, what)

    def biased(*args, **kwargs):
        return original(*args, **kwargs) * (1.3 if what == "equiangular_pdf" else 1.03)

    monkeypatch.setattr(module, what, biased)
    scene = mi.load_dict(media_scenes.fog_box())
    result = z_scores(lab(scene), reference(scene, name="fog_box"))
    print(f"{what} too high: max |z| {result.max_abs_z:.1f}, relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z > Z_BOUND


def test_a_majorant_grid_below_the_extinction_fails_a_render(monkeypatch):
    """Every cell's bound at 0.4 of the grid's maximum over its footprint: lab_mis with the grid on
    smoke against volpath must fail the bound."""
    from mitsuba_lab.plugins.integrators.common import majorants

    monkeypatch.setattr(majorants, "ROUNDING", 0.4)
    scene = mi.load_dict(media_scenes.smoke())
    result = z_scores(lab(scene, majorants="grid"), reference(scene, name="smoke"))
    print(f"majorant grid at 0.4: max |z| {result.max_abs_z:.1f}, relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z > Z_BOUND


def test_spectral_mis_without_the_carried_ratios_is_caught(monkeypatch):
    """Each flight weighted by its own channel mean, mean_c(q_c), forgetting the ratios r_c that
    the path carries from its earlier flights (a product of means instead of the mean of
    products), must fail the bound (max_depth 16: paths of many flights, where it shows)."""
    import drjit as dr
    from mitsuba_lab.plugins.integrators.common import media

    original = media.free_flight

    def forgetful(*args, **kwargs):
        mei, scattered, weight, ratios, nulls = original(*args, **kwargs)
        return mei, scattered, weight, None if ratios is None else dr.ones(type(ratios)), nulls

    monkeypatch.setattr(media, "free_flight", forgetful)
    scene = mi.load_dict(media_scenes.chromatic_in_glass())
    result = z_scores(lab(scene, max_depth=16, spectral_mis=True), reference(scene, 16, "volpathmis"))
    print(f"spectral MIS without carried ratios: max |z| {result.max_abs_z:.1f}, "
          f"relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z > Z_BOUND


@pytest.mark.parametrize("kind", ["lab_nee", "lab_mis"])
def test_equiangular_mode_without_nee_for_lights_at_infinity_is_caught(monkeypatch, kind):
    """tests/plugins/test_media.py's ``test_equiangular_mode_keeps_nee_for_lights_at_infinity``
    with the bug it guards against put back: the scene taken to have no light at infinity, so that
    in mode equiangular NEE at medium vertices is dropped (lab_nee loses the sky's and the sun's
    scattered light; lab_mis still weighs its phase-sampled hits of the sky against that NEE)."""
    from mitsuba_lab.plugins.integrators.common import equiangular

    monkeypatch.setattr(equiangular, "lights_at_infinity", lambda scene: False)
    scene = mi.load_dict(media_scenes.fog_box_sky())
    result = z_scores(lab(scene, kind, medium_sampling="equiangular"), reference(scene, name="fog_box_sky"))
    print(f"{kind} equiangular without NEE at infinity: max |z| {result.max_abs_z:.1f}, "
          f"relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z > Z_BOUND
