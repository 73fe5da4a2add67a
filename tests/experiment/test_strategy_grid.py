"""The report's per-strategy (s, t) grid: config checks, the images summing to the full one, resume."""
import os

import numpy as np
import pytest

from mitsuba_lab.experiment.pipeline.config import ConfigError, load_config
from mitsuba_lab.experiment.pipeline.plan import build_plan
from mitsuba_lab.experiment.pipeline.store import ResultStore
from mitsuba_lab.experiment.execution.strategy_grid import (check_grid, grid_cells, grid_section, render_strategy_grid,
                                                  require_complete)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

GRID = """
[experiment]
spp = [2]
repetitions = 2

[reference]
spp = 8
chunks = 2
cache = "{cache}"

[scenes.cornell]
path = "{root}/scenes/cornell_box.xml"
resolution = 16

[scenes.sky]
path = "{root}/scenes/stiff/environment_only.xml"
resolution = 16

[strategies]
bdpt = {{ type = "lab_bdpt" }}
mis = {{ type = "lab_mis" }}

[report.strategy_grid]
scene = "cornell"
strategy = "bdpt"
max_length = 2
spp = 4
"""


def write(tmp_path, text):
    path = tmp_path / "grid.toml"
    path.write_text(text)
    return str(path)


@pytest.fixture
def grid_text(tmp_path):
    return GRID.format(cache=tmp_path / "cache", root=ROOT)


@pytest.mark.parametrize("old, new, expected", [
    ('scene = "cornell"', 'scene = "kitchen"', "report.strategy_grid.scene: expected the name of a [scenes] table"),
    ('strategy = "bdpt"', 'strategy = "mis"', "report.strategy_grid.strategy: expected the name of a [strategies] "
                                              "entry of type lab_bdpt (bdpt)"),
    ("max_length = 2", "max_length = 0", "report.strategy_grid.max_length: expected an integer in [1, 8]"),
    ("max_length = 2", "max_length = 9", "report.strategy_grid.max_length: expected an integer in [1, 8]"),
    ("max_length = 2", 'max_length = "4"', "report.strategy_grid.max_length: expected an integer in [1, 8]"),
    ("max_length = 2", "", "report.strategy_grid.max_length: expected an integer in [1, 8] (rows k = 1..max_length)"
                           " (missing)"),
    ("spp = 4", "spp = -4", "report.strategy_grid.spp: expected a positive integer"),
    ("spp = 4", "spp = 4\nresolution = 0", "report.strategy_grid.resolution: expected a positive integer"),
    ("spp = 4", "spp = 4\nrows = 3", "report.strategy_grid.rows: expected one of the keys"),
    ("[report.strategy_grid]", "[report.grid]\n[report.strategy_grid]", "report.grid: expected one of the keys"),
    ('bdpt = { type = "lab_bdpt" }', 'bdpt = { type = "lab_bdpt", only_strategy = "1,1" }',
     "report.strategy_grid.strategy: expected a lab_bdpt strategy without 'only_strategy'"),
])
def test_bad_grid_values_are_refused_in_one_line(grid_text, tmp_path, old, new, expected):
    assert old in grid_text
    with pytest.raises(ConfigError) as err:
        load_config(write(tmp_path, grid_text.replace(old, new)))
    message = str(err.value)
    assert "\n" not in message and "grid.toml" in message
    assert expected in message, message


def test_grid_on_a_scene_the_planner_leaves_out_is_refused(grid_text, tmp_path):
    config = load_config(write(tmp_path, grid_text.replace('scene = "cornell"', 'scene = "sky"')))
    reason = "emitters at infinity are not supported"
    plan = build_plan(config, lambda scene, strategies: ({"bdpt": reason} if scene.name == "sky" else {}, {}))
    with pytest.raises(ConfigError) as err:
        check_grid(config, plan)
    message = str(err.value)
    assert "\n" not in message and message.endswith(f"report.strategy_grid: expected a scene that strategies.bdpt "
                                                    f"can render, but on scene sky it is left out: {reason}")
    check_grid(load_config(write(tmp_path, grid_text)), plan)          # the grid on cornell: fine


@pytest.mark.slow
def test_grid_images_sum_to_the_full_image_and_resume(grid_text, tmp_path):
    config = load_config(write(tmp_path, grid_text))
    assert config.strategy_grid.max_length == 2 and config.strategy_grid.resolution is None
    assert grid_cells(2) == [(1, 0, 2), (1, 1, 1), (2, 0, 3), (2, 1, 2), (2, 2, 1)]
    store = ResultStore(str(tmp_path / "out"))
    assert render_strategy_grid(config, store) == 6              # five strategies and the full image
    data = require_complete(store)
    full, cells = data["full"], data["cells"]
    assert full.shape[:2] == (16, 16) and np.isfinite(full).all() and full.mean() > 0
    # same seed for every image: the MIS-weighted strategies add up to the full image (float rounding)
    summed = sum(cells.values())
    assert np.allclose(summed, full, rtol=1e-5, atol=1e-6 * float(full.max()))
    # each path length has light from more than one strategy (the grid shows the split)
    for k in (1, 2):
        assert sum(float(cells[c].mean()) > 0 for c in cells if c[0] == k) >= 2

    # resumable: nothing to redo; a store reopened after a kill finds the same cells
    assert render_strategy_grid(config, ResultStore(store.folder)) == 0
    out = tmp_path / "report"
    out.mkdir()
    md = "\n".join(grid_section(ResultStore(store.folder), str(out)))
    assert "## Per-strategy images (s, t): scene `cornell`" in md and "t = 0: never" in md
    assert (out / "cornell_strategy_grid.png").is_file() and "every image finite: yes" in md

    # a later sweep without a grid (its meta row comes last): the report leaves the old grid out
    ResultStore(store.folder).append({"kind": "meta", "name": "no grid"})
    assert grid_section(ResultStore(store.folder), str(out)) == []
