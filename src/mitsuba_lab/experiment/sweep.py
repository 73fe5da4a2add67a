"""A sweep wired end to end: config, plan, references, points, strategy grid, report.

``prepare_sweep`` and ``run_sweep`` are the pipeline itself, shared by ``mitsuba-lab sweep``
(``commands.sweep``, which prints) and ``mitsuba_lab.sweep`` (``experiment.api``); progress goes
to the ProgressBar they are given. ``estimate_cost`` is ``--dry-run``'s estimate,
``build_reference`` the reference of ``mitsuba-lab reference``."""
from __future__ import annotations

import os

from ..errors import LabError
from ..progress import duration
from .execution.strategy_grid import check_grid, estimated_grid_seconds, render_strategy_grid
from .pipeline.budget import tolerance_text
from .pipeline.config import Config, PluginSpec, load_config, with_depth
from .pipeline.plan import Plan, build_plan, estimated_seconds, nothing_to_run
from .pipeline.reference import get_reference, load_cached, reference_key
from .pipeline.reference_choice import choose_references
from .pipeline.store import ResultStore
from .pipeline.validate import validate


def scene_traits(scene_spec):
    """The ``SceneTraits`` of a config's scene, loaded at its resolution with its defaults."""
    from ..scene import SceneTraits
    from ..scene_xml import load_scene_variant

    return SceneTraits.from_scene(load_scene_variant(scene_spec.path, scene_spec.resolution, None,
                                                     scene_spec.defaults))


def assess_scene(scene_spec, strategies, traits=None, allowed=()):
    """Left-out strategies, aliases and the strategies that run though they cannot render the
    scene correctly (those named in ``allowed``, ``experiment.allow_unsupported``: {name: (mark,
    reason)}) for one scene, from its traits (mitsuba_lab.scene; loaded when not given)."""
    from ..features import ignored_features, ignores_text
    from ..plugins.integrators.estimator import lookup
    from ..scene import equivalence_reason, equivalent_strategies, strategy_applicability

    traits = traits if traits is not None else scene_traits(scene_spec)
    left_out, unsupported = {}, {}
    for s in strategies:
        ok, reason = strategy_applicability(traits, s.type, s.params)
        if ok:
            continue
        estimator = lookup(s.type)
        renders_at_all = estimator is None or not estimator.unsupported(traits)     # (as render's refusal)
        if s.name in allowed and renders_at_all:
            unsupported[s.name] = (ignores_text(ignored_features(traits, s.type, s.params)), reason)
        else:
            left_out[s.name] = reason
    usable = {s.name: (s.type, s.params) for s in strategies if s.name not in left_out}
    aliases = {}
    for name, canonical in equivalent_strategies(traits, usable).items():
        if canonical != name:
            aliases[name] = (canonical, equivalence_reason(traits, *usable[name]))
    return left_out, aliases, unsupported


def pilot_rates(config) -> tuple[dict, dict]:
    """Samples per second and pixels per scene, from a 2-spp render with the reference integrator
    after an untimed warm-up (the basis of --dry-run's time estimate)."""
    from ..render import render
    from ..scene import make_integrator
    from ..scene_xml import load_scene_variant

    rates, pixels = {}, {}
    for scene in config.scenes:
        scene_obj = load_scene_variant(scene.path, scene.resolution, None, scene.defaults)
        spec = with_depth(config.reference_for(scene).integrator, config.max_depth)
        integrator = make_integrator(spec.type, spec.params)
        render(scene_obj, integrator, spp=2, seed=0)
        image, stats = render(scene_obj, integrator, spp=2, seed=1)
        rates[scene.name] = stats.samples_per_second
        pixels[scene.name] = image.shape[0] * image.shape[1]
    return rates, pixels


def prepare_sweep(source) -> tuple[Config, Plan]:
    """(config, plan) from a TOML path or a dict (``load_config``): every problem with the config,
    its plugins and its scenes is raised here, as a LabError, before anything renders."""
    config = load_config(source)
    validate(config)                  # every plugin and scene x sampler, before anything renders
    traits = {scene.name: scene_traits(scene) for scene in config.scenes}
    config = choose_references(config, traits)      # each scene's reference renders all of it
    plan = build_plan(config, lambda scene, strategies: assess_scene(scene, strategies, traits[scene.name],
                                                                     config.allow_unsupported))
    check_grid(config, plan)
    return config, plan


def require_points(config, plan) -> None:
    """LabError (exit 2) saying why when the plan has nothing to run: then nothing renders,
    not even a reference."""
    reason = nothing_to_run(config, plan)
    if reason:
        raise LabError(reason)


def estimate_cost(config, plan) -> dict:
    """``--dry-run``'s estimate, from a short pilot render per scene (a plan with nothing to run is
    refused first, ``require_points``): {"seconds": {scene: s}, "grid_seconds": s or None,
    "rates": {scene: samples per second of the pilot}, "cached": scenes whose reference is cached}."""
    require_points(config, plan)
    rates, pixels = pilot_rates(config)
    cached = set()
    for scene in config.scenes:
        ref = config.reference_for(scene)
        key = reference_key(scene.path, scene.resolution, scene.defaults, with_depth(ref.integrator, config.max_depth),
                            ref.spp, ref.chunks)
        if load_cached(ref.cache, key):
            cached.add(scene.name)
    grid = config.strategy_grid
    return {"seconds": estimated_seconds(plan, config, rates, pixels, cached), "rates": rates, "cached": cached,
            "grid_seconds": estimated_grid_seconds(config, rates[grid.scene], pixels[grid.scene]) if grid else None}


