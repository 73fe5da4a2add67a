"""Films keep their shape (issue 42, item 5): a scalar resolution sets the larger side and keeps
the aspect ratio, [w, h] sets both, the same in ``check --res``, ``reference --res`` and
``invert``'s ``resolution`` (mitsuba_lab.film; sweeps: tests/experiment/test_film_sweep.py).
A 32x24 Cornell box (the shipped one with its film fixed at 32x24, no ``res`` parameter)."""
import os
import types

import pytest
from film_scenes import CORNELL, wide_cornell
from lab_cli import run

from mitsuba_lab import check
from mitsuba_lab import inverse as inv
from mitsuba_lab.experiment.pipeline.config import ConfigError
from mitsuba_lab.film import as_resolution, film_key, film_shape, parse_resolution_text
from mitsuba_lab.scene import film_size

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("native, resolution, shape", [
    ((32, 24), 16, (16, 12)), ((24, 32), 16, (12, 16)), ((128, 96), 48, (48, 36)), ((32, 24), 5, (5, 4)),
    ((1000, 1), 10, (10, 1)), ((32, 24), (20, 10), (20, 10)), ((32, 24), [20, 10], (20, 10)),
    ((32, 24), None, (32, 24)), ((64, 64), 16, (16, 16))])
def test_film_shape(native, resolution, shape):
    assert film_shape(native, resolution) == shape


def test_film_keys_of_square_films_are_what_they_were():
    """References cached under a square override keep their keys; other shapes get their own."""
    assert film_key((64, 64), 32) == 32 and film_key((64, 64), (32, 32)) == 32
    assert film_key((32, 24), 16) == [16, 12] and film_key((32, 24), None) is None


@pytest.mark.parametrize("value", [0, -3, [16, 12, 3], "16", [16, 0], True, 2.5, [16]])
def test_bad_resolutions_are_refused(value):
    with pytest.raises(ValueError, match="expected a positive integer .* or \\[width, height\\]"):
        as_resolution(value)


def test_command_line_resolutions():
    assert parse_resolution_text("16") == 16 and parse_resolution_text("16x12") == (16, 12)
    for text in ("0", "-3", "16x12x3", "abc", "16x0", ""):
        with pytest.raises(ValueError, match="N .* or WIDTHxHEIGHT"):
            parse_resolution_text(text)


def test_check_keeps_the_shape(tmp_path):
    wide = wide_cornell(str(tmp_path))
    assert film_size(check.load_check_scene(wide, 16, {})) == (16, 12)
    assert film_size(check.load_check_scene(wide, (20, 10), {})) == (20, 10)
    assert film_size(check.load_check_scene(wide, 16, {"res": 8})) == (8, 6)        # -D res=N: the same
    assert film_size(check.load_check_scene(CORNELL, 16, {})) == (16, 16)           # its own res parameter
    args = types.SimpleNamespace(res=16, max_depth=4, ref_spp=4, splits=2, cache=str(tmp_path / "cache"))
    reference, _ = check.check_reference(wide, args, {}, "path")
    assert reference.image.shape[:2] == (12, 16)


@pytest.mark.parametrize("res", ["0", "-3", "16x12x3", "abc"])
def test_check_refuses_bad_res_in_one_line(res):
    code, out, err = run(["check", CORNELL, "--res", res])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--res" in err and "WIDTHxHEIGHT" in err


def test_reference_command_keeps_the_shape(tmp_path, monkeypatch):
    monkeypatch.setenv("MITSUBA_LAB_CACHE", str(tmp_path / "cache"))
    wide = wide_cornell(str(tmp_path))
    code, out, err = run(["reference", wide, "--res", "16", "--spp", "4", "--chunks", "2", "--max-depth", "3"])
    assert code == 0, err
    assert "(path, 16x12)" in out
    code, out, err = run(["reference", wide, "--res", "20x10", "--spp", "4", "--chunks", "2", "--max-depth", "3"])
    assert code == 0 and "(path, 20x10)" in out, err


def _inverse_config(scene: dict):
    return inv.parse_config({"scene": scene, "render": {"max_depth": 3},
                             "parameters": {"red.reflectance.value": {"init": 0.5}}},
                            os.path.join(ROOT, "experiments", "test.toml"))


def test_invert_keeps_the_shape(tmp_path):
    from mitsuba_lab.inverse.scenes import film_of

    wide = wide_cornell(str(tmp_path))
    for scene, shape in (({"path": wide, "resolution": 16}, (16, 12)),
                         ({"path": wide, "resolution": [20, 10]}, (20, 10)),
                         ({"path": wide}, (32, 24)),                         # the default 32: the larger side
                         ({"builtin": "cornell_texture", "resolution": [20, 10], "texture_size": 4}, (20, 10)),
                         ({"builtin": "cornell_texture", "resolution": 12, "texture_size": 4}, (12, 12))):
        cfg = _inverse_config(scene)
        assert film_of(cfg) == shape
        assert film_size(inv.load_inverse_scene(cfg)) == shape


@pytest.mark.parametrize("value", [0, -1, [16, 12, 3], "16"])
def test_invert_refuses_bad_resolutions_in_one_line(value):
    with pytest.raises(ConfigError) as err:
        _inverse_config({"path": CORNELL, "resolution": value})
    message = str(err.value)
    assert "\n" not in message and "scene.resolution: expected a positive integer" in message
