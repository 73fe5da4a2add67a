"""``mitsuba-lab check [SCENES...]``: every lab strategy on stiff scenes, against `path`.

For each scene: its traits (``scene.SceneTraits``) and warnings (geometry beyond
far_clip, emitters that emit nothing, participating media), then every strategy that
applies to it (``scene.strategy_applicability``; the others are listed with the
reason), each class of provably identical strategies rendered once
(``scene.equivalent_strategies``), and Mitsuba's `path` as the reference at more
samples per pixel. Each strategy is rendered as ``--splits`` independent renders
(seeds 0..), whose spread gives the standard error of its image mean. The reference
comes from the sweep runner's content-addressed reference cache (``--cache``, shared
with ``mitsuba-lab reference`` and sweeps): rendered once in ``--splits`` independent
chunks, it keeps its mean image and the per-pixel variance of that mean, and is reused
by every later check with the same scene, settings and versions.

Resolution: ``--res N`` renders N x N. A scene that declares ``<default name="res" .../>``
(the shipped ones do) gets it as its ``res`` parameter; any other scene gets its first
sensor's film width and height set to N by editing the XML (``scene_xml.load_scene_variant``).

Columns: finite fraction (of pixel channels), negative pixels, max value, fireflies,
mean luminance, its z-score against the reference, rays per pixel by kind, time.

Firefly rule: with luminance Y = 0.2126 R + 0.7152 G + 0.0722 B of the combined
image, a pixel is a firefly when Y > k * max(median of Y over the 5 x 5 pixels around
it (edges replicated), 0.01 * mean Y of the reference image); k = ``--firefly-k``
(default 10). The floor keeps black regions from turning every speck into a firefly.

z-score: z = (m - m_ref) / sqrt(s^2 / R + se_ref^2), with m the mean luminance over
the R splits, s^2 their sample variance, m_ref the reference's mean luminance and
se_ref its standard error, from the reference's per-pixel variance of the mean: pixels
are independent (box filter, as in the shipped scenes; a wider filter shares samples
between neighbours, and se_ref comes out somewhat small), and a pixel's luminance
variance is taken as (sum_c w_c sd_c)^2 over its channels c, exact when the channels
move together (as they do along one light path) and an upper bound otherwise
(``reference_mean_variance``). Every lab strategy that applies is
unbiased by design, so |z| > ``--z-max`` is a failure. An estimator whose rare
events (a tiny light hit by BSDF sampling, an emitter sample inside a near-delta
lobe) never happen in the budget shows up here too, with zero spread across splits:
unbiased in theory, useless in practice; the note column says so.

Exit status: 0 when every strategy is finite, non-negative and within the bound;
1 when any is not; 2 for bad input (raised as LabError).
"""
from __future__ import annotations

import argparse
import glob
import html
import math
import os
import time

import numpy as np

from .commands.args import positive_int

from . import metrics
from .errors import LabError
from .reporting import dict_rows, fmt, html_page, html_table, write_csv as write_table, write_text

