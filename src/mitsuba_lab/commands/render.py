"""``mitsuba-lab render SCENE``: one scene, one integrator; EXR (settings in its header) + PNG.

Also the pieces ``demo`` shares: ``write_outputs``, ``format_stats``.
"""
from __future__ import annotations

import os
import sys

from .args import parse_assignments, positive_int, seed_int
from .plugins import lab_integrators, parameter_help

#: (option, integrator parameter): type, allowed values and default come from the declarations.
INTEGRATOR_OPTIONS = (
    ("--max-depth", "max_depth"),
    ("--rr-depth", "rr_depth"),
    ("--heuristic", "heuristic"),
    ("--beta", "beta"),
    ("--emitter-samples", "emitter_samples"),
)

#: Integrator used when neither the scene nor --integrator names one.
DEFAULT_INTEGRATOR = "lab_mis"
#: Sampler parameters every sampler has: kept when --sampler names another type.
SAMPLER_SHARED = ("sample_count", "seed")


def _option_type(name: str, plugins: tuple[str, ...]) -> type:
    from ..plugins.params import declared

    return next(p.kind for plugin in plugins for p in declared(plugin) if p.name == name)


def add_arguments(parser) -> None:
    integrators = lab_integrators()
    parser.description = ("Render SCENE and write an EXR (float32 RGB, settings and timings in its "
                          "header) and an sRGB PNG preview.")
    parser.add_argument("scene", help="Mitsuba XML scene file")
    parser.add_argument("--integrator",
                        help=f"integrator plugin: {', '.join(integrators)} or any of Mitsuba's (path, "
                             f"direct, ...) (default: the scene's <integrator> with its parameters, "
                             f"else {DEFAULT_INTEGRATOR}). Options below override the scene's "
                             f"parameters; with another type, the scene's parameters that it "
                             f"declares carry over")
    for option, name in INTEGRATOR_OPTIONS:
        parser.add_argument(option, dest=name, type=_option_type(name, integrators),
                            help=parameter_help(name, integrators))
    parser.add_argument("--hide-emitters", action="store_true",
                        help="directly visible emitters are black")
    parser.add_argument("--param", action="append", metavar="KEY=VALUE",
                        help="any other integrator parameter (repeatable)")
    parser.add_argument("--define", "-D", action="append", metavar="KEY=VALUE",
                        help="scene <default> value, e.g. -D res=64 (repeatable)")
    parser.add_argument("--sampler", help="sampler plugin (default: the scene's sampler with its "
                                          "parameters); sample_count and seed carry over to another type")
    parser.add_argument("--sampler-param", action="append", metavar="KEY=VALUE",
                        help="sampler parameter, e.g. --sampler-param randomization=owen (repeatable)")
    parser.add_argument("--spp", type=positive_int,
                        help="camera samples per pixel (default: the scene sampler's sample_count). "
                             "For lab_photon, N camera samples = N passes of one sample each, as in a "
                             "sweep (or passes = P given: N / P samples per pass)")
    parser.add_argument("--seed", type=seed_int, default=0, help="render seed, in [0, 2^32) (default: 0)")
    parser.add_argument("-o", "--output", help="output EXR path (default: out/SCENE_INTEGRATOR.exr)")
    parser.add_argument("--no-png", action="store_true", help="do not write the PNG preview")
    parser.add_argument("--allow-unsupported", action="store_true",
                        help="render with a lab integrator that cannot render the scene's light "
                             "correctly (participating media, delta lights for lab_naive), with a "
                             "warning; without it such a render is refused (exit 2)")


def integrator_params(args) -> dict:
    params = {}
    for _, name in INTEGRATOR_OPTIONS:
        value = getattr(args, name)
        if value is not None:
            params[name] = value
    if args.hide_emitters:
        params["hide_emitters"] = True
    params.update(parse_assignments(args.param, "--param"))
    return params


def default_output(scene: str, integrator: str) -> str:
    stem = os.path.splitext(os.path.basename(scene))[0]
    return os.path.join("out", f"{stem}_{integrator}.exr")


