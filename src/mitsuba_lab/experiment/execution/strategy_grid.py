"""lab_bdpt's per-strategy images: what each (s, t) technique contributes (Veach 1997, fig. 10.3).

A path of length k (segments) can be built by k + 2 strategies: s light-subpath vertices and
t = k + 1 - s camera-subpath vertices, s = 0..k+1. The grid renders lab_bdpt once per strategy
with ``only_strategy = "s,t"`` (the strategy's contribution with its MIS weight) and once in
full, all with ``max_depth = K`` and one seed: the cells of rows k = 1..K then sum to the full
image exactly (same random numbers, the weights of a path's strategies sum to one). Column
t = 0 (a light subpath that hits the camera) is empty: a pinhole camera has no area to hit.

The sweep renders the grid after its points (``render_strategy_grid``) into the result store:
one ``strategy_grid`` row (what the grid is, with its identity) and one ``strategy_grid_cell``
row per image, written after the image, so a killed sweep redoes only missing cells and a
changed grid (scene, parameters, code version) renders again. The report reads them
(``grid_section``); it never renders.
"""
from __future__ import annotations

import os

import numpy as np

from ... import images
from ...errors import LabError
from ...reporting import fmt, markdown_table, pyplot, save_figure
from ..pipeline.config import Config, ConfigError, PluginSpec
from ..pipeline.identity import identity_hash, integrator_identity, versions_identity
from ..pipeline.plan import SEED_STRIDE, Plan
from ..pipeline.store import ResultStore

GRID_FOLDER = "strategy_grid"
#: lab_bdpt's time per camera sample relative to Mitsuba's `path` (two subpaths and their
#: connections; ~3-4x at 64x64 on 2 cores): scales --dry-run's estimate of the grid.
BDPT_COST = 4.0
FULL = "full"


def grid_cells(max_length: int) -> list[tuple[int, int, int]]:
    """(k, s, t) of every rendered cell: k = 1..K, s = 0..k, t = k + 1 - s >= 1."""
    return [(k, s, k + 1 - s) for k in range(1, max_length + 1) for s in range(k + 1)]


def _cell_key(s, t) -> str:
    return FULL if s is None else f"{s},{t}"


def grid_seed(config: Config) -> int:
    """The one seed of every grid image: the sweep's first point seed."""
    return config.seed * SEED_STRIDE + 1


def grid_setup(config: Config):
    """(scene spec, lab_bdpt plugin spec with max_depth = K, identity, its hash)."""
    from ...scene_xml import film_override_key, scene_digest

    spec = config.strategy_grid
    scene = next(s for s in config.scenes if s.name == spec.scene)
    strategy = next(s for s in config.strategies if s.name == spec.strategy)
    plugin = PluginSpec(strategy.name, strategy.type, {**strategy.params, "max_depth": spec.max_length})
    resolution = film_override_key(scene.path, grid_resolution(config), scene.defaults)
    identity = {"scene": {"digest": scene_digest(scene.path), "resolution": resolution,
                          "defaults": dict(scene.defaults)},
                "integrator": integrator_identity(plugin), "spp": spec.spp, "seed": grid_seed(config),
                "max_length": spec.max_length, "versions": versions_identity()}
    return scene, plugin, identity, identity_hash(identity)


def check_grid(config: Config, plan: Plan) -> None:
    """ConfigError when the planner left the grid's strategy out on the grid's scene."""
    spec = config.strategy_grid
    if spec is None:
        return
    for item in plan.left_out:
        if item["scene"] == spec.scene and item["strategy"] == spec.strategy:
            raise ConfigError(f"{config.source}: report.strategy_grid: expected a scene that strategies."
                              f"{spec.strategy} can render, but on scene {spec.scene} it is left out: "
                              f"{item['reason']}")


def grid_renders(config: Config) -> int:
    """How many renders the grid takes (cells and the full image); 0 without a grid."""
    spec = config.strategy_grid
    return 0 if spec is None else len(grid_cells(spec.max_length)) + 1


def grid_resolution(config: Config):
    """The grid's film override: its own ``resolution``, else its scene's (None: the scene's film)."""
    spec = config.strategy_grid
    scene = next(s for s in config.scenes if s.name == spec.scene)
    return spec.resolution or scene.resolution


