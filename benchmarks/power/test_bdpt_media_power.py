"""Power proofs of tests/plugins/test_bdpt_media.py (each renders a 16-seed stack of lab_bdpt and
of volpath of its own, about 10 CPU s apiece, so they left the suite): a medium vertex's forward
density without sigma_t, and delta-tracked flights whose weight is 4% low, both fail the block
test's bound. Each prints its max |z| (recorded in experiments/results/2026-11-28-power-proofs.md).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/power/test_bdpt_media_power.py
"""
import mitsuba as mi
import numpy as np

import media_scenes
from agreement import Z_BOUND, z_scores
from test_bdpt_media import SCENES, bdpt, reference


def test_a_medium_density_without_sigma_t_is_caught(monkeypatch):
    """Power: the free flights' factor of a medium vertex's forward density divided by sigma_t
    (p_A = p_W T / d^2, the collision density's sigma_t left out); the weights no longer sum to 1."""
    from mitsuba_lab.plugins.integrators.common import subpath_media

    original = subpath_media.homogeneous_flight

    def wrong(medium, ray, t_max, u, channel, active):
        mei, scattered, weight, T_c = original(medium, ray, t_max, u, channel, active)
        sigma = subpath_media.media.channel_value(mei.sigma_t, channel)
        return mei, scattered, weight, mi.Float(np.float32(1.0)) * subpath_media.dr.select(scattered, T_c / sigma, T_c)

    monkeypatch.setattr(subpath_media, "homogeneous_flight", wrong)
    scene = mi.load_dict(media_scenes.point_in_fog())
    result = z_scores(bdpt(scene), reference(scene))
    print(f"sigma_t left out of p_A: max |z| {result.max_abs_z:.1f}, relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z > Z_BOUND


def test_a_biased_delta_tracked_flight_is_caught(monkeypatch):
    """Power: every delta-tracked flight's weight x 0.96 (its transmittance over its density 4% low)."""
    from mitsuba_lab.plugins.integrators.common import subpath_media

    original = subpath_media.tracked_flight

    def biased(*args):
        mei, scattered, weight, T_c = original(*args)
        return mei, scattered, 0.96 * weight, T_c

    monkeypatch.setattr(subpath_media, "tracked_flight", biased)
    scene = mi.load_dict(SCENES["spot_into_smoke"]())
    result = z_scores(bdpt(scene), reference(scene))
    print(f"flights 4% low: max |z| {result.max_abs_z:.1f}, relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z > Z_BOUND
