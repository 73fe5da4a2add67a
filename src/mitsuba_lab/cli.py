"""``mitsuba-lab``: the command line. The CLI owns the terminal; library code never prints.

Every user error (bad scene, unknown plugin, bad value, unwritable output)
ends in one line on stderr (one per problem when a config has several) and exit
status 2; ``--debug`` shows the traceback. Ctrl-C ends with "interrupted" and
status 130, a closed output pipe quietly with status 141.
"""
from __future__ import annotations

import argparse
import os
import sys
import traceback

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130        # 128 + SIGINT, as shells report Ctrl-C
EXIT_PIPE = 141               # 128 + SIGPIPE, as for any command whose reader closed the pipe

INTEGRATOR_OPTIONS = (
    # (option, parameter, type, help)
    ("--max-depth", "max_depth", int, "longest path in segments; -1 = unbounded, 1 = emitters seen "
                                      "directly, 2 = direct lighting (plugin default: -1)"),
    ("--rr-depth", "rr_depth", int, "depth at which Russian roulette starts (plugin default: 5)"),
    ("--heuristic", "heuristic", str, "lab_mis only: balance | power | max | average "
                                      "(default: power)"),
    ("--beta", "beta", float, "lab_mis only: power-heuristic exponent > 0 (default: 2)"),
    ("--emitter-samples", "emitter_samples", int, "lab_mis only: shadow rays per vertex >= 1 "
                                                  "(default: 1)"),
)


def parse_value(text: str):
    """'8' -> 8, '0.5' -> 0.5, 'true' -> True, anything else stays a string."""
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_assignments(items: list[str] | None, option: str) -> dict:
    params = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"{option} expects KEY=VALUE, got '{item}'")
        params[key.strip()] = parse_value(value.strip())
    return params


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got '{text}'") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def seed_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, 2^32), got '{text}'") from None
    if not 0 <= value < 2 ** 32:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, 2^32), got {text}")
    return value


def integrator_params(args) -> dict:
    params = {}
    for _, name, _, _ in INTEGRATOR_OPTIONS:
        value = getattr(args, name)
        if value is not None:
            params[name] = value
    if args.hide_emitters:
        params["hide_emitters"] = True
    params.update(parse_assignments(args.param, "--param"))
    return params


