"""The report's comparison viewer: per scene, one image area for the reference and each
strategy at equal time and at equal spp, tone-mapped in the browser.

The data of a viewer is one JSON block in the page (no network, no server). Images travel as
HDR data: little-endian IEEE half floats, base64, H x W x 3 linear radiance for the renders
and the reference, H x W log10 values for the two per-pixel maps (relative error, relative
variance across seeds; log10 first, so values far below half's smallest normal survive).
``viewer.js`` (a package file, inlined into the page once) decodes them, applies the
exposure and the sRGB curve, and draws crops of the scene's regions beside the image.

The signed difference map (``signed_difference``: over- and under-estimation) costs no data:
the browser computes it from the render's and the reference's half floats, which the page
holds anyway; only its symmetric colour range travels (``diff_range``). Half rounding of the
two images limits it to relative differences above about 1e-3, far below the range any
single render's noise sets. Stored as a third map it would add a fifth to a scene's data.
The split view (two strategies either side of a divider) is drawn from the same data.
"""
from __future__ import annotations

import base64
import html
import json
from importlib import resources

import numpy as np

from ..pipeline.budget import missed_budget, off_budget_text
from .comparisons import (comparison_sets, default_set, group_points, region_rel_mse, relative_error,
                          relative_variance, shown_image)

#: Half floats stop at 65504; brighter pixels are stored as that (still "white" at any
#: exposure a person would choose).
HALF_MAX = 65504.0
#: log10 maps: values below this are shown as the bottom of the colour scale.
LOG_FLOOR = -12.0

STYLE = """.viewer { border: 1px solid #bbb; padding: 0.6em; margin: 0.5em 0 1.5em; outline: none; }
.viewer:focus-within, .viewer.vw-hover { border-color: #2a7ae2; }
.vw-row { display: flex; flex-wrap: wrap; gap: 0.3em; align-items: center; margin: 0.2em 0; }
.vw-row button { font: inherit; font-size: 0.85em; padding: 0.15em 0.5em; border: 1px solid #999;
  background: #f4f4f4; border-radius: 3px; cursor: pointer; }
.vw-row button.vw-on { background: #2a7ae2; color: #fff; border-color: #2a7ae2; }
.vw-row button.vw-b { background: #e2762a; color: #fff; border-color: #e2762a; }
.vw-row button:disabled { opacity: 0.45; cursor: default; }
.vw-split select { font: inherit; font-size: 0.85em; }
.vw-split input[type=range] { width: 120px; }
.vw-body { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
.vw-canvas { background: #222; cursor: grab; image-rendering: pixelated; }
.vw-crops { border-collapse: collapse; font-size: 0.75em; }
.vw-crops td, .vw-crops th { border: none; padding: 0.15em 0.3em; text-align: center; vertical-align: top; }
.vw-crops td.vw-on { outline: 2px solid #2a7ae2; }
.vw-crops td.vw-b { outline: 2px solid #e2762a; }
.vw-crops canvas { image-rendering: pixelated; display: block; margin: 0 auto; border: 1px solid #888; }
.vw-status { font-size: 0.8em; color: #333; min-height: 1.3em; }
.vw-legend { display: inline-block; width: 160px; height: 10px; vertical-align: middle; border: 1px solid #999; }
.vw-help { font-size: 0.75em; color: #666; }"""


def encode_half(values: np.ndarray) -> str:
    """base64 of ``values`` as little-endian half floats (non-finite and out-of-range values
    clamped to +-HALF_MAX, NaN to 0: the map shows it, the numbers beside it say it)."""
    clean = np.nan_to_num(np.asarray(values, dtype=np.float64), nan=0.0, posinf=HALF_MAX, neginf=-HALF_MAX)
    return base64.b64encode(np.clip(clean, -HALF_MAX, HALF_MAX).astype("<f2").tobytes()).decode("ascii")


def log_map(values: np.ndarray) -> np.ndarray:
    return np.log10(np.maximum(values, 10.0 ** LOG_FLOOR))


