"""``mitsuba-lab check [SCENES...]``: every lab strategy on stiff scenes, against `path`.

For each scene: its traits (``scene.SceneTraits``) and warnings (geometry beyond
far_clip, emitters that emit nothing, participating media), then every strategy that
applies to it (``scene.strategy_applicability``; the others are listed with the
reason), each class of provably identical strategies rendered once
(``scene.equivalent_strategies``), and Mitsuba's `path` as the reference at more
samples per pixel (``volpathmis`` on a scene with participating media, which `path` ignores:
``features.default_reference``). Each strategy is rendered as ``--splits`` independent renders
(seeds 0..), whose spread gives the standard error of its image mean. The reference
comes from the sweep runner's content-addressed reference cache (``--cache``, shared
with ``mitsuba-lab reference`` and sweeps): rendered once in ``--splits`` independent
chunks, it keeps its mean image and the per-pixel variance of that mean, and is reused
by every later check with the same scene, settings and versions.

Resolution: ``--res N`` is given to a scene that declares ``<default name="res" .../>`` (the
shipped ones do, for a square film) as its ``res`` parameter; any other scene gets its first
sensor's film edited (``scene_xml.load_scene_variant``): N sets the larger side and keeps the
aspect ratio. ``--res WxH`` sets the film's width and height on every scene.

Strategies: lab_naive, lab_nee, lab_mis (power and balance), lab_bdpt, lab_vcm in modes bpt,
vcm and ppm, and lab_photon (its sample count is its passes).

Columns: finite fraction (of pixel channels), negative pixels, max value, fireflies,
mean luminance, its z-score against the reference, rays per pixel by kind (camera,
extension, shadow, and the bidirectional integrators' other kinds summed: connections,
light subpaths, rays to the sensor, merge lookups, photon segments), time.

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
(``reference_mean_variance``).

Verdicts (``check_verdicts``): lab_vcm's merging modes (vcm, ppm) and lab_photon are
consistent, not unbiased: their row says "converging" with the measured log-log slope of bias^2
against the samples (bias^2 at 1, 4 and 16 times the budget per split), fails when a resolved
bias^2 does not shrink, and claims nothing when no bias is resolved. Every other lab strategy
that applies is unbiased by design, so
|z| > ``--z-max`` is a failure, with two exceptions that are told apart, not assumed. A mean
too *low* may be an unbiased estimator whose rare, huge samples the budget does not resolve
(a BSDF ray hitting a tiny light, an emitter sample inside a near-delta lobe): the strategy
is rendered again at 4 and 16 times the budget per split (``--escalate``), and when the
deficit sits in pixels where no sample ever found light, or shrinks as the budget grows, or
the split means are strongly skewed, the row is a warning, "unconverged: heavy-tailed
estimator", with those numbers; a deficit that holds, with symmetric split means, fails as a
bias (and so does any mean too *high*). A scene that declares an unscaled twin
(``<default name="twin" value="PATH"/>``) has `path` rendered on the twin as well; when the
scene's `path` disagrees with it, Mitsuba's reference is off there (ray offsets at this
scale) and the strategies are judged against the twin.

Exit status: 0 when every strategy is finite, non-negative and within the bound or only
warned about (heavy tail); 1 when any fails; 2 for bad input (raised as LabError).
"""
from __future__ import annotations

import argparse
import glob
import math
import os
import time

import numpy as np

from . import metrics
from .metrics import luminance
from .check_report import format_table, format_verdicts, verdict_kind, write_csv, write_html
from .check_verdicts import (LADDER_SPLITS, Rung, Twin, Verdict, empty_pixels, judge, judge_consistent, path_off_note,
                             twin_status)
from .check_render import bias_ladder, is_consistent, render_ladder, render_splits
from .commands.args import positive_int, resolution_arg
from .errors import LabError
from .film import as_resolution, resolution_text