class OneLineParser(argparse.ArgumentParser):
    """Usage errors as one line (plus where to look), exit status 2."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="mitsuba-lab",
        description="A Monte Carlo light-transport laboratory on Mitsuba 3 and Dr.Jit.")
    parser.add_argument("--variant", help="Mitsuba variant (default: $MITSUBA_LAB_VARIANT or "
                                          "llvm_ad_rgb), e.g. cuda_ad_rgb on an NVIDIA GPU")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    render = sub.add_parser("render", help="render one scene with one integrator",
                            description="Render SCENE and write an EXR (float32 RGB, settings and "
                                        "timings in its header) and an sRGB PNG preview.")
    render.add_argument("scene", help="Mitsuba XML scene file")
    render.add_argument("--integrator",
                        help="integrator plugin: lab_naive, lab_nee, lab_mis, lab_photon or any of "
                             "Mitsuba's (path, direct, ...) (default: the scene's <integrator> with "
                             "its parameters, else lab_mis). Options below override the scene's "
                             "parameters; with another type, the scene's parameters that it "
                             "declares carry over")
    for option, name, kind, help_text in INTEGRATOR_OPTIONS:
        render.add_argument(option, dest=name, type=kind, help=help_text)
    render.add_argument("--hide-emitters", action="store_true",
                        help="directly visible emitters are black")
    render.add_argument("--param", action="append", metavar="KEY=VALUE",
                        help="any other integrator parameter (repeatable)")
    render.add_argument("--define", "-D", action="append", metavar="KEY=VALUE",
                        help="scene <default> value, e.g. -D res=64 (repeatable)")
    render.add_argument("--sampler", help="sampler plugin (default: the scene's sampler with its "
                                          "parameters); sample_count and seed carry over to another type")
    render.add_argument("--sampler-param", action="append", metavar="KEY=VALUE",
                        help="sampler parameter, e.g. --sampler-param randomization=owen (repeatable)")
    render.add_argument("--spp", type=positive_int,
                        help="camera samples per pixel (default: the scene sampler's sample_count). "
                             "For lab_photon, N camera samples = N passes of one sample each, as in a "
                             "sweep (or passes = P given: N / P samples per pass)")
    render.add_argument("--seed", type=seed_int, default=0, help="render seed, in [0, 2^32) (default: 0)")
    render.add_argument("-o", "--output", help="output EXR path (default: out/SCENE_INTEGRATOR.exr)")
    render.add_argument("--no-png", action="store_true", help="do not write the PNG preview")

    demo = sub.add_parser("demo", help="render the Cornell box with every lab integrator",
                          description="Render scenes/cornell_box.xml with lab_naive, lab_nee and "
                                      "lab_mis (power and balance) and write EXR + PNG files.")
    demo.add_argument("-o", "--output", default="out/demo", help="output folder (default: out/demo)")
    demo.add_argument("--spp", type=positive_int, default=64, help="samples per pixel (default: 64)")
    demo.add_argument("--res", type=positive_int, default=128, help="image width and height "
                                                                    "(default: 128)")
    demo.add_argument("--max-depth", type=int, default=8, help="max_depth of every integrator "
                                                              "(default: 8)")
    sweep = sub.add_parser("sweep", help="run a strategy sweep and write its report",
                           description="Run every point of an experiment config (scenes x strategies x "
                                       "samplers x spp / time budgets, R seeds each) against cached "
                                       "references, store one row per render, and write the report. "
                                       "A killed sweep resumes where it stopped. Config schema: "
                                       "experiments/README.md.")
    sweep.add_argument("config", help="experiment TOML file")
    sweep.add_argument("-o", "--output", help="output folder (default: the config's experiment.output)")
    sweep.add_argument("--cluster", metavar="ADDRESS",
                       help="run the points on a Dask distributed cluster, e.g. tcp://host:8786 "
                            "(needs the 'distributed' extra; overrides the config's [executor] cluster)")
    sweep.add_argument("--dry-run", action="store_true",
                       help="print the plan, left-out strategies and an estimated cost (from a short "
                            "pilot render per scene), and render nothing else")

    reference = sub.add_parser("reference", help="build (or find) one cached high-spp reference",
                               description="Render SCENE's reference in independent chunks, cache it "
                                           "(content-addressed) and print its key and noise floor.")
    reference.add_argument("scene", help="Mitsuba XML scene file")
    reference.add_argument("--integrator", default="path", help="reference integrator (default: path)")
    reference.add_argument("--max-depth", type=int, help="max_depth of the integrator")
    reference.add_argument("--param", action="append", metavar="KEY=VALUE",
                           help="other integrator parameter (repeatable)")
    reference.add_argument("--spp", type=positive_int, default=4096, help="total samples per pixel "
                                                                           "(default: 4096)")
    reference.add_argument("--chunks", type=positive_int, default=8,
                           help="independent chunks (>= 2, dividing --spp) for the noise floor (default: 8)")
    reference.add_argument("--res", type=positive_int, help="square film resolution override")
    reference.add_argument("--define", "-D", action="append", metavar="KEY=VALUE",
                           help="scene <default> value (repeatable)")
    reference.add_argument("--cache", help="cache folder (default: $MITSUBA_LAB_CACHE or "
                                           "~/.cache/mitsuba_lab/references)")
    reference.add_argument("-o", "--output", help="also write the reference image here (.exr, + .png)")

    report = sub.add_parser("report", help="rebuild a sweep's report from its stored results",
                            description="Rebuild OUTDIR/results.csv and OUTDIR/report/ from "
                                        "OUTDIR/results.jsonl and the stored images; renders nothing.")
    report.add_argument("folder", help="a sweep's output folder")

    from . import check

    check.add_arguments(sub.add_parser(
        "check", help="render the stiff scenes with every applicable lab strategy against path",
        description="Render every scene (default: scenes/stiff/*.xml) with every lab strategy that "
                    "applies and with Mitsuba's path as the reference; report NaN/Inf/negative "
                    "pixels, fireflies and z-scores of the means; write CSV + HTML. Exit status 1 "
                    "when a strategy produces NaN, Inf or negative values or a mean off the "
                    "reference where it claims to be unbiased."))

    from . import inverse

    inverse.add_arguments(sub.add_parser(
        "invert", help="prb inverse-rendering demos and gradient variance against time",
        description="Run an inverse-rendering config (experiments/inverse_*.toml): optimise the chosen "
                    "scene parameters with Mitsuba's prb and Adam from a target rendered with known "
                    "values, and measure the gradient's variance against time per sampler and spp. "
                    "Writes CSV files, plots, images and a report to OUTDIR."))

    theory = sub.add_parser("theory", help="reproduce the seed text's Problems 1-5",
                            description="Run the seed text's toy estimators (uniform MC, importance "
                                        "sampling, cosine sampling, MIS weights and MIS, Russian "
                                        "roulette) and print predicted against measured values. "
                                        "Exit status 1 when a measurement misses its stated "
                                        "tolerance.")
    theory.add_argument("--json", action="store_true",
                        help='print a JSON list of {"problem", "quantity", "predicted", "measured", '
                             '"tolerance", "note"} rows instead of a table')
    theory.add_argument("--quick", action="store_true", help="about 10x fewer trials (seconds)")
    theory.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    return parser


def cmd_theory(args, out) -> int:
    import json

    from . import theory

    rows = theory.run_all(seed=args.seed, quick=args.quick)
    print(json.dumps(rows, indent=1) if args.json else theory.format_table(rows), file=out)
    return 1 if theory.check(rows) else 0


def cmd_sweep(args, out) -> int:
    from .experiment import sweep

    return sweep.sweep_command(args.config, args.output, args.dry_run, out, args.cluster)


def cmd_reference(args, out) -> int:
    from .experiment import sweep

    params = parse_assignments(args.param, "--param")
    if args.max_depth is not None:
        params["max_depth"] = args.max_depth
    return sweep.reference_command(args.scene, args.integrator, params, args.spp, args.chunks, args.res,
                                   parse_assignments(args.define, "--define"), args.cache, args.output, out)


def cmd_report(args, out) -> int:
    from .experiment.report import build_report

    paths = build_report(args.folder)
    print(f"wrote {paths['html']}, {paths['md']} and {paths['csv']}", file=out)
    return 0


def default_output(scene: str, integrator: str) -> str:
    stem = os.path.splitext(os.path.basename(scene))[0]
    return os.path.join("out", f"{stem}_{integrator}.exr")


#: Integrator used when neither the scene nor --integrator names one.
DEFAULT_INTEGRATOR = "lab_mis"
#: Sampler parameters every sampler has: kept when --sampler names another type.
SAMPLER_SHARED = ("sample_count", "seed")


def _accepted_names(plugin_type: str):
    from .plugins.params import declared

    params = declared(plugin_type)
    return None if params is None else {p.name for p in params}


def chosen_plugin(scene_spec, cli_type: str | None, overrides: dict, fallback: str,
                  shared=()) -> tuple[str, dict, list[str]]:
    """(type, parameters, dropped scene parameters): the scene's plugin and parameters are the
    defaults and the command line overrides them. When the command line names another type,
    the scene's parameters that the new plugin declares (or ``shared`` ones) carry over."""
    scene_type, scene_params = scene_spec or (fallback, {})
    kind = cli_type or scene_type
    if kind == scene_type:
        carried = dict(scene_params)
    else:
        accepted = _accepted_names(kind) or set(shared)
        carried = {k: v for k, v in scene_params.items() if k in accepted}
    dropped = sorted(set(scene_params) - set(carried))
    return kind, {**carried, **overrides}, dropped


