"""A stored sweep made with numpy (nothing rendered), for tests of what the report draws
from stored results: the comparison viewer and the publication figure.

One scene "s", WIDTH x HEIGHT (not square, so rows and columns cannot be swapped unseen): a
coloured gradient, a bright block of radiance 4 (above 1: only a real HDR exposure shows
its level) and a dim corner, each a region. Two strategies, "good" and "noisy", each at two
time budgets and two spp levels, SEEDS seeds; images are the reference plus Gaussian noise.
"""
import os

import numpy as np

from mitsuba_lab import images
from mitsuba_lab.experiment.pipeline.store import ResultStore

WIDTH, HEIGHT = 24, 16
SEEDS = (1, 2, 3)
BRIGHT = 4.0
REGIONS = {"light": [2, 2, 8, 6], "dim": [14, 10, 22, 14]}
#: strategy -> relative noise of one sample
STRATEGIES = {"good": 0.3, "noisy": 1.2}
BUDGETS = (0.1, 0.2)
SPPS = (4, 16)


def reference_image() -> np.ndarray:
    x = np.linspace(0.1, 0.6, WIDTH, dtype=np.float32)
    image = np.stack([np.tile(x, (HEIGHT, 1)), np.full((HEIGHT, WIDTH), 0.3, np.float32),
                      np.tile(x[::-1], (HEIGHT, 1))], axis=-1)
    x0, y0, x1, y1 = REGIONS["light"]
    image[y0:y1, x0:x1] = BRIGHT
    x0, y0, x1, y1 = REGIONS["dim"]
    image[y0:y1, x0:x1] = 0.05
    return image


def _region_errors(image, reference) -> dict:
    out = {}
    for name, (x0, y0, x1, y1) in REGIONS.items():
        a, r = image[y0:y1, x0:x1].astype(np.float64), reference[y0:y1, x0:x1].astype(np.float64)
        out[name] = {"mse": float(np.mean((a - r) ** 2)), "rel_mse": float(np.mean((a - r) ** 2 / (r ** 2 + 0.01)))}
    return out


def write_sweep(folder, seeds=SEEDS, strategies=STRATEGIES, budgets=BUDGETS, spps=SPPS, bias=None) -> None:
    """``bias``: {strategy: HEIGHT x WIDTH relative bias}, that strategy's images are the
    reference times (1 + bias) plus the noise (a known over- and under-estimation)."""
    rng = np.random.default_rng(11)
    bias = bias or {}
    store = ResultStore(str(folder))
    store.append({"kind": "meta", "config": "synthetic.toml", "name": "synthetic", "machine": {}})
    reference = reference_image()
    for sub in ("references", "images"):
        os.makedirs(os.path.join(folder, sub), exist_ok=True)
    images.write_exr(os.path.join(folder, "references", "k.exr"), reference)
    images.write_exr(os.path.join(folder, "references", "k.var.exr"), 1e-5 * (reference ** 2 + 0.01))
    store.append({"kind": "reference", "scene": "s", "key": "k", "regions": REGIONS, "spp": 4096, "chunks": 8,
                  "integrator": "path", "params": {}})
    for name, noise in strategies.items():
        speed = 0.004 if name == "good" else 0.002          # seconds per spp
        levels = [(f"t{b:g}s", b, max(1, int(b / speed))) for b in budgets] + \
                 [(f"spp{spp}", None, spp) for spp in spps]
        for tag, budget, spp in levels:
            point = f"s/{name}/independent/{tag}"
            for seed in seeds:
                sigma = noise / np.sqrt(spp) * (reference + 0.05)
                mean = reference * (1 + bias[name][..., None]) if name in bias else reference
                image = (mean + rng.normal(0, 1, reference.shape) * sigma).astype(np.float32)
                path = store.image_path(point, seed)
                images.write_exr(path, image)
                store.append({"kind": "run", "point": point, "scene": "s", "strategy": name,
                              "sampler": "independent", "spp": spp, "budget_s": budget, "seed": seed,
                              "wall_s": speed * spp * (1 + 0.01 * seed), "kernel_s": speed * spp, "compile_s": 0.0,
                              "rays": {}, "integrator": "lab_nee", "params": {},
                              "mse": float(np.mean((image - reference) ** 2)),
                              "rel_mse": float(np.mean((image - reference) ** 2 / (reference ** 2 + 0.01))),
                              "image": os.path.relpath(path, folder), "regions": _region_errors(image, reference),
                              "finite": True, "negative": 0})


def edit_runs(folder, edit) -> None:
    """Rewrite the stored sweep's run rows: ``edit(row)`` changes a row in place, or returns
    the rows that replace it (a list); the other rows are kept as they are."""
    import json

    path = os.path.join(folder, "results.jsonl")
    rows = []
    for row in map(json.loads, open(path)):
        replaced = edit(row) if row["kind"] == "run" else None
        rows.extend(replaced if replaced is not None else [row])
    with open(path, "w") as f:
        f.writelines(json.dumps(r) + "\n" for r in rows)