#: name -> (integrator type, parameters); max_depth comes from --max-depth.
PATH_STRATEGIES = {
    "lab_naive": ("lab_naive", {}),
    "lab_nee": ("lab_nee", {}),
    "lab_mis_power": ("lab_mis", {"heuristic": "power"}),
    "lab_mis_balance": ("lab_mis", {"heuristic": "balance"}),
}
#: The bidirectional and density-estimation strategies: lab_bdpt and lab_vcm's bpt are unbiased
#: (the z-test), lab_vcm's vcm and ppm and lab_photon consistent (bias^2 shrinking). lab_photon's
#: sample count is its passes (``Estimator.SAMPLE_COUNT_PARAMETER``), of fewer photons than its
#: default: check's images are small.
BIDIRECTIONAL_STRATEGIES = {
    "lab_bdpt": ("lab_bdpt", {}),
    "lab_vcm_bpt": ("lab_vcm", {"mode": "bpt"}),
    "lab_vcm": ("lab_vcm", {"mode": "vcm", "pilot": False}),   # (merging itself, not the pilot's choice)
    "lab_vcm_ppm": ("lab_vcm", {"mode": "ppm"}),
    "lab_photon": ("lab_photon", {"photons_per_pass": 10_000}),
}
STRATEGIES = {**PATH_STRATEGIES, **BIDIRECTIONAL_STRATEGIES}
#: Ray kinds with a column of their own (the path tracers'); the bidirectional integrators'
#: other kinds are summed in ``other_rays_per_pixel``.
RAY_COLUMNS = ("camera", "extension", "shadow")
#: Luminance weights (Rec. 709 primaries) of R, G, B.
FIREFLY_WINDOW = 5
FIREFLY_FLOOR = 0.01


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Render every scene with every lab strategy that applies (lab_naive, lab_nee, lab_mis "
        "power and balance, lab_bdpt, lab_vcm modes bpt, vcm and ppm, lab_photon) and Mitsuba's path as "
        "reference; print finite fraction, negative "
        "pixels, max value, fireflies, mean and its z-score against the reference, rays per "
        "pixel by kind; write CSV + HTML. Exit status 1 when any strategy gives NaN, Inf or "
        "negative values or a mean beyond --z-max standard errors of the reference, except a low "
        "mean with the marks of an unresolved heavy tail (a warning); the consistent ones (lab_vcm vcm "
        "and ppm, lab_photon) are judged by their bias^2 shrinking as the budget grows. A scene that declares an "
        "unscaled twin (<default name=\"twin\" .../>) is also compared with path on the twin.")
    parser.add_argument("scenes", nargs="*", metavar="SCENE",
                        help="Mitsuba XML scene files (default: every scenes/stiff/*.xml)")
    parser.add_argument("--res", type=resolution_arg, default=32,
                        help="film size (default: 32): N is passed as the scene's 'res' parameter when "
                             "the scene declares <default name=\"res\" .../>, otherwise it sets the first "
                             "sensor's film's larger side, keeping its aspect ratio (the XML is edited); "
                             "WxH sets width and height")
    parser.add_argument("--spp", type=positive_int, default=64,
                        help="samples per pixel of each lab strategy, over all splits (default: 64)")
    parser.add_argument("--ref-spp", type=positive_int, default=256,
                        help="samples per pixel of the reference, over all splits (default: 256)")
    parser.add_argument("--splits", type=positive_int, default=8,
                        help="independent renders per strategy (seeds 0..) and chunks of the reference, "
                             ">= 2; their spread gives the standard error of the mean; --spp and "
                             "--ref-spp must be multiples of it (default: 8)")
    parser.add_argument("--max-depth", type=int, default=8,
                        help="max_depth of every integrator, -1 = unbounded (default: 8)")
    parser.add_argument("--z-max", type=_positive_float, default=5.0,
                        help="largest |z| of the mean luminance against the reference that passes "
                             "(default: 5; P(|z| > 5) = 6e-7 for a normal z)")
    parser.add_argument("--escalate", type=positive_int, default=16,
                        help="a strategy whose mean is below the reference by more than --z-max is "
                             "rendered again at 4x, 16x, ... up to this many times the budget per split "
                             f"({LADDER_SPLITS} splits each) to tell an unresolved heavy tail (a warning) "
                             "from a bias (a failure); 1 = never (default: 16)")
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
           **rays_per_pixel(rays, pixels)}
    row["fireflies"] = firefly_count(image, k, max(FIREFLY_FLOOR * ref["mean"], 1e-12))
    row["ref_mean"] = ref["mean"]
    row["z"] = (metrics.z_score(means.mean(), means.var(ddof=1), len(means), ref["mean"], ref["mean_variance"], 1)
                if ref["finite"] else math.nan)
    row["split_means"] = means
    return row


def rays_per_pixel(rays: dict, pixels: int) -> dict:
    """Row values: rays per pixel of each kind in ``RAY_COLUMNS``, and of every other kind summed
    (lab_bdpt's connection, light subpath and sensor rays, lab_vcm's merge lookups, lab_photon's
    photon segments)."""
    row = {f"{kind}_rays_per_pixel": rays.get(kind, 0) / pixels for kind in RAY_COLUMNS}
    row["other_rays_per_pixel"] = sum(v for k, v in rays.items() if k not in RAY_COLUMNS) / pixels
    return row


