"""``mitsuba-lab check [SCENES...]``: every lab strategy on stiff scenes, against `path`
(``mitsuba_lab.check``: what is measured and how it is judged). Here: the options, the checks of
their values, and what is printed."""
from __future__ import annotations

import argparse
import glob
import os
import time

from ..errors import LabError
from .args import parse_assignments, positive_int, project_root, resolution_arg


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..check.verdicts import LADDER_SPLITS

    parser.description = (
        "Render every scene with every lab strategy that applies (lab_naive, lab_nee, lab_mis "
        "power and balance, lab_bdpt, lab_vcm modes bpt, vcm and ppm, lab_photon, lab_pssmlt, "
        "lab_mmlt) and Mitsuba's path as reference; print finite fraction, negative "
        "pixels, max value, fireflies, mean and its z-score against the reference, rays per "
        "pixel by kind; write CSV + HTML. Exit status 1 when any strategy gives NaN, Inf or "
        "negative values or a mean beyond --z-max standard errors of the reference, except a low "
        "mean with the marks of an unresolved heavy tail (a warning); the consistent ones (lab_vcm vcm "
        "and ppm, lab_photon) are judged by their bias^2 shrinking as the budget grows. A scene that declares an "
        "unscaled twin (<default name=\"twin\" .../>) is also compared with path on the twin.")
    parser.add_argument("scenes", nargs="*", metavar="SCENE",
                        help="Mitsuba XML scene files (default: every scenes/stiff/*.xml and scenes/stiff/media/*.xml)")
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


def default_scenes() -> list[str]:
    """Every scenes/stiff/*.xml of the checkout, then the media cases of scenes/stiff/media/."""
    stiff = os.path.join(project_root(), "scenes", "stiff")
    return sorted(glob.glob(os.path.join(stiff, "*.xml"))) + sorted(glob.glob(os.path.join(stiff, "media", "*.xml")))


def run(args, out) -> int:
    """The command: 0 = all good (warnings allowed), 1 = some strategy failed (LabError for bad input)."""
    from .. import check
    from ..check.report import format_table, format_verdicts, verdict_kind, write_csv, write_html

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

    settings = check.settings_text(args)
    print(f"mitsuba-lab check: {len(scenes)} scene(s); {settings}", file=out)
    rows, warnings = [], {}
    start = time.perf_counter()
    for path in scenes:
        print(f"{os.path.basename(path)} ...", file=out, flush=True)
        # (check.STRATEGIES read as the command runs: a caller may narrow it, as the tests do)
        scene_rows, scene_warnings = check.check_scene(path, args, defines, check.STRATEGIES,
                                                       lambda line: print(line, file=out, flush=True))
        rows.extend(scene_rows)
        warnings[os.path.basename(path)] = scene_warnings
    print(format_table(rows), file=out)
    verdicts = format_verdicts(rows)
    if verdicts:
        print(verdicts, file=out)
    write_csv(args.output + ".csv", rows)
    write_html(args.output + ".html", rows, warnings, settings, check.__doc__)
    failures = [r for r in rows if verdict_kind(r) == "FAIL"]
    tails = [r for r in rows if verdict_kind(r) == "WARNING"]
    print(f"{len(failures)} failure(s), {len(tails)} heavy-tail warning(s) in {time.perf_counter() - start:.1f} s; "
          f"wrote {args.output}.csv and {args.output}.html", file=out)
    return 1 if failures else 0