def progress_printer(bar):
    """The runner's ``progress(event, **info)`` callback, shown on ``bar`` (a ProgressBar)."""
    def progress(event, **info):
        if event == "reference":
            bar.message(f"reference for {info['scene']} ...")
        elif event == "reference_done":
            origin = "from the cache" if info["cached"] else "rendered"
            bar.message(f"reference for {info['scene']} {origin}; noise floor MSE {info['floor']:.3g}")
        elif event == "stale":
            runs = f"{info['count']} stored run{'s' if info['count'] != 1 else ''}"
            if info["planned"]:
                bar.message(f"{runs} no longer match: {info['changes']}; rerunning them")
            else:
                bar.message(f"{runs} left out of the report: {info['changes']}")
        elif event == "start":
            bar.begin(info["total"], f"{info['total']} points to run ({info['skipped']} already done)",
                      unit="point")
        elif event == "point_done":
            bar.step(info["point"])
        elif event in ("budget_retry", "budget_missed"):
            bar.message(budget_message(event, info))
        elif event == "grid_cell":
            bar.message(f"strategy grid: ({info['cell']}), {info['done']}/{info['total']}")

    return progress


def budget_message(event: str, info: dict) -> str:
    """The log line of a budget point rendered again (``budget_retry``) or still off its budget
    after its retries (``budget_missed``): ``SweepRunner.report_budget_tries``."""
    off = (f"{info['point']}: median render time {info['measured']:.3f} s at {info['spp']} spp is outside "
           f"{tolerance_text()} of its {info['budget']:g} s budget")
    if event == "budget_retry":
        return (f"{off}; recalibrated to {info['new_spp']} spp, rendering its seeds again "
                f"(retry {info['retry']} of {info['retries']})")
    tried = f"after {info['retries']} retr{'y' if info['retries'] == 1 else 'ies'}" if info["retries"] else "(no retry)"
    return f"{off} {tried}; the report marks it as off budget"


def run_sweep(config, plan, folder: str, bar, cluster: str | None = None, in_process: bool = True) -> dict[str, str]:
    """Run a prepared sweep into ``folder`` (resuming what it holds): references, points (on
    ``cluster``, else in this process or, ``in_process`` False, in a worker process of the
    sweep's own: ``executors``), the strategy grid, then the report. Returns the report's
    paths (csv, html, md)."""
    require_points(config, plan)
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise LabError(f"output path is not a folder: {folder}")
    from .report.build import build_report
    from .pipeline.run import SweepRunner

    store = ResultStore(folder)
    progress = progress_printer(bar)
    executor = None
    address = cluster or config.cluster
    if address:
        from .execution.executors import DaskExecutor

        executor = DaskExecutor(address)
        bar.message(f"running points on the Dask cluster at {address}")
    elif not in_process:
        from .execution.executors import ProcessExecutor

        executor = ProcessExecutor()
    try:
        SweepRunner(config, plan, store, progress, executor).run()
        render_strategy_grid(config, store, progress)      # here: its renders are few, and cheap
    finally:
        bar.close()                                        # an interrupted sweep leaves no live bar
    return build_report(folder)


def done_line(config, seconds: float, paths: dict[str, str]) -> str:
    return (f"sweep '{config.name}' done in {duration(seconds)}; results in {paths['csv']}; "
            f"report: {paths['html']} (and {paths['md']})")


def build_reference(scene_path, integrator, params, spp, chunks, resolution, defaults, cache, output, bar):
    """``mitsuba-lab reference``'s reference: (Reference, was cached, the cache folder, the
    integrator). ``integrator`` None: the default for the scene's features
    (``features.default_reference``); a named one that ignores a feature of the scene is refused.
    ``bar`` (a ProgressBar) shows the chunks."""
    from .. import images
    from ..features import default_reference
    from ..scene import SceneTraits
    from ..scene_xml import load_scene_variant
    from .pipeline.config import DEFAULT_CACHE
    from .pipeline.reference_choice import reference_problem

    if spp % chunks or chunks < 2:
        raise LabError(f"--chunks must be >= 2 and divide --spp ({spp}), got {chunks}")
    if not os.path.isfile(scene_path):
        raise LabError(f"scene file not found: {scene_path}")
    if output:
        images.check_writable(output)
    traits = SceneTraits.from_scene(load_scene_variant(scene_path, resolution, None, defaults))
    if integrator is None:
        integrator = default_reference(traits)
    reason = reference_problem(traits, PluginSpec("reference", integrator, params))
    if reason:
        raise LabError(f"scene {scene_path}: the reference must render every feature of the scene, but {reason}")
    cache = os.path.abspath(os.path.expanduser(cache or os.environ.get("MITSUBA_LAB_CACHE") or DEFAULT_CACHE))
    bar.begin(chunks, unit="chunk")
    try:
        ref, cached = get_reference(os.path.abspath(scene_path), resolution, defaults,
                                    PluginSpec("reference", integrator, params), spp, chunks, cache,
                                    progress=lambda k, n: bar.step())
    finally:
        bar.close()                                        # (Ctrl-C: no live bar left mid-line)
    return ref, cached, cache, integrator


def write_reference_image(output: str, ref) -> None:
    """The reference's image as ``output`` (EXR, tagged with its key) and a PNG beside it."""
    from .. import images

    images.write_exr(output, ref.image, {"mitsuba_lab.reference": ref.key})
    images.write_png(os.path.splitext(output)[0] + ".png", ref.image)