def reference_summary(reference, k: float) -> tuple[dict, dict]:
    """(summary for ``measure``, the reference's own row values) of a cached reference
    (``experiment.reference.Reference``): its mean image stands in for the combined image of
    the splits, so finite fraction, negative pixels, max value and fireflies are those of the
    mean image."""
    image, variance = reference.image.astype(np.float64), reference.variance
    finite = np.isfinite(image)
    pixels = luminance(image)
    mean = float(pixels.mean())
    summary = {"mean": mean, "mean_variance": reference_mean_variance(variance), "pixels": pixels,
               "finite": bool(finite.all() and np.isfinite(variance).all()),
               "image": image[..., :3], "variance": np.asarray(variance, dtype=np.float64)[..., :3]}
    row = {"finite_fraction": float(finite.mean()), "negative_pixels": int(np.sum(np.any(image < 0, axis=-1))),
           "max_value": float(image[finite].max()) if finite.any() else math.nan, "mean": mean,
           "time_s": float(reference.meta.get("seconds", 0.0)),
           **rays_per_pixel({}, 1)}
    floor = FIREFLY_FLOOR * float(np.nanmean(pixels))
    row["fireflies"] = firefly_count(image, k, max(floor, 1e-12))
    return summary, row


# -- Rendering ----------------------------------------------------------------------------------

def default_scenes() -> list[str]:
    from .commands.args import project_root

    return sorted(glob.glob(os.path.join(project_root(), "scenes", "stiff", "*.xml")))


def scene_settings(path: str, res, defines: dict) -> tuple[object, dict]:
    """(film override to edit into the XML or None, <default> values) for ``--res``: a scalar is
    the scene's ``res`` parameter when it declares one (``<default name="res" .../>``, as the
    shipped scenes do), else the film's larger side (``film``: aspect ratio kept), so any scene
    works; (W, H) sets the film's width and height. ``defines`` (-D) fill the scene's other
    <default> parameters."""
    from .scene_xml import scene_defaults

    if isinstance(res, int) and "res" in scene_defaults(path):
        return None, {"res": res, **defines}
    defines = dict(defines)
    if "res" in defines:                      # -D res=N means the film size here too
        try:
            res = as_resolution(defines.pop("res"))
        except ValueError as err:
            raise LabError(f"-D res: {err}") from None
    return res, defines


def load_check_scene(path: str, res, defines: dict):
    """The scene at the film size ``--res`` gives it (``scene_settings``)."""
    from .scene import load_scene
    from .scene_xml import load_scene_variant

    resolution, defaults = scene_settings(path, res, defines)
    if resolution is None:
        return load_scene(path, **defaults)
    return load_scene_variant(path, resolution, None, defaults)


def twin_of(path: str, defines: dict) -> tuple[str, str, dict] | None:
    """(declared name, path, -D values it declares) of the scene's unscaled twin
    (``<default name="twin" value="PATH"/>``, relative to the scene file), or None."""
    from .scene_xml import scene_defaults

    name = scene_defaults(path).get("twin")
    if not name:
        return None
    twin = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(path)), name))
    if not os.path.isfile(twin):
        raise LabError(f"{path}: its twin scene {name} is not found ({twin})")
    declared = scene_defaults(twin)
    return name, twin, {k: v for k, v in defines.items() if k in declared}


def cache_folder(option: str | None) -> str:
    """The reference cache: ``--cache``, else $MITSUBA_LAB_CACHE, else the default folder
    (as ``mitsuba-lab reference``)."""
    from .experiment.config import DEFAULT_CACHE

    return os.path.abspath(os.path.expanduser(option or os.environ.get("MITSUBA_LAB_CACHE") or DEFAULT_CACHE))


def check_reference(path: str, args, defines: dict, integrator: str):
    """(Reference, was_cached): ``integrator`` (Mitsuba's path, or volpathmis for a scene with
    media) at ``--ref-spp`` in ``--splits`` chunks, from the reference cache or rendered into it."""
    from .experiment.config import PluginSpec
    from .experiment.reference import get_reference

    resolution, defaults = scene_settings(path, args.res, defines)
    spec = PluginSpec("reference", integrator, {"max_depth": args.max_depth})
    return get_reference(os.path.abspath(path), resolution, defaults, spec, args.ref_spp, args.splits,
                         cache_folder(args.cache))