#: name -> (integrator type, parameters); max_depth comes from --max-depth.
STRATEGIES = {
    "lab_naive": ("lab_naive", {}),
    "lab_nee": ("lab_nee", {}),
    "lab_mis_power": ("lab_mis", {"heuristic": "power"}),
    "lab_mis_balance": ("lab_mis", {"heuristic": "balance"}),
}
REFERENCE = "path"
#: Luminance weights (Rec. 709 primaries) of R, G, B.
LUMINANCE = (0.2126, 0.7152, 0.0722)
FIREFLY_WINDOW = 5
FIREFLY_FLOOR = 0.01
COLUMNS = ("scene", "strategy", "status", "finite_fraction", "negative_pixels", "max_value",
           "fireflies", "mean", "ref_mean", "z", "camera_rays_per_pixel",
           "extension_rays_per_pixel", "shadow_rays_per_pixel", "time_s", "note")


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Render every scene with every lab strategy that applies (lab_naive, lab_nee, lab_mis "
        "power and balance) and Mitsuba's path as reference; print finite fraction, negative "
        "pixels, max value, fireflies, mean and its z-score against the reference, rays per "
        "pixel by kind; write CSV + HTML. Exit status 1 when any strategy gives NaN, Inf or "
        "negative values or a mean beyond --z-max standard errors of the reference.")
    parser.add_argument("scenes", nargs="*", metavar="SCENE",
                        help="Mitsuba XML scene files (default: every scenes/stiff/*.xml)")
    parser.add_argument("--res", type=positive_int, default=32,
                        help="image width and height (default: 32): passed as the scene's 'res' "
                             "parameter when the scene declares <default name=\"res\" .../>, otherwise "
                             "set as the first sensor's film width and height (the XML is edited)")
    parser.add_argument("--spp", type=positive_int, default=64,
                        help="samples per pixel of each lab strategy, over all splits (default: 64)")
    parser.add_argument("--ref-spp", type=positive_int, default=256,
                        help="samples per pixel of the path reference, over all splits (default: 256)")
    parser.add_argument("--splits", type=positive_int, default=8,
                        help="independent renders per strategy (seeds 0..) and chunks of the reference, "
                             ">= 2; their spread gives the standard error of the mean; --spp and "
                             "--ref-spp must be multiples of it (default: 8)")
    parser.add_argument("--max-depth", type=int, default=8,
                        help="max_depth of every integrator, -1 = unbounded (default: 8)")
    parser.add_argument("--z-max", type=_positive_float, default=5.0,
                        help="largest |z| of the mean luminance against the reference that passes "
                             "(default: 5; P(|z| > 5) = 6e-7 for a normal z)")
    parser.add_argument("--firefly-k", type=_positive_float, default=10.0,
                        help="a pixel is a firefly when its luminance exceeds k times the median of "
                             "its 5x5 neighbourhood (and k times 1%% of the reference's mean) "
                             "(default: 10)")
    parser.add_argument("-D", "--define", action="append", metavar="KEY=VALUE",
                        help="scene <default> value for every scene, e.g. -D far_clip=1e4 (repeatable)")
    parser.add_argument("--cache", help="reference cache folder, shared with `mitsuba-lab reference` and "
                                        "sweeps (default: $MITSUBA_LAB_CACHE or ~/.cache/mitsuba_lab/references)")
    parser.add_argument("-o", "--output", default=os.path.join("out", "check"),
                        help="output path without extension: writes OUTPUT.csv and OUTPUT.html "
                             "(default: out/check)")


# -- Measurements (pure numpy) ----------------------------------------------------------------

def luminance(image: np.ndarray) -> np.ndarray:
    return image[..., 0] * LUMINANCE[0] + image[..., 1] * LUMINANCE[1] + image[..., 2] * LUMINANCE[2]


def firefly_count(image: np.ndarray, k: float, floor: float) -> int:
    """Pixels whose luminance exceeds k * max(5x5 local median, floor) (module doc)."""
    y = np.nan_to_num(luminance(image), nan=0.0, posinf=np.finfo(np.float32).max)
    pad = FIREFLY_WINDOW // 2
    windows = np.lib.stride_tricks.sliding_window_view(np.pad(y, pad, mode="edge"),
                                                       (FIREFLY_WINDOW, FIREFLY_WINDOW))
    local = np.median(windows, axis=(-2, -1))
    return int(np.sum(y > k * np.maximum(local, floor)))


def reference_mean_variance(variance: np.ndarray) -> float:
    """Variance of a reference's mean luminance, from the per-pixel, per-channel variance of
    its mean image (H x W x C). Pixels are taken as independent (a box filter: each sample
    lands in one pixel); a pixel's luminance variance is (sum_c w_c sd_c)^2, the largest the
    channels' variances allow, reached when they move together, as the channels of one light
    path do (module doc)."""
    sd = np.sqrt(np.asarray(variance, dtype=np.float64)[..., :3])
    pixels = sd.shape[0] * sd.shape[1]
    return float(np.sum(luminance(sd) ** 2) / pixels ** 2)