def estimated_grid_seconds(config: Config, rate: float, pixels: int) -> float:
    """--dry-run's estimate: ``rate`` is the reference integrator's samples per second, ``pixels``
    the scene's at its own resolution."""
    from ...scene_xml import film_size

    spec = config.strategy_grid
    if spec is None:
        return 0.0
    if spec.resolution:
        scene = next(s for s in config.scenes if s.name == spec.scene)
        width, height = film_size(scene.path, spec.resolution, scene.defaults)
        pixels = width * height
    return grid_renders(config) * pixels * spec.spp / rate * BDPT_COST


def render_strategy_grid(config: Config, store: ResultStore, progress=None) -> int:
    """Render the grid's missing images into ``store``; returns how many were rendered."""
    from ...render import render
    from ...scene import make_integrator
    from ...scene_xml import load_scene_variant

    spec = config.strategy_grid
    if spec is None:
        return 0
    progress = progress or (lambda event, **info: None)
    scene_spec, plugin, identity, ident_hash = grid_setup(config)
    store.append({"kind": "strategy_grid", "scene": spec.scene, "strategy": spec.strategy,
                  "max_length": spec.max_length, "spp": spec.spp, "seed": identity["seed"],
                  "params": plugin.params, "identity": identity, "identity_hash": ident_hash})
    done = {row["cell"] for row in store.of_kind("strategy_grid_cell")
            if row.get("identity_hash") == ident_hash and os.path.exists(os.path.join(store.folder, row["image"]))}
    todo = [(k, s, t) for k, s, t in grid_cells(spec.max_length) if _cell_key(s, t) not in done]
    if FULL not in done:
        todo.append((None, None, None))
    if not todo:
        return 0
    scene = load_scene_variant(scene_spec.path, grid_resolution(config), None, scene_spec.defaults)
    folder = os.path.join(store.folder, GRID_FOLDER)
    os.makedirs(folder, exist_ok=True)
    for i, (k, s, t) in enumerate(todo, 1):
        key = _cell_key(s, t)
        only = "" if s is None else key
        progress("grid_cell", cell=key, done=i, total=len(todo))
        integrator = make_integrator(plugin.type, {**plugin.params, "only_strategy": only})
        image, stats = render(scene, integrator, spp=spec.spp, seed=identity["seed"])
        name = f"{ident_hash[:8]}_{'full' if s is None else f's{s}_t{t}'}.exr"
        images.write_exr(os.path.join(folder, name), image, {"mitsuba_lab.strategy": key})
        store.append({"kind": "strategy_grid_cell", "identity_hash": ident_hash, "cell": key, "k": k, "s": s,
                      "t": t, "image": os.path.join(GRID_FOLDER, name), "mean": float(np.mean(image)),
                      "finite": bool(np.isfinite(image).all()), "wall_s": stats.wall_s})
    return len(todo)


# -- report ------------------------------------------------------------------------------

def grid_in_force(store: ResultStore) -> tuple[dict, dict] | None:
    """(grid row, {cell key: cell row}) of the grid the latest sweep asked for, or None when the
    latest sweep (its ``meta`` row) came after the last grid, i.e. its config has none."""
    last_grid = last_meta = None
    for index, row in enumerate(store.rows):
        if row.get("kind") == "strategy_grid":
            last_grid = index
        elif row.get("kind") == "meta":
            last_meta = index
    if last_grid is None or (last_meta is not None and last_meta > last_grid):
        return None
    grid = store.rows[last_grid]
    cells = {row["cell"]: row for row in store.of_kind("strategy_grid_cell")
             if row.get("identity_hash") == grid["identity_hash"]}
    return grid, cells


def load_grid(store: ResultStore) -> dict | None:
    """The grid in force with its images: {"grid": row, "K": K, "full": image or None,
    "cells": {(k, s, t): image}, "missing": [cell keys]}; None when there is no grid."""
    found = grid_in_force(store)
    if found is None:
        return None
    grid, rows = found
    read = lambda row: images.read_exr(os.path.join(store.folder, row["image"]))[0]   # noqa: E731
    K = grid["max_length"]
    cells, missing = {}, []
    for k, s, t in grid_cells(K):
        row = rows.get(_cell_key(s, t))
        if row is None:
            missing.append(_cell_key(s, t))
        else:
            cells[(k, s, t)] = read(row)
    full = read(rows[FULL]) if FULL in rows else None
    if full is None:
        missing.append(FULL)
    return {"grid": grid, "K": K, "full": full, "cells": cells, "missing": missing}


def _share(image, total: float) -> float:
    return float(np.mean(image)) / total if total > 0 else float("nan")