def _origin(reference, cached: bool, args) -> str:
    return f"{args.ref_spp} spp, {'from the cache' if cached else 'rendered into the cache'} ({reference.key})"


def references(path, name, args, defines, traits):
    """(reference rows, summary the strategies are judged against, path's summary, Twin or None,
    scene warnings): the scene's reference integrator (``features.default_reference``: Mitsuba's
    path unless the scene has media) on the scene, and on its unscaled twin when it declares one."""
    from .features import default_reference

    integrator = default_reference(traits)
    reference, cached = check_reference(path, args, defines, integrator)
    ref, ref_row = reference_summary(reference, args.firefly_k)
    rows = [{"scene": name, "strategy": f"{integrator} (reference)", "status": "reference", **ref_row,
             "ref_mean": ref["mean"], "z": 0.0, "note": _origin(reference, cached, args)}]
    warnings = [] if ref["finite"] else [f"the {integrator} reference has non-finite pixels: no z-scores"]
    found = twin_of(path, defines)
    if found is not None and traits.far_clip_problems:   # no longer the same scene at another scale
        warnings.append(f"not compared with its unscaled twin {found[0]}: it loses geometry beyond far_clip")
        found = None
    if found is None:
        return rows, ref, ref, None, warnings
    twin_name, twin_path, twin_defines = found
    twin_reference, twin_cached = check_reference(twin_path, args, twin_defines, integrator)
    twin_ref, twin_row = reference_summary(twin_reference, args.firefly_k)
    twin = Twin.compare(twin_name, twin_ref["mean"], twin_ref["mean_variance"], ref["mean"], ref["mean_variance"])
    rows[0].update(ref_mean=twin.mean, z=twin.z_path, z_twin=twin.z_path)
    rows.append({"scene": name, "strategy": f"{integrator} (twin)", "status": "twin reference", **twin_row,
                 "ref_mean": twin.mean, "note": f"{integrator} on the unscaled twin {twin_name}: "
                                                f"{_origin(twin_reference, twin_cached, args)}"})
    if twin.path_off(args.z_max) and twin_ref["finite"] and ref["finite"]:
        note = path_off_note(twin, traits.bbox_min, traits.bbox_max)
        rows[0].update(status="reference: OFF", note=note, evidence=[rows[0]["note"]])
        warnings.append(note)
        return rows, twin_ref, ref, twin, warnings
    rows[0]["note"] += f"; agrees with the unscaled twin {twin_name} ({twin.rel_path:+.1%})"
    return rows, ref, ref, twin, warnings


def _z_against(row: dict, mean: float, variance: float) -> float:
    means = row["split_means"]
    return metrics.z_score(row["mean"], np.var(means, ddof=1), len(means), mean, variance, 1)