def measure(stack: np.ndarray, rays: dict, seconds: float, ref: dict, k: float) -> dict:
    """Row values for one strategy's splits (R x H x W x C) against the reference's summary
    (``reference_summary``)."""
    finite = np.isfinite(stack)
    image = stack.mean(axis=0)
    pixels = image.shape[0] * image.shape[1]
    negative = int(np.sum(np.any(stack < 0, axis=-1)))
    means = luminance(stack).mean(axis=(1, 2))
    row = {"finite_fraction": float(finite.mean()), "negative_pixels": negative,
           "max_value": float(stack[finite].max()) if finite.any() else math.nan,
           "mean": float(means.mean()), "time_s": seconds,
           **{f"{kind}_rays_per_pixel": rays.get(kind, 0) / pixels for kind in
              ("camera", "extension", "shadow")}}
    row["fireflies"] = firefly_count(image, k, max(FIREFLY_FLOOR * ref["mean"], 1e-12))
    row["ref_mean"] = ref["mean"]
    row["z"] = (metrics.z_score(means.mean(), means.var(ddof=1), len(means), ref["mean"], ref["mean_variance"], 1)
                if ref["finite"] else math.nan)
    row["split_means"] = means
    return row


def reference_summary(reference, k: float) -> tuple[dict, dict]:
    """(summary for ``measure``, the reference's own row values) of a cached reference
    (``experiment.reference.Reference``): its mean image stands in for the combined image of
    the splits, so finite fraction, negative pixels, max value and fireflies are those of the
    mean image."""
    image, variance = reference.image.astype(np.float64), reference.variance
    finite = np.isfinite(image)
    mean = float(luminance(image).mean())
    summary = {"mean": mean, "mean_variance": reference_mean_variance(variance),
               "finite": bool(finite.all() and np.isfinite(variance).all())}
    row = {"finite_fraction": float(finite.mean()), "negative_pixels": int(np.sum(np.any(image < 0, axis=-1))),
           "max_value": float(image[finite].max()) if finite.any() else math.nan, "mean": mean,
           "time_s": float(reference.meta.get("seconds", 0.0)),
           **{f"{kind}_rays_per_pixel": 0.0 for kind in ("camera", "extension", "shadow")}}
    floor = FIREFLY_FLOOR * float(np.nanmean(luminance(image)))
    row["fireflies"] = firefly_count(image, k, max(floor, 1e-12))
    return summary, row


# -- Rendering ----------------------------------------------------------------------------------

def render_splits(scene, integrator, spp_total, splits, seed0):
    from .render import render

    spp = spp_total // splits
    images, rays, seconds = [], {}, 0.0
    for index in range(splits):
        image, stats = render(scene, integrator, spp=spp, seed=seed0 + index)
        images.append(image[..., :3])
        seconds += stats.wall_s
        for kind, count in stats.rays.items():
            rays[kind] = rays.get(kind, 0) + count
    return np.stack(images), rays, seconds


def default_scenes() -> list[str]:
    from .commands.args import project_root

    return sorted(glob.glob(os.path.join(project_root(), "scenes", "stiff", "*.xml")))


def scene_settings(path: str, res: int, defines: dict) -> tuple[int | None, dict]:
    """(film size to set in the XML or None, <default> values) that make the scene
    ``res`` x ``res``: its ``res`` parameter when it declares one (``<default name="res"
    .../>``, as the shipped scenes do), else the first sensor's film width and height, so any
    scene works. ``defines`` (-D) fill the scene's other <default> parameters."""
    from .scene_xml import scene_defaults

    if "res" in scene_defaults(path):
        return None, {"res": res, **defines}
    defines = dict(defines)
    res = int(defines.pop("res", res))        # -D res=N means the film size here too
    return res, defines


def load_check_scene(path: str, res: int, defines: dict):
    """The scene at ``res`` x ``res`` (``scene_settings``)."""
    from .scene import load_scene
    from .scene_xml import load_scene_variant

    resolution, defaults = scene_settings(path, res, defines)
    if resolution is None:
        return load_scene(path, **defaults)
    return load_scene_variant(path, resolution, None, defaults)


def cache_folder(option: str | None) -> str:
    """The reference cache: ``--cache``, else $MITSUBA_LAB_CACHE, else the default folder
    (as ``mitsuba-lab reference``)."""
    from .experiment.config import DEFAULT_CACHE

    return os.path.abspath(os.path.expanduser(option or os.environ.get("MITSUBA_LAB_CACHE") or DEFAULT_CACHE))