def _percent(image, total: float) -> str:
    """Share of the full image's mean in percent, three significant digits (tiny shares too)."""
    return f"{fmt(100 * _share(image, total), 3)}%"


def plot_grid(data: dict, path: str) -> str:
    """Rows k = 1..K, columns s = 0..K+1 and the row's sum; the full image under the sums. Every
    panel at the full image's exposure, titled with (s, t) and its share of the full image's mean."""
    plt = pyplot()
    K, full, cells = data["K"], data["full"], data["cells"]
    total = float(np.mean(full))
    shape = full.shape
    cols = K + 3
    fig, axes = plt.subplots(K + 1, cols, figsize=(1.45 * cols, 1.6 * (K + 1)), dpi=100, squeeze=False)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
        ax.axis("off")

    def show(ax, image, title):
        ax.axis("on")
        ax.imshow(images.srgb_preview(image))
        ax.set_title(title, fontsize=7)

    for k in range(1, K + 1):
        row = np.zeros(shape, dtype=np.float32)
        for s in range(k + 1):
            image = cells[(k, s, k + 1 - s)]
            row += image
            show(axes[k - 1][s], image, f"({s},{k + 1 - s}) {_percent(image, total)}")
        show(axes[k - 1][k + 1], np.zeros(shape, dtype=np.float32), f"({k + 1},0) never:\npinhole camera")
        show(axes[k - 1][cols - 1], row, f"length {k}: {_percent(row, total)}")
        axes[k - 1][0].set_ylabel(f"k = {k}", fontsize=8)
    show(axes[K][cols - 1], full, f"full image\n(max_depth {K})")
    fig.suptitle("lab_bdpt per strategy (s light vertices, t camera vertices): image at the full "
                 "image's exposure, share of its mean", fontsize=8)
    return save_figure(fig, path)


def grid_section(store: ResultStore, out: str) -> list[str]:
    """The report's section on the grid in force (Markdown lines; [] when there is none)."""
    data = load_grid(store)
    if data is None:
        return []
    grid, K = data["grid"], data["K"]
    md = ["", f"## Per-strategy images (s, t): scene `{grid['scene']}`", "",
          f"lab_bdpt (`strategies.{grid['strategy']}`, max_depth {K}, {grid['spp']} spp, seed {grid['seed']}) "
          f"rendered once per strategy with `only_strategy = \"s,t\"`: the contribution of the paths of "
          f"length k = s + t - 1 that strategy (s light-subpath vertices, t camera-subpath vertices) "
          f"builds, times its MIS weight. All images use one seed, so over every (s, t) they sum to the full "
          f"image. Column t = 0 (the light subpath hits the camera) is always black: a pinhole camera "
          f"cannot be hit."]
    if data["missing"]:
        return md + ["", f"**Not complete:** {len(data['missing'])} image(s) missing ({', '.join(data['missing'])}): "
                         f"run the sweep again to render them."]
    full, cells = data["full"], data["cells"]
    total = float(np.mean(full))
    plot = plot_grid(data, os.path.join(out, f"{grid['scene']}_strategy_grid.png"))
    header = ["k", *(f"s = {s}" for s in range(K + 2)), "length k"]
    body = []
    for k in range(1, K + 1):
        row = [cells[(k, s, k + 1 - s)] for s in range(k + 1)]
        shares = [f"t = {k + 1 - s}: {_percent(image, total)}" for s, image in enumerate(row)]
        body.append([k, *shares, "t = 0: never", *([""] * (K - k)),
                     _percent(sum(row), total)])
    summed = sum(cells.values())
    diff = float(np.max(np.abs(summed - full)))
    finite = all(np.isfinite(image).all() for image in [full, *cells.values()])
    md += ["", f"![per-strategy images]({os.path.basename(plot)})", "",
           "Share of the full image's mean (mean over pixels and channels) per strategy:", "",
           *markdown_table(header, body), "",
           f"Sum of the {len(cells)} strategy images against the full image: largest absolute difference "
           f"{fmt(diff)} (the full image's largest value is {fmt(float(np.max(full)))}; float rounding "
           f"only); every image finite: {'yes' if finite else 'NO'}."]
    return md


def require_complete(store: ResultStore) -> dict:
    """The grid in force with every image (for tests and tools); LabError otherwise."""
    data = load_grid(store)
    if data is None or data["missing"]:
        raise LabError(f"{store.folder}: no complete strategy grid")
    return data