def judge_strategy(row, stack, scene, strategy, args, judged, path_ref, twin) -> None:
    """Fill the row's status, note and evidence (module doc, ``check_verdicts``)."""
    problems = [name for name, bad in (("NaN/Inf", row["finite_fraction"] < 1),
                                       ("negative", row["negative_pixels"] > 0)) if bad]
    if is_consistent(*strategy):
        verdict = Verdict("ok")
        if judged["finite"] and not problems:
            verdict = judge_consistent(bias_ladder(scene, strategy, stack, args.spp // args.splits, args, judged),
                                       judged["mean"])
        row["note"], row["evidence"] = verdict.summary, verdict.evidence
        status = {"ok": "ok", "converging": "converging"}.get(verdict.kind, "FAIL: bias not shrinking")
        row["status"] = "FAIL: " + ", ".join(problems) if problems else status
        return
    verdict = Verdict("ok")
    if judged["finite"] and not problems:
        rungs = [Rung(1, args.spp // args.splits, row["split_means"])]
        verdict = judge(rungs, judged["mean"], judged["mean_variance"], args.z_max)
        if verdict.kind != "ok" and row["z"] < 0:      # a low mean: larger budgets tell bias from tail
            rungs, sums, lab_mean, samples, wall = render_ladder(scene, strategy, stack, rungs[0].spp,
                                                                 args.escalate)
            empty = empty_pixels(sums, judged["pixels"], lab_mean, judged["mean"], samples)
            verdict = judge(rungs, judged["mean"], judged["mean_variance"], args.z_max, empty)
            if len(rungs) > 1:
                verdict.evidence.append(f"the larger budgets took {wall:.1f} s (not in time_s)")
    elif judged["finite"] and not abs(row["z"]) <= args.z_max:
        problems.append(f"mean off by {row['z']:+.1f} sigma")
    row["note"], row["evidence"] = verdict.summary, verdict.evidence
    if twin is not None:
        row["z_twin"] = _z_against(row, twin.mean, twin.variance)
    if twin is not None and judged is not path_ref:       # path is off: judged against the twin
        z_path = _z_against(row, path_ref["mean"], path_ref["mean_variance"])
        status, row["note"] = twin_status(verdict, z_path, row["mean"] / twin.mean - 1, twin, args.z_max)
    else:
        status = {"ok": "ok", "heavy tail": "WARN: heavy tail"}.get(
            verdict.kind, f"FAIL: mean off by {row['z']:+.1f} sigma")
    row["status"] = "FAIL: " + ", ".join(problems) if problems else status


def check_scene(path, args, defines, out) -> tuple[list[dict], list[str]]:
    from .scene import SceneTraits, equivalent_strategies, strategy_applicability

    scene = load_check_scene(path, args.res, defines)
    traits = SceneTraits.from_scene(scene)
    name = os.path.basename(path)
    film = film_text(scene)
    print(f"  {name}: film {film} pixels (width x height), as rendered", file=out, flush=True)
    warnings = traits.warnings()
    rows, judged, path_ref, twin, more = references(path, name, args, defines, traits)
    warnings += more
    for warning in warnings:
        print(f"  warning: {name}: {warning}", file=out)
    depth = {"max_depth": args.max_depth}
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
        same = canonical[strategy]
        if same != strategy:
            rows.append({**measured[same], "strategy": strategy, "status": "same", "time_s": 0.0,
                         "note": f"the same estimator as {same} on this scene: not rendered "
                                 f"(its row's numbers)", "evidence": []})
            continue
        chosen = (kind, {**params, **depth})
        render_splits(scene, chosen, args.splits, 1, 0)               # warm-up: compile
        stack, rays, seconds = render_splits(scene, chosen, args.spp, args.splits, 0)
        row = {"scene": name, "strategy": strategy, **measure(stack, rays, seconds, judged, args.firefly_k)}
        judge_strategy(row, stack, scene, chosen, args, judged, path_ref, twin)
        measured[strategy] = row
        rows.append(row)
    for row in rows:
        row.setdefault("film", film)                 # the film as rendered, in the CSV and the HTML
    return rows, warnings


def film_text(scene) -> str:
    """The scene's film as rendered, "64x48" (width x height): what ``--res`` made of it."""
    size = scene.sensors()[0].film().size()
    return f"{size[0]}x{size[1]}"


def run(args, out) -> int:
    """The command: 0 = all good (warnings allowed), 1 = some strategy failed (LabError for bad input)."""
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
    if "twin" in defines:
        raise LabError("-D twin=... is not a scene parameter: a scene names its unscaled twin itself "
                       "with <default name=\"twin\" value=\"PATH\"/>")
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

    settings = (f"--res {resolution_text(args.res)} (each scene's film as rendered: its line and the film column), "
                f"{args.spp} spp per strategy, reference {args.ref_spp} spp, "
                f"{args.splits} splits, max_depth {args.max_depth}, |z| <= {args.z_max:g}, "
                f"escalate x{args.escalate}, firefly k = {args.firefly_k:g}")
    print(f"mitsuba-lab check: {len(scenes)} scene(s); {settings}", file=out)
    rows, warnings = [], {}
    start = time.perf_counter()
    for path in scenes:
        print(f"{os.path.basename(path)} ...", file=out, flush=True)
        scene_rows, scene_warnings = check_scene(path, args, defines, out)
        rows.extend(scene_rows)
        warnings[os.path.basename(path)] = scene_warnings
    print(format_table(rows), file=out)
    verdicts = format_verdicts(rows)
    if verdicts:
        print(verdicts, file=out)
    write_csv(args.output + ".csv", rows)
    write_html(args.output + ".html", rows, warnings, settings, __doc__)
    failures = [r for r in rows if verdict_kind(r) == "FAIL"]
    tails = [r for r in rows if verdict_kind(r) == "WARNING"]
    print(f"{len(failures)} failure(s), {len(tails)} heavy-tail warning(s) in {time.perf_counter() - start:.1f} s; "
          f"wrote {args.output}.csv and {args.output}.html", file=out)
    return 1 if failures else 0
