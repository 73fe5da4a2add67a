"""lab_vcm in participating media. Its modes without merging (bpt, lt, pt) run lab_bdpt's media
loops with the same techniques, so they render lab_bdpt's image for the same seed (up to float
atomics in the light-tracing splats): lab_bdpt's block tests against volpath
(test_bdpt_media.py) cover them.

Tolerance: |difference| <= 1e-5 per pixel (splat order), fixed seed. Power: the same check fails
when lab_vcm leaves the media out (``RENDERS_MEDIA`` off: the scene rendered as if empty).
"""
import numpy as np
import pytest

import mitsuba as mi
import backend  # noqa: F401 (the variant)
import media_scenes
from mitsuba_lab.plugins.integrators.vcm.estimator import VertexMerging
from mitsuba_lab.scene import make_integrator

#: lab_vcm's modes without merging and lab_bdpt's strategies with the same techniques.
SAME = {"bpt": "all", "lt": "light", "pt": "camera"}


def fog():
    scene = media_scenes.fog_box(sigma_t=2.5)
    scene["sensor"]["film"].update(width=16, height=12)
    return mi.load_dict(scene)


def image(scene, kind, **params):
    return np.array(mi.render(scene, integrator=make_integrator(kind, {"max_depth": 5, **params}), spp=2, seed=7))


def difference(scene, mode) -> float:
    return float(np.abs(image(scene, "lab_vcm", mode=mode) - image(scene, "lab_bdpt", strategies=SAME[mode])).max())


@pytest.mark.parametrize("mode", sorted(SAME))
def test_modes_without_merging_render_what_lab_bdpt_renders(mode):
    assert difference(fog(), mode) <= 1e-5


def test_leaving_the_media_out_is_caught(monkeypatch):
    monkeypatch.setattr(VertexMerging, "RENDERS_MEDIA", False)
    assert difference(fog(), "bpt") > 1e-2


@pytest.mark.parametrize("mode", ["vcm", "bpm", "ppm"])
def test_merging_modes_refuse_media_in_one_line(mode):
    with pytest.raises(ValueError, match=f"^lab_vcm mode={mode} does not support participating media yet"):
        make_integrator("lab_vcm", {"mode": mode}).render(fog(), spp=1)
