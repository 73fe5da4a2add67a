"""``mitsuba-lab check [SCENES...]``: every lab strategy on stiff scenes, against `path`.

For each scene: its traits (``scene.SceneTraits``) and warnings (geometry beyond
far_clip, emitters that emit nothing, participating media), then every strategy that
applies to it (``scene.strategy_applicability``; the others are listed with the
reason), each class of provably identical strategies rendered once
(``scene.equivalent_strategies``), and Mitsuba's `path` as the reference at more
samples per pixel. Each strategy and the reference are rendered as ``--splits``
independent renders (seeds 0.. and 1000..), whose spread gives the standard error
of the image mean.

Resolution: ``--res N`` renders N x N. A scene that declares ``<default name="res" .../>``
(the shipped ones do) gets it as its ``res`` parameter; any other scene gets its first
sensor's film width and height set to N by editing the XML (``scene_xml.load_scene_variant``).

Columns: finite fraction (of pixel channels), negative pixels, max value, fireflies,
mean luminance, its z-score against the reference, rays per pixel by kind, time.

Firefly rule: with luminance Y = 0.2126 R + 0.7152 G + 0.0722 B of the combined
image, a pixel is a firefly when Y > k * max(median of Y over the 5 x 5 pixels around
it (edges replicated), 0.01 * mean Y of the reference image); k = ``--firefly-k``
(default 10). The floor keeps black regions from turning every speck into a firefly.

z-score: z = (m - m_ref) / sqrt(s^2 / R + s_ref^2 / R_ref), with m the mean luminance
over the R splits and s^2 their sample variance. Every lab strategy that applies is
unbiased by design, so |z| > ``--z-max`` is a failure. An estimator whose rare
events (a tiny light hit by BSDF sampling, an emitter sample inside a near-delta
lobe) never happen in the budget shows up here too, with zero spread across splits:
unbiased in theory, useless in practice; the note column says so.

Exit status: 0 when every strategy is finite, non-negative and within the bound;
1 when any is not; 2 for bad input (raised as LabError).
"""
from __future__ import annotations

import argparse
import csv
import glob
import html
import math
import os
import time

import numpy as np

from .cli import positive_int

from .errors import LabError

#: name -> (integrator type, parameters); max_depth comes from --max-depth.
STRATEGIES = {
    "lab_naive": ("lab_naive", {}),
    "lab_nee": ("lab_nee", {}),
    "lab_mis_power": ("lab_mis", {"heuristic": "power"}),
    "lab_mis_balance": ("lab_mis", {"heuristic": "balance"}),
}
REFERENCE = "path"
REF_SEED0 = 1000
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
                        help="independent renders per strategy (seeds 0..) and reference (seeds 1000..), "
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
    parser.add_argument("-o", "--output", default=os.path.join("out", "check"),
                        help="output path without extension: writes OUTPUT.csv and OUTPUT.html "
                             "(default: out/check)")


# -- Measurements (pure numpy) ----------------------------------------------------------------

def luminance(image: np.ndarray) -> np.ndarray:
    return image[..., 0] * 0.2126 + image[..., 1] * 0.7152 + image[..., 2] * 0.0722


def firefly_count(image: np.ndarray, k: float, floor: float) -> int:
    """Pixels whose luminance exceeds k * max(5x5 local median, floor) (module doc)."""
    y = np.nan_to_num(luminance(image), nan=0.0, posinf=np.finfo(np.float32).max)
    pad = FIREFLY_WINDOW // 2
    windows = np.lib.stride_tricks.sliding_window_view(np.pad(y, pad, mode="edge"),
                                                       (FIREFLY_WINDOW, FIREFLY_WINDOW))
    local = np.median(windows, axis=(-2, -1))
    return int(np.sum(y > k * np.maximum(local, floor)))


def z_score(means: np.ndarray, ref_means: np.ndarray) -> float:
    """(mean - ref mean) / standard error of the difference, from the splits' spread."""
    diff = float(means.mean() - ref_means.mean())
    se = math.sqrt(means.var(ddof=1) / len(means) + ref_means.var(ddof=1) / len(ref_means))
    if se > 0:
        return diff / se
    return 0.0 if diff == 0 else math.copysign(math.inf, diff)


