"""The path family's media in a polarized variant: lab_mis against Mitsuba's volpath (volpathmis
has no polarized mode) under the block test (tests/agreement.py: 6x6-pixel block means, Welch z
over the seeds, Sidak-corrected alpha 0.01), on a cube of fog behind a null boundary whose floor
is a polarizing rough conductor and whose light comes through a glass pane: the path's throughput
is a Mueller matrix, the medium's weights scale it, and the order of the conductor's and the
glass's matrices matters. Power: every free flight's weight x 0.97 fails."""
import mitsuba as mi
import pytest

import backend
import media_scenes
import mitsuba_lab
from agreement import block_test, pixel_problem, renders
from mitsuba_lab.scene import make_integrator
from test_media_block import bias_free_flights

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier

KIND = "ad_spectral_polarized"
RES = (24, 16)
DEPTH = 8
SPP = 32
REF_SPP = 4 * SPP
SEEDS_LAB, SEEDS_REF = range(32), range(1000, 1032)
_stacks: dict = {}


def polarizing_fog_box() -> dict:
    scene = media_scenes.fog_box()
    scene["sensor"]["film"]["width"], scene["sensor"]["film"]["height"] = RES
    scene["floor"]["bsdf"] = {"type": "roughconductor", "material": "Cu", "alpha": 0.3}
    scene["pane"] = {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 2.4, 0]).rotate([1, 0, 0], 90),
                     "bsdf": {"type": "thindielectric"}}
    return scene


def render(integrator: str, seeds, spp: int = SPP):
    return renders(mi.load_dict(polarizing_fog_box()), make_integrator(integrator, {"max_depth": DEPTH}), spp, seeds)


@pytest.fixture(scope="module")
def polarized():
    mitsuba_lab.use_variant(backend.variant(KIND))
    try:
        yield render("volpath", SEEDS_REF, REF_SPP)
    finally:
        mitsuba_lab.use_variant(backend.HOME)


def test_lab_mis_agrees_with_volpath_in_a_polarized_variant(polarized):
    images = render("lab_mis", SEEDS_LAB)
    result = block_test(images, polarized)
    print(f"lab_mis in {mi.variant()}: {result.summary()}")
    assert pixel_problem(images, True) == ""
    assert not result.failing, result.summary()


def test_a_three_percent_error_fails_it_in_a_polarized_variant(polarized, monkeypatch):
    bias_free_flights(monkeypatch, 0.97)
    result = block_test(render("lab_mis", SEEDS_LAB), polarized)
    print(f"free flights x 0.97: {result.summary()}")
    assert result.failing, result.summary()
