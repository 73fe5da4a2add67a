"""tests/plugins/test_aim.py's aimed-emission agreement on every plugin x both scenes (the suite
keeps one scene per plugin):

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/agreement/test_aim_matrix.py
"""
import pytest

from agreement import SEEDS_LAB, assert_agrees, renders, scene_path
from mitsuba_lab.scene import load_scene, make_integrator
from test_aim import AIMED_PLUGINS, MAX_DEPTH, RES, path_stack


@pytest.mark.parametrize("name", ["caustic.xml", "stiff/light_in_glass.xml"])
@pytest.mark.parametrize("plugin, params", AIMED_PLUGINS)
def test_aimed_emission_agrees_with_mitsuba_path(name, plugin, params):
    scene = load_scene(scene_path(name), res=RES)
    lab = renders(scene, make_integrator(plugin, {"max_depth": MAX_DEPTH, "aim": 0.5, **params}), 16, SEEDS_LAB)
    assert_agrees(lab, path_stack(name), f"{plugin} {params} aim=0.5 on {name}")


def test_no_target_renders_the_same_image_in_lab_photon():
    import test_aim

    test_aim.test_no_target_renders_the_same_image("lab_photon")