def render_plan(args, defines: dict):
    """What ``render`` will run: integrator and sampler (type, parameters), the scene's
    parameters that do not apply, and the camera samples per pixel in all."""
    from .errors import LabError
    from .experiment.config import PASS_PARAMETER
    from .scene_xml import plugin_spec

    if not os.path.isfile(args.scene):
        raise LabError(f"scene file not found: {args.scene}")

    integrator = chosen_plugin(plugin_spec(args.scene, "integrator", defines), args.integrator,
                               integrator_params(args), DEFAULT_INTEGRATOR)
    sampler_overrides = parse_assignments(args.sampler_param, "--sampler-param")
    sampler = chosen_plugin(plugin_spec(args.scene, "sampler", defines), args.sampler,
                            sampler_overrides, "independent", SAMPLER_SHARED)
    return integrator, sampler, PASS_PARAMETER.get(integrator[0])


def cmd_render(args, out) -> int:
    from . import images, scene as scenes
    from .plugins.params import resolve
    from .render import render
    from .errors import LabError
    from .runtime import versions
    from .scene_xml import load_scene_variant

    defines = parse_assignments(args.define, "--define")
    (kind, params, dropped), (sampler_type, sampler_params, _), pass_name = render_plan(args, defines)
    output = args.output or default_output(args.scene, kind)
    if not output.lower().endswith(".exr"):
        raise ValueError(f"output must be an .exr path, got '{output}'")
    images.ensure_parent(output)
    if args.sampler or args.sampler_param:
        scenes.make_sampler(sampler_type, sampler_params)          # its own errors, named
        scene = load_scene_variant(args.scene, None, {"type": sampler_type, **sampler_params}, defines)
    else:
        scene = scenes.load_scene(args.scene, **defines)
    samples = args.spp or scene.sensors()[0].sampler().sample_count()    # per pixel, in all
    spp = samples
    if pass_name:                # pass-scaled (lab_photon): N camera samples = passes x spp per pass
        passes = params.setdefault(pass_name, samples)
        if samples % passes:
            raise LabError(f"{kind}: {samples} camera samples per pixel (--spp or the scene's "
                           f"sample_count) is not a multiple of {pass_name} = {passes}")
        spp = samples // passes
    integrator = scenes.make_integrator(kind, params)
    for note in render_warnings(scene, kind, params):
        print(f"mitsuba-lab: warning: {note}", file=sys.stderr)
    if dropped:
        print(f"mitsuba-lab: note: the scene's integrator parameters {', '.join(dropped)} do not "
              f"apply to {kind} and are not used", file=sys.stderr)
    image, stats = render(scene, integrator, spp=spp, seed=args.seed)
    stats.spp = samples
    settings = {"integrator": {"type": kind, "params": resolve(kind, params)},
                "sampler": {"type": sampler_type,
                            "params": {**resolve(sampler_type, sampler_params), "sample_count": spp}}}
    write_outputs(output, image, stats, settings, args.scene, versions(), png=not args.no_png)
    print(format_stats(kind, stats), file=out)
    print(f"settings: {describe_settings(settings)}", file=out)
    if hasattr(integrator, "photon_stats"):
        print("photons: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                      for k, v in integrator.photon_stats().items()), file=out)
    print(f"wrote {output}" + ("" if args.no_png else f" and {png_path(output)}"), file=out)
    return 0


def render_warnings(scene, kind: str, params: dict) -> list[str]:
    """What the user should know before trusting this render: the scene's own problems and
    the planner's reason when the estimator cannot render the scene's light correctly."""
    from .scene import SceneTraits, strategy_applicability

    traits = SceneTraits.from_scene(scene)
    notes = traits.warnings()
    ok, reason = strategy_applicability(traits, kind, params)
    if not ok and reason not in notes:
        notes.append(reason)
    return notes


def describe_settings(settings: dict) -> str:
    parts = []
    for role in ("integrator", "sampler"):
        plugin = settings[role]
        values = ", ".join(f"{k}={v}" for k, v in sorted(plugin["params"].items()))
        parts.append(f"{role} {plugin['type']} ({values})")
    return "; ".join(parts)


def png_path(exr_path: str) -> str:
    return os.path.splitext(exr_path)[0] + ".png"


def write_outputs(output, image, stats, settings: dict, scene_path, version_info, png=True):
    """EXR with the settings as used (``{"integrator": {type, params}, "sampler": {...}}``),
    the stats and the versions in its header, and the PNG preview."""
    from . import images

    metadata = {"mitsuba_lab.scene": scene_path,
                "mitsuba_lab.integrator": settings["integrator"]["type"],
                "mitsuba_lab.params": settings["integrator"]["params"],
                "mitsuba_lab.stats": stats.as_dict(),
                **{f"mitsuba_lab.{k}": v for k, v in version_info.items()}}
    if "sampler" in settings:
        metadata["mitsuba_lab.sampler"] = settings["sampler"]
    images.write_exr(output, image, metadata)
    if png:
        images.write_png(png_path(output), image)


def format_stats(label: str, stats) -> str:
    rays = ", ".join(f"{kind} {count:,}" for kind, count in stats.rays.items()) or "not counted"
    return (f"{label}: {stats.width}x{stats.height} @ {stats.spp} spp, seed {stats.seed}: "
            f"wall {stats.wall_s:.3f} s (compile {stats.compile_s:.3f} s, kernels "
            f"{stats.kernel_s:.3f} s), {stats.samples_per_second / 1e6:.2f} M samples/s; rays: {rays}")


DEMO_STRATEGIES = (
    ("lab_naive", {}),
    ("lab_nee", {}),
    ("lab_mis", {"heuristic": "balance"}),
    ("lab_mis", {"heuristic": "power"}),
)


def cmd_demo(args, out) -> int:
    from . import images, scene as scenes
    from .plugins.params import resolve
    from .render import render
    from .runtime import versions

    os.makedirs(args.output, exist_ok=True)
    images.check_writable(os.path.join(args.output, "x.exr"))
    scene_path = os.path.join(project_root(), "scenes", "cornell_box.xml")
    scene = scenes.load_scene(scene_path, res=args.res)
    info = versions()
    print(f"Cornell box {args.res}x{args.res}, {args.spp} spp, max_depth {args.max_depth}, "
          f"variant {info['variant']}", file=out)
    for name, extra in DEMO_STRATEGIES:
        params = {"max_depth": args.max_depth, **extra}
        integrator = scenes.make_integrator(name, params)
        render(scene, integrator, spp=args.spp, seed=0)        # warm-up: compiles the kernel
        image, stats = render(scene, integrator, spp=args.spp, seed=1)
        label = name + "".join(f"_{v}" for v in extra.values())
        output = os.path.join(args.output, f"cornell_box_{label}.exr")
        settings = {"integrator": {"type": name, "params": resolve(name, params)}}
        write_outputs(output, image, stats, settings, scene_path, info)
        print(f"  {format_stats(label, stats)}", file=out)
    print(f"wrote EXR + PNG files to {args.output}", file=out)
    return 0


def project_root() -> str:
    """The source checkout holding scenes/ (the package is installed editable from it)."""
    here = os.path.dirname(os.path.abspath(__file__))
    return os.path.dirname(os.path.dirname(here))


def cmd_invert(args, out) -> int:
    from . import inverse

    return inverse.run(args, out)


def cmd_check(args, out) -> int:
    from . import check

    return check.run(args, out)


COMMANDS = {"render": cmd_render, "demo": cmd_demo, "sweep": cmd_sweep, "reference": cmd_reference,
            "report": cmd_report, "check": cmd_check, "invert": cmd_invert, "theory": cmd_theory}


def main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        from . import activate

        if args.command not in ("theory", "report"):      # these never render
            activate(args.variant)
        return COMMANDS[args.command](args, out)
    except KeyboardInterrupt:
        return interrupted()
    except BrokenPipeError:
        return closed_pipe()
    except Exception as err:  # noqa: BLE001 - every failure becomes one line (see module doc)
        from .errors import is_interrupt, one_line

        if is_interrupt(err):                 # Ctrl-C inside a Dr.Jit loop arrives wrapped
            return interrupted()
        if args.debug:
            traceback.print_exc()
        for line in getattr(err, "problems", None) or [one_line(err)]:
            print(f"mitsuba-lab: error: {line}", file=sys.stderr)
        return EXIT_USAGE


def interrupted() -> int:
    print("mitsuba-lab: interrupted", file=sys.stderr)
    return EXIT_INTERRUPTED


def closed_pipe() -> int:
    """The reader of our output went away (``| head``): stop quietly. Python would report the
    failed flush of stdout at exit, so stdout is pointed at /dev/null first."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):     # a stdout without a file descriptor
        pass
    return EXIT_PIPE


if __name__ == "__main__":
    sys.exit(main())