def measure(stack: np.ndarray, rays: dict, seconds: float, ref: dict | None, k: float) -> dict:
    """Row values for one strategy's splits (R x H x W x C)."""
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
    floor = FIREFLY_FLOOR * (ref["mean"] if ref else float(np.nanmean(luminance(image))))
    row["fireflies"] = firefly_count(image, k, max(floor, 1e-12))
    if ref is not None:
        row["ref_mean"] = ref["mean"]
        row["z"] = z_score(means, ref["split_means"]) if ref["finite"] else math.nan
        row["split_means"] = means
    return row


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
    from .cli import project_root

    return sorted(glob.glob(os.path.join(project_root(), "scenes", "stiff", "*.xml")))


def load_check_scene(path: str, res: int, defines: dict):
    """The scene at ``res`` x ``res``: through its ``res`` parameter when it declares one
    (``<default name="res" .../>``, as the shipped scenes do), else by setting the first
    sensor's film width and height in the XML (``scene_xml.load_scene_variant``), so any
    scene works. ``defines`` (-D) fill the scene's other <default> parameters."""
    from .scene import load_scene
    from .scene_xml import load_scene_variant, scene_defaults

    if "res" in scene_defaults(path):
        return load_scene(path, **{"res": res, **defines})
    defines = dict(defines)
    res = int(defines.pop("res", res))        # -D res=N means the film size here too
    return load_scene_variant(path, res, None, defines)


def check_scene(path, args, defines, out) -> tuple[list[dict], list[str]]:
    from .scene import SceneTraits, equivalent_strategies, make_integrator, strategy_applicability

    scene = load_check_scene(path, args.res, defines)
    traits = SceneTraits.from_scene(scene)
    name = os.path.basename(path)
    warnings = traits.warnings()
    for warning in warnings:
        print(f"  warning: {name}: {warning}", file=out)
    depth = {"max_depth": args.max_depth}
    stack, rays, seconds = render_splits(scene, make_integrator(REFERENCE, depth), args.ref_spp,
                                         args.splits, REF_SEED0)
    ref_row = measure(stack, {}, seconds, None, args.firefly_k)
    ref = {"mean": ref_row["mean"], "split_means": luminance(stack).mean(axis=(1, 2)),
           "finite": bool(np.isfinite(stack).all())}
    if not ref["finite"]:
        warnings.append("the path reference has non-finite pixels: no z-scores")
    rows = [{"scene": name, "strategy": f"{REFERENCE} (reference)", "status": "reference",
             **ref_row, "ref_mean": ref["mean"], "z": 0.0, "note": f"{args.ref_spp} spp"}]

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
    if value is None or value == "":
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


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
    from .images import atomic_path

    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=COLUMNS, extrasaction="ignore")
            writer.writeheader()
            for row in rows:
                writer.writerow({k: row.get(k, "") for k in COLUMNS})


def write_html(path: str, rows: list[dict], warnings: dict[str, list[str]], settings: str) -> None:
    from .images import atomic_path

    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>mitsuba-lab check</title>",
             "<style>body{font-family:sans-serif}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:2px 6px;font-size:13px}.fail{background:#fcc}"
             ".skipped,.same{color:#777}</style></head><body><h1>mitsuba-lab check</h1>",
             f"<p>{html.escape(settings)}</p>", f"<pre>{html.escape(__doc__.split(chr(10) * 2, 1)[1])}</pre>"]
    if any(warnings.values()):
        parts.append("<h2>Warnings</h2><ul>")
        for scene, notes in warnings.items():
            parts.extend(f"<li>{html.escape(scene)}: {html.escape(n)}</li>" for n in notes)
        parts.append("</ul>")
    parts.append("<table><tr>" + "".join(f"<th>{c}</th>" for c in COLUMNS) + "</tr>")
    for row in rows:
        status = row.get("status", "")
        css = "fail" if status.startswith("FAIL") else status.split(":")[0]
        parts.append(f"<tr class='{css}'>" + "".join(f"<td>{html.escape(_fmt(row.get(c)))}</td>"
                                                      for c in COLUMNS) + "</tr>")
    parts.append("</table></body></html>")
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as handle:
            handle.write("\n".join(parts))


def run(args, out) -> int:
    """The command: 0 = all good, 1 = some strategy failed (LabError for bad input)."""
    from .cli import parse_assignments

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
