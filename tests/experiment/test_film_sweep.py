"""A sweep keeps its scenes' film shape (issue 42, item 5): ``[scenes.X] resolution = 16`` on a
32x24 scene renders 16x12 (the larger side; the aspect ratio kept), ``[w, h]`` sets both, the
report's settings table shows the film as rendered, and bad values are one-line errors with
exit status 2. A 32x24 Cornell box, 2 spp, fixed seeds."""
import os

import pytest
from film_scenes import wide_cornell
from lab_cli import run

from mitsuba_lab import images
from mitsuba_lab.experiment.pipeline.config import ConfigError, load_config_dict
from mitsuba_lab.experiment.sweep import prepare_sweep
from mitsuba_lab.scene import film_size
from mitsuba_lab.scene_xml import load_scene_variant


def config(tmp_path, resolution, grid=False) -> dict:
    """The sweep: lab_mis on the 32x24 scene at ``resolution``; with ``grid``, lab_bdpt too and
    its strategy grid (path length 1, at the scene's resolution)."""
    scene = {"path": wide_cornell(str(tmp_path))}
    if resolution is not None:
        scene["resolution"] = resolution
    data = {"experiment": {"spp": [2], "repetitions": 2, "progressive": False, "max_depth": 3, "metrics": []},
            "reference": {"spp": 8, "chunks": 2, "cache": str(tmp_path / "cache")},
            "scenes": {"wide": scene},
            "strategies": {"mis": {"type": "lab_mis"}}}
    if grid:
        data["strategies"]["bdpt"] = {"type": "lab_bdpt"}
        data["report"] = {"strategy_grid": {"scene": "wide", "strategy": "bdpt", "max_length": 1, "spp": 1}}
    return data


@pytest.mark.slow
def test_a_sweep_renders_16x12_and_says_so(tmp_path):
    import mitsuba_lab

    data = config(tmp_path, 16, grid=True)
    mitsuba_lab.sweep(data, output=tmp_path / "out", progress=False, as_frame=False, in_process=True)
    out = tmp_path / "out"
    references = [f for f in os.listdir(out / "references") if not f.endswith(".var.exr")]
    assert [images.read_exr(str(out / "references" / f))[0].shape[:2] for f in references] == [(12, 16)]
    renders = [os.path.join(folder, f) for folder, _, files in os.walk(out / "images") for f in files]
    assert renders and all(images.read_exr(f)[0].shape[:2] == (12, 16) for f in renders)
    grid = [f for f in os.listdir(out / "strategy_grid")]
    assert grid and all(images.read_exr(str(out / "strategy_grid" / f))[0].shape[:2] == (12, 16) for f in grid)
    summary = (out / "report" / "summary.md").read_text()
    assert "| film | wide |  | 16x12 pixels (width x height) |" in summary


@pytest.mark.parametrize("resolution, shape", [([20, 10], (20, 10)), (None, (32, 24)), (40, (40, 30))])
def test_width_and_height(tmp_path, resolution, shape):
    config_, _ = prepare_sweep(config(tmp_path, resolution))
    scene = config_.scenes[0]
    assert film_size(load_scene_variant(scene.path, scene.resolution, None, scene.defaults)) == shape


@pytest.mark.parametrize("value", [0, -16, [16, 12, 3], "16", [16, "12"], True])
def test_bad_resolutions_are_one_line_errors(tmp_path, value):
    for where in ("scenes.wide", "report.strategy_grid"):
        data = config(tmp_path, None, grid=True)
        table = data["scenes"]["wide"] if where == "scenes.wide" else data["report"]["strategy_grid"]
        table["resolution"] = value
        with pytest.raises(ConfigError) as err:
            load_config_dict(data)
        assert str(err.value) == (f"config dict: {where}.resolution: expected a positive integer (the film's larger "
                                  f"side; the scene's aspect ratio is kept) or [width, height] of positive "
                                  f"integers, got {value!r}")


def test_a_bad_resolution_exits_2(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(f'[experiment]\nspp = [2]\n[scenes.wide]\npath = "{wide_cornell(str(tmp_path))}"\n'
                    f'resolution = [16, 12, 3]\n[strategies]\nmis = {{ type = "lab_mis" }}\n')
    code, out, err = run(["sweep", str(path), "--dry-run"])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "scenes.wide.resolution" in err