def signed_difference(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per-pixel signed relative difference mean_c (x - ref) / sqrt(ref^2 + 0.01): positive
    where the render is brighter than the reference, negative where darker. Its magnitude is
    on the scale of ``relative_error``; viewer.js computes the same from the page's data."""
    ref = reference.astype(np.float64)
    return np.mean((image.astype(np.float64) - ref) / np.sqrt(ref ** 2 + 1e-2), axis=-1)


def colormap_stops(name: str, count: int = 17) -> list[list[int]]:
    """``count`` evenly spaced RGB stops (0..255) of a matplotlib colour map, for the browser
    to interpolate: the viewer's false colours match the report's PNGs."""
    from matplotlib import colormaps

    cmap = colormaps[name]
    return [[int(round(255 * c)) for c in cmap(i / (count - 1))[:3]] for i in range(count)]


def crop_exposure(reference: np.ndarray, rect) -> float:
    """Exposure offset (EV, in half stops) of a region's crops: the reference's 98th percentile
    there shown at 0.8, so a caustic far above 1 or a dim corner shows its detail at the
    page's exposure 0. The crops' headers state it."""
    x0, y0, x1, y1 = rect
    level = float(np.percentile(reference[y0:y1, x0:x1], 98))
    if not level > 0:
        return 0.0
    return float(np.clip(np.round(2 * np.log2(0.8 / level)) / 2, -10, 10))


def _range(maps: list[np.ndarray], low: float = 1.0, high: float = 99.5) -> list[float]:
    """One colour range for a scene's maps (percentiles over all of them), so that switching
    images compares colours on the same scale."""
    values = np.concatenate([m.ravel() for m in maps]) if maps else np.zeros(1)
    values = values[values > LOG_FLOOR]
    if values.size == 0:
        return [LOG_FLOOR, 0.0]
    lo, hi = (float(v) for v in np.percentile(values, [low, high]))
    return [round(lo, 2), round(max(hi, lo + 0.1), 2)]


def _symmetric_range(maps: list[np.ndarray], high: float = 99.5) -> list[float]:
    """[-R, R] for a scene's signed maps, R the ``high`` percentile of |value| over all of
    them (2 significant digits): zero sits in the middle of the diverging colour map."""
    values = np.abs(np.concatenate([m.ravel() for m in maps])) if maps else np.zeros(1)
    values = values[np.isfinite(values)]
    limit = float(np.percentile(values, high)) if values.size else 0.0
    limit = float(f"{max(limit, 1e-3):.2g}")
    return [-limit, limit]


def scene_data(folder: str, scene: str, stats: list, reference, regions: dict) -> dict | None:
    """The JSON-ready data of one scene's viewer (None without any comparison set).

    ``regions``: {name: (x0, y0, x1, y1)} in pixels. Images are stored once each under a key
    (a render shown in two sets, e.g. at a budget and at its spp, is not repeated)."""
    groups, label = group_points(stats)
    sets = comparison_sets(groups, label)
    if not sets:
        return None
    ref = reference.image
    height, width = ref.shape[:2]
    ref_var = np.mean(reference.variance / (ref.astype(np.float64) ** 2 + 1e-2), axis=-1)
    blobs = {"ref": encode_half(ref)}
    err_maps, var_maps, diff_maps = [np.sqrt(ref_var)], [ref_var], []
    ref_entry = {"label": "reference", "key": "reference", "rgb": "ref", "err": "ref:err", "var": "ref:var",
                 "detail": f"reference: {reference.meta.get('integrator')}, {reference.meta.get('spp')} spp in "
                           f"{reference.meta.get('chunks')} chunks; error map: its own standard error, "
                           f"variance map: the variance of its mean",
                 "crops": {n: {"text": f"floor {_fmt(float(np.mean(ref_var[r[1]:r[3], r[0]:r[2]])))}"}
                           for n, r in regions.items()}}
    out_sets = []
    for cset in sets:
        entries = [ref_entry]
        for name, p in cset.entries:
            image = shown_image(folder, p)
            key = p.images[0]
            if key not in blobs:
                err, var = relative_error(image, ref), relative_variance(folder, p, ref)
                err_maps.append(err)
                var_maps.append(var)
                diff_maps.append(signed_difference(image, ref))
                blobs[key] = encode_half(image)
                blobs[key + ":err"] = encode_half(log_map(err))
                blobs[key + ":var"] = encode_half(log_map(var))
            own = float(np.mean(relative_error(image, ref) ** 2))
            crops = {}
            for n, rect in regions.items():
                mean = p.regions.get(n, {}).get("rel_mse")
                crops[n] = {"text": f"relMSE {_fmt(region_rel_mse(image, ref, rect))}" +
                            (f" (mean {_fmt(mean)})" if mean is not None else "")}
            off = f" ({off_budget_text(p)})" if missed_budget(p) else ""
            entries.append({"label": name + (" (off budget)" if off else ""), "key": name, "rgb": key,
                            "err": key + ":err", "var": key + ":var", "crops": crops,
                            "detail": f"{name}: {p.spp} spp, {p.time_s:.3g} s (median of {p.seeds} seeds){off}; "
                                      f"relMSE of this image {_fmt(own)}, mean over seeds {_fmt(p.rel_mse)}"})
        out_sets.append({"name": cset.name, "entries": entries})
    blobs["ref:err"] = encode_half(log_map(np.sqrt(ref_var)))
    blobs["ref:var"] = encode_half(log_map(ref_var))
    return {"scene": scene, "width": width, "height": height, "start": default_set(sets),
            "regions": {n: list(map(int, r)) for n, r in regions.items()}, "sets": out_sets, "images": blobs,
            "crop_exposure": {n: crop_exposure(ref, r) for n, r in regions.items()},
            "err_range": _range([log_map(m) for m in err_maps]), "var_range": _range([log_map(m) for m in var_maps]),
            "diff_range": _symmetric_range(diff_maps),
            "colormaps": {"err": colormap_stops("magma"), "var": colormap_stops("viridis"),
                          "diff": colormap_stops("RdBu_r")}}


def _fmt(value) -> str:
    from ...reporting import fmt

    return fmt(value, 2)


def viewer_block(data: dict) -> str:
    """The HTML of one viewer: an empty container and its data; viewer.js fills it in."""
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    return (f'<div class="viewer" tabindex="0" data-scene="{html.escape(data["scene"])}">'
            f'<script type="application/json" class="vw-data">{payload}</script></div>')


def script() -> str:
    """The viewer's JavaScript (the package file viewer.js), once per page."""
    return resources.files(__package__).joinpath("viewer.js").read_text(encoding="utf-8")