def _accepted_names(plugin_type: str):
    from ..plugins.params import declared

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
    parameters that do not apply."""
    from ..errors import LabError
    from ..scene_xml import plugin_spec

    if not os.path.isfile(args.scene):
        raise LabError(f"scene file not found: {args.scene}")

    integrator = chosen_plugin(plugin_spec(args.scene, "integrator", defines), args.integrator,
                               integrator_params(args), DEFAULT_INTEGRATOR)
    sampler_overrides = parse_assignments(args.sampler_param, "--sampler-param")
    sampler = chosen_plugin(plugin_spec(args.scene, "sampler", defines), args.sampler,
                            sampler_overrides, "independent", SAMPLER_SHARED)
    return integrator, sampler


def run(args, out) -> int:
    from .. import images, scene as scenes
    from ..errors import LabError
    from ..experiment.pipeline.config import PluginSpec, sample_count_plugin
    from ..plugins.params import resolve
    from ..render import render
    from ..runtime import versions
    from ..scene_xml import load_scene_variant

    defines = parse_assignments(args.define, "--define")
    (kind, params, dropped), (sampler_type, sampler_params, _) = render_plan(args, defines)
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
    # lab_photon: N camera samples = passes x spp per pass, as in a sweep
    spec, spp = sample_count_plugin(PluginSpec(kind, kind, params), samples)
    params = spec.params
    integrator = scenes.make_integrator(kind, params)
    notes, unsupported = render_warnings(scene, kind, params)
    if unsupported and unsupported == cannot_run(scene, kind):
        raise LabError(unsupported)                       # no light left out: nothing to render
    if unsupported and not args.allow_unsupported:
        raise LabError(f"{unsupported} (--allow-unsupported renders it anyway)")
    if unsupported:
        notes.append(f"{unsupported} (rendering it anyway: --allow-unsupported)")
        integrator.unsupported_acknowledged = True       # said here: the plugin need not log it
    for note in notes:
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
    if stats.integrator:                                  # the plugin's own statistics (render.integrator_stats)
        label = "photons" if hasattr(integrator, "photon_stats") else "statistics"
        print(f"{label}: {describe_stats(stats.integrator)}", file=out)
    print(f"wrote {output}" + ("" if args.no_png else f" and {png_path(output)}"), file=out)
    return 0


def render_warnings(scene, kind: str, params: dict) -> tuple[list[str], str]:
    """(warnings, reason): what the user should know before trusting this render (the scene's
    own problems), and the reason a lab integrator cannot render the scene's light correctly
    ('' when it can; the planner's answer, ``strategy_applicability``). Mitsuba's own integrators
    are not refused here: what they ignore (media for `path`) is among the scene's warnings."""
    from ..features import ignored_features
    from ..plugins.integrators.estimator import lookup
    from ..scene import SceneTraits, strategy_applicability

    traits = SceneTraits.from_scene(scene)
    ok, reason = strategy_applicability(traits, kind, params) if lookup(kind) is not None else (True, "")
    ignored = ignored_features(traits, kind, params)
    # the note on media is for an integrator that ignores them (an unsupported lab one says so itself)
    notes = traits.warnings(media=ok and (ignored is None or "media" in ignored))
    return notes, "" if ok else reason


def cannot_run(scene, kind: str) -> str:
    """Why a lab integrator cannot render the scene at all, even with light left out ('')."""
    from ..plugins.integrators.estimator import lookup
    from ..scene import SceneTraits

    estimator = lookup(kind)
    return estimator.unsupported(SceneTraits.from_scene(scene)) if estimator is not None else ""


def describe_stats(stats: dict) -> str:
    """An integrator's statistics of its last render on one line (``photon_stats()``,
    ``bdpt_stats()``): floats to 4 digits, a table of them as (key: value, ...)."""
    def value(v) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        if isinstance(v, dict):
            return "(" + ", ".join(f"{k}: {value(x)}" for k, x in v.items()) + ")"
        return f"{v}"

    return ", ".join(f"{k} {value(v)}" for k, v in stats.items())


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
    from .. import images

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
