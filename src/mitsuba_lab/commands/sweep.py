"""``mitsuba-lab sweep CONFIG``: a strategy sweep against cached references, and its report."""
from __future__ import annotations

import itertools
import time


def add_arguments(parser) -> None:
    parser.description = ("Run every point of an experiment config (scenes x strategies x samplers x "
                          "spp / time budgets, R seeds each) against cached references, store one row "
                          "per render, and write the report. A killed sweep resumes where it stopped. "
                          "Config schema: experiments/README.md.")
    parser.add_argument("config", help="experiment TOML file")
    parser.add_argument("-o", "--output", help="output folder (default: the config's experiment.output)")
    parser.add_argument("--cluster", metavar="ADDRESS",
                        help="run the points on a Dask distributed cluster, e.g. tcp://host:8786 "
                             "(needs the 'distributed' extra; overrides the config's [executor] cluster)")
    parser.add_argument("--dry-run", action="store_true",
                        help="print the plan, left-out strategies and why, and an estimated cost (from a "
                             "short pilot render per scene), and render nothing else; exit status 2 when "
                             "nothing would run")


def run(args, out) -> int:
    return sweep_command(args.config, args.output, args.dry_run, out, args.cluster)


def sweep_command(config_path: str, output: str | None, dry_run: bool, out, cluster: str | None = None) -> int:
    """The command on its values: the plan and its cost (``dry_run``), or the sweep, run."""
    from ..experiment import sweep
    from ..progress import ProgressBar

    config, plan = sweep.prepare_sweep(config_path)
    if dry_run:
        print_dry_run(config, plan, out)
        return 0
    start = time.perf_counter()
    paths = sweep.run_sweep(config, plan, output or config.output, ProgressBar(), cluster)
    print(sweep.done_line(config, time.perf_counter() - start, paths), file=out)
    return 0


def print_plan(config, plan, out) -> None:
    """The plan as ``--dry-run`` prints it: every point, and what is left out, aliased, marked or
    rendered separately, and why."""
    from ..experiment.pipeline.config import PASS_PARAMETER

    print(f"sweep '{config.name}' from {config.source}: {len(config.scenes)} scene(s), "
          f"{len(config.strategies)} strateg(ies), {len(config.samplers)} sampler(s), "
          f"levels {list(config.spp)} spp + {list(config.time_budgets)} s, {config.repetitions} seeds",
          file=out)
    strategies = {s.name: s for s in config.strategies}
    for scene in config.scenes:
        points = plan.for_scene(scene.name)
        print(f"  {scene.name}: {len(points)} points x ({config.repetitions} timed + 1 warm-up) renders; "
              f"reference {config.reference_for(scene).integrator.type}", file=out)
        for point in points:
            unit = PASS_PARAMETER.get(strategies[point.strategy].type)
            count = f"{point.spp} {unit} of 1 spp" if unit else f"{point.spp} spp"
            level = count if point.spp else f"{point.budget_s:g} s budget ({unit or 'spp'} from a pilot)"
            if point.progressive:
                level = (f"progressive: passes {list(point.passes)} spp, curve at "
                         f"{list(itertools.accumulate(point.passes))} spp" if point.passes
                         else f"{point.budget_s:g} s budget, progressive (passes fitted by the first seed)")
            print(f"    {point.id:60s} {level}", file=out)
    for item in plan.separate:
        print(f"  separate renders on {item['scene']}: {item['strategy']} / {item['sampler']}: {item['reason']}",
              file=out)
    for item in plan.left_out:
        print(f"  left out: {item['scene']} / {item['strategy']}: {item['reason']}", file=out)
    for item in plan.unsupported:
        print(f"  runs, marked \"{item['mark']}\" (experiment.allow_unsupported): {item['scene']} / "
              f"{item['strategy']}: {item['reason']}", file=out)
    for item in plan.aliases:
        print(f"  alias: {item['scene']} / {item['strategy']} = {item['same_as']}: {item['reason']}", file=out)


def print_dry_run(config, plan, out) -> None:
    """The plan and its estimated cost, from a short pilot render per scene (``--dry-run``); a
    plan with nothing to run is printed, then refused (``sweep.require_points``) before any pilot."""
    from ..experiment.execution.strategy_grid import grid_renders
    from ..experiment.sweep import estimate_cost
    from ..progress import duration

    print_plan(config, plan, out)
    cost = estimate_cost(config, plan)
    for name, s in cost["seconds"].items():
        ref = "cached" if name in cost["cached"] else "to render"
        print(f"  estimated {duration(s)} for {name} (reference {ref}; pilot "
              f"{cost['rates'][name] / 1e6:.2f} M samples/s with the reference integrator)", file=out)
    grid = config.strategy_grid
    total = sum(cost["seconds"].values())
    if grid:
        total += cost["grid_seconds"]
        print(f"  strategy grid: {grid_renders(config)} renders of {grid.strategy} on {grid.scene}, "
              f"{grid.spp} spp, path lengths 1..{grid.max_length}: estimated "
              f"{duration(cost['grid_seconds'])}", file=out)
    print(f"estimated total: {duration(total)} (lab integrators run at 0.7-1.1x the "
          f"speed of path; compile time not included)", file=out)