def check_reference(path: str, args, defines: dict):
    """(Reference, was_cached): Mitsuba's path at ``--ref-spp`` in ``--splits`` chunks, from
    the reference cache or rendered into it."""
    from .experiment.config import PluginSpec
    from .experiment.reference import get_reference

    resolution, defaults = scene_settings(path, args.res, defines)
    spec = PluginSpec("reference", REFERENCE, {"max_depth": args.max_depth})
    return get_reference(os.path.abspath(path), resolution, defaults, spec, args.ref_spp, args.splits,
                         cache_folder(args.cache))


def check_scene(path, args, defines, out) -> tuple[list[dict], list[str]]:
    from .scene import SceneTraits, equivalent_strategies, make_integrator, strategy_applicability

    scene = load_check_scene(path, args.res, defines)
    traits = SceneTraits.from_scene(scene)
    name = os.path.basename(path)
    warnings = traits.warnings()
    for warning in warnings:
        print(f"  warning: {name}: {warning}", file=out)
    depth = {"max_depth": args.max_depth}
    reference, cached = check_reference(path, args, defines)
    ref, ref_row = reference_summary(reference, args.firefly_k)
    if not ref["finite"]:
        warnings.append("the path reference has non-finite pixels: no z-scores")
    origin = "from the cache" if cached else "rendered into the cache"
    rows = [{"scene": name, "strategy": f"{REFERENCE} (reference)", "status": "reference",
             **ref_row, "ref_mean": ref["mean"], "z": 0.0,
             "note": f"{args.ref_spp} spp, {origin} ({reference.key})"}]

    applicable = {}
    for strategy, (kind, params) in STRATEGIES.items():
        applies, reason = strategy_applicability(traits, kind, params)
        if applies:
            applicable[strategy] = (kind, params)
        else:
            rows.append({"scene": name, "strategy": strategy, "status": "skipped", "note": reason})
    canonical = equivalent_strategies(traits, applicable)
    measured = {}
    for strategy, (kind, params) in applicable.items():
        twin = canonical[strategy]
        if twin != strategy:
            rows.append({**measured[twin], "strategy": strategy, "status": "same", "time_s": 0.0,
                         "note": f"the same estimator as {twin} on this scene: not rendered "
                                 f"(its row's numbers)"})
            continue
        integrator = make_integrator(kind, {**params, **depth})
        render_splits(scene, integrator, args.splits, 1, 0)               # warm-up: compile
        stack, rays, seconds = render_splits(scene, integrator, args.spp, args.splits, 0)
        row = {"scene": name, "strategy": strategy,
               **measure(stack, rays, seconds, ref, args.firefly_k), "note": ""}
        problems = []
        if row["finite_fraction"] < 1:
            problems.append("NaN/Inf")
        if row["negative_pixels"]:
            problems.append("negative")
        if not abs(row["z"]) <= args.z_max and ref["finite"]:
            problems.append(f"mean off by {row['z']:+.1f} sigma")
            if np.ptp(row["split_means"]) == 0:
                row["note"] = ("no spread across splits: the estimator never sampled what the "
                               "reference sees (unbiased, but unconverged at this spp)")
        row["status"] = "FAIL: " + ", ".join(problems) if problems else "ok"
        measured[strategy] = row
        rows.append(row)
    return rows, warnings


# -- Output -------------------------------------------------------------------------------------

def _fmt(value, digits=4) -> str:
    return fmt(value, digits, missing="-")


def format_table(rows: list[dict]) -> str:
    head = (f"{'scene':26s} {'strategy':18s} {'status':24s} {'finite':>7s} {'neg':>5s} {'max':>9s} "
            f"{'ffly':>5s} {'mean':>9s} {'z':>7s} {'cam/px':>7s} {'ext/px':>7s} {'shd/px':>7s}")
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['scene'][:26]:26s} {r['strategy'][:18]:18s} {r['status'][:24]:24s} "
            f"{_fmt(r.get('finite_fraction')):>7s} {_fmt(r.get('negative_pixels')):>5s} "
            f"{_fmt(r.get('max_value')):>9s} {_fmt(r.get('fireflies')):>5s} {_fmt(r.get('mean')):>9s} "
            f"{_fmt(r.get('z'), 3):>7s} {_fmt(r.get('camera_rays_per_pixel'), 3):>7s} "
            f"{_fmt(r.get('extension_rays_per_pixel'), 3):>7s} {_fmt(r.get('shadow_rays_per_pixel'), 3):>7s}"
            + (f"  {r['note']}" if r.get("note") else ""))
    return "\n".join(lines)


def write_csv(path: str, rows: list[dict]) -> None:
    write_table(path, COLUMNS, dict_rows(rows, COLUMNS))


#: Row colours of the HTML table by status.
ROW_STYLE = "tr.fail td { background: #fcc; } tr.skipped td, tr.same td { color: #777; }"


def write_html(path: str, rows: list[dict], warnings: dict[str, list[str]], settings: str) -> None:
    parts = ["<h1>mitsuba-lab check</h1>", f"<p>{html.escape(settings)}</p>",
             f"<pre>{html.escape(__doc__.split(chr(10) * 2, 1)[1])}</pre>"]
    if any(warnings.values()):
        parts.append("<h2>Warnings</h2><ul>")
        for scene, notes in warnings.items():
            parts.extend(f"<li>{html.escape(scene)}: {html.escape(n)}</li>" for n in notes)
        parts.append("</ul>")
    classes = []
    for row in rows:
        status = row.get("status", "")
        classes.append("fail" if status.startswith("FAIL") else status.split(":")[0])
    parts.append(html_table(COLUMNS, [[_fmt(row.get(c)) for c in COLUMNS] for row in rows], classes))
    write_text(path, html_page("mitsuba-lab check", "\n".join(parts), ROW_STYLE))


def run(args, out) -> int:
    """The command: 0 = all good, 1 = some strategy failed (LabError for bad input)."""
    from .commands.args import parse_assignments

    if args.splits < 2:
        raise LabError(f"--splits must be >= 2 (the standard error needs a spread), got {args.splits}")
    for option, value in (("--spp", args.spp), ("--ref-spp", args.ref_spp)):
        if value % args.splits:
            raise LabError(f"{option} {value} is not a multiple of --splits {args.splits}")
    if args.max_depth < -1:
        raise LabError(f"--max-depth must be -1 (unbounded) or >= 0, got {args.max_depth}")
    try:
        defines = parse_assignments(args.define, "--define")
    except ValueError as err:
        raise LabError(str(err)) from err
    scenes = args.scenes or default_scenes()
    if not scenes:
        raise LabError("no scenes given and no scenes/stiff/*.xml found")
    for path in scenes:
        if not os.path.isfile(path):
            raise LabError(f"scene file not found: {path}")
    folder = os.path.dirname(os.path.abspath(args.output))
    if args.output == os.path.join("out", "check"):
        os.makedirs(folder, exist_ok=True)
    if not os.path.isdir(folder) or not os.access(folder, os.W_OK):
        raise LabError(f"output folder does not exist or is not writable: {folder}")

    settings = (f"{args.res}x{args.res}, {args.spp} spp per strategy, path reference {args.ref_spp} spp, "
                f"{args.splits} splits, max_depth {args.max_depth}, |z| <= {args.z_max:g}, "
                f"firefly k = {args.firefly_k:g}")
    print(f"mitsuba-lab check: {len(scenes)} scene(s); {settings}", file=out)
    rows, warnings = [], {}
    start = time.perf_counter()
    for path in scenes:
        print(f"{os.path.basename(path)} ...", file=out, flush=True)
        scene_rows, scene_warnings = check_scene(path, args, defines, out)
        rows.extend(scene_rows)
        warnings[os.path.basename(path)] = scene_warnings
    print(format_table(rows), file=out)
    write_csv(args.output + ".csv", rows)
    write_html(args.output + ".html", rows, warnings, settings)
    failures = [r for r in rows if r.get("status", "").startswith("FAIL")]
    print(f"{len(failures)} failure(s) in {time.perf_counter() - start:.1f} s; wrote {args.output}.csv "
          f"and {args.output}.html", file=out)
    return 1 if failures else 0
