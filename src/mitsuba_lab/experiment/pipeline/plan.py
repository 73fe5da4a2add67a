"""The sweep plan: scene x strategy x sampler x (spp | time budget), R seeds per point.

Strategies that cannot work on a scene are left out with their reason, and
strategies that are provably the same estimator on a scene are run once and
reported as aliases of the one that runs: each lab integrator's estimator class
answers both from the scene's traits (``mitsuba_lab.scene.strategy_applicability``,
``equivalent_strategies``; ``plugins/integrators/estimator.py``). Point ids are stable strings, so a resumed sweep and a
report find the same points again.

With ``experiment.progressive`` each strategy and sampler of a scene gets one *progressive* point
for the whole spp ladder (``scene/strategy/sampler/spp4-64``: one render per seed whose passes
accumulate, ``ladder_passes``; experiment/execution/progressive.py) and one per time budget, provided
every strategy and sampler planned on the scene can accumulate; otherwise the scene keeps one
point per spp and budget, and the reason is recorded (``separate_reason``, ``Plan.separate``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .config import Config, PluginSpec

#: Seeds: point seeds are seed * SEED_STRIDE + 1 .. R; the untimed warm-up uses seed * SEED_STRIDE.
SEED_STRIDE = 1000


@dataclass(frozen=True)
class Point:
    id: str
    scene: str
    strategy: str
    sampler: str
    spp: int | None                 # None: chosen at run time to fill ``budget_s``
    budget_s: float | None
    seeds: tuple[int, ...]
    warmup_seed: int
    progressive: bool = False       # one accumulating render per seed (experiment/execution/progressive.py)
    passes: tuple[int, ...] = ()    # progressive over the ladder: spp of each pass (ladder_passes);
                                    # () for a budget: fitted by the point's first run
    ladder: tuple[int, ...] = ()    # progressive: the configured spp (they get the optional metrics)


@dataclass
class Plan:
    points: list[Point]
    left_out: list[dict] = field(default_factory=list)   # {scene, strategy, reason}
    aliases: list[dict] = field(default_factory=list)    # {scene, strategy, same_as, reason}
    unsupported: list[dict] = field(default_factory=list)  # run though they cannot render the scene
                                                           # correctly (experiment.allow_unsupported):
                                                           # {scene, strategy, reason, mark}
    separate: list[dict] = field(default_factory=list)   # progressive sweeps: what kept a scene on
                                                         # separate renders {scene, strategy, sampler, reason}

    def for_scene(self, scene: str) -> list[Point]:
        return [p for p in self.points if p.scene == scene]


def point_id(scene, strategy, sampler, spp=None, budget=None, first_spp=None) -> str:
    """``scene/strategy/sampler/spp16``, ``.../t0.5s``, or ``.../spp4-64`` for a progressive run
    over a ladder from ``first_spp`` to ``spp``."""
    if spp is not None:
        level = f"spp{first_spp}-{spp}" if first_spp is not None else f"spp{spp}"
    else:
        level = f"t{budget:g}s"
    return f"{scene}/{strategy}/{sampler}/{level}"


#: Samplers whose samples owe nothing to the other samples of the render: renders of different
#: seeds, averaged, are one render of all their samples. The other samplers stratify a pixel's
#: samples across the whole render (Sobol nets, strata, Halton points); averaged renders would lose
#: that, and converge at the plain Monte Carlo rate.
INDEPENDENT_SAMPLERS = ("independent", "lab_independent")


def separate_reason(strategy: PluginSpec, sampler: PluginSpec) -> str:
    """Why a strategy with a sampler cannot run progressively (one render per spp instead), or ''
    when the spp-weighted mean of independent renders is the same estimator as one render."""
    from ...plugins.integrators.estimator import lookup

    estimator = lookup(strategy.type)
    reason = estimator.separate_reason(strategy.params) if estimator is not None else ""
    if reason:
        return reason
    if sampler.type not in INDEPENDENT_SAMPLERS:
        return (f"sampler {sampler.type} stratifies a pixel's samples across one render: averaged renders of "
                f"different seeds would lose that")
    return ""


def ladder_passes(ladder, checkpoints: str = "doubling") -> tuple[int, ...]:
    """Pass sizes (spp) of a progressive run over an spp ladder. "doubling": the first pass
    renders the smallest count P, each later one as many samples as are accumulated (P, P, 2P,
    4P, ...: the image holds P, 2P, 4P, 8P, ... spp after passes 1, 2, 3, 4, ...), a pass cut
    short where that reaches a ladder value exactly; [4, 16, 64] -> (4, 4, 8, 16, 32). "ladder":
    passes end at the ladder's values only (fewest renders, each paying a render's fixed cost);
    [4, 16, 64] -> (4, 12, 48). The run ends at the largest value."""
    targets = sorted(set(ladder))
    total, sizes = 0, []
    for target in targets:
        while total < target:
            size = target - total if checkpoints == "ladder" else min(max(total, targets[0]), target - total)
            sizes.append(size)
            total += size
    return tuple(sizes)


def warmup_sizes(passes) -> tuple[int, ...]:
    """The untimed warm-up of a progressive point: its two smallest pass sizes (1 and 2 spp for a
    budget, whose passes start at 1; one size for a run of one pass). Were the sample count
    compiled into a kernel, the second would compile again, and a run that compiles is rendered
    again (worker.execute_progressive)."""
    return tuple(sorted(set(passes or (1, 2)))[:2])


def build_plan(config: Config, assess=None) -> Plan:
    """Expand the configuration. ``assess(scene_spec, strategies)`` returns
    ``(left_out: {name: reason}, aliases: {name: (canonical, reason)})``, and optionally third
    the strategies that run though they cannot render the scene correctly, as the config allows:
    ``{name: (mark, reason)}``."""
    plan = Plan(points=[])
    base = config.seed * SEED_STRIDE
    seeds = tuple(base + 1 + r for r in range(config.repetitions))
    for scene in config.scenes:
        left_out, aliases, unsupported = (*assess(scene, config.strategies), {})[:3] if assess else ({}, {}, {})
        for name, reason in left_out.items():
            plan.left_out.append({"scene": scene.name, "strategy": name, "reason": reason})
        for name, (mark, reason) in unsupported.items():
            plan.unsupported.append({"scene": scene.name, "strategy": name, "reason": reason, "mark": mark})
        for name, (canonical, reason) in aliases.items():
            plan.aliases.append({"scene": scene.name, "strategy": name, "same_as": canonical,
                                 "reason": reason})
        groups = [(strategy, sampler) for strategy in config.strategies
                  if strategy.name not in left_out and strategy.name not in aliases for sampler in config.samplers]
        # One time base per scene: a pass costs a render's fixed part again, so a progressive curve
        # is a little slower than separate renders of the same spp; a scene runs progressively only
        # when all of its strategies and samplers can.
        reasons = [(st, sa, separate_reason(st, sa)) for st, sa in groups] if config.progressive else []
        blocking = [{"scene": scene.name, "strategy": st.name, "sampler": sa.name, "reason": reason}
                    for st, sa, reason in reasons if reason]
        plan.separate += blocking
        for strategy, sampler in groups:
            plan.points += _points(config, scene.name, strategy.name, sampler.name, seeds, base,
                                   config.progressive and not blocking)
    return plan


def _points(config: Config, scene: str, strategy: str, sampler: str, seeds, base, progressive) -> list[Point]:
    """The points of one scene, strategy and sampler: one per spp and budget, or progressive ones."""
    if not progressive:
        levels = [(spp, None) for spp in config.spp] + [(None, b) for b in config.time_budgets]
        return [Point(point_id(scene, strategy, sampler, spp, budget), scene, strategy, sampler, spp, budget,
                      seeds, base) for spp, budget in levels]
    points = []
    if config.spp:
        first, last = min(config.spp), max(config.spp)
        points.append(Point(point_id(scene, strategy, sampler, last, first_spp=first), scene, strategy, sampler,
                            last, None, seeds, base, True, ladder_passes(config.spp, config.checkpoints),
                            tuple(config.spp)))
    points += [Point(point_id(scene, strategy, sampler, budget=b), scene, strategy, sampler, None, b, seeds, base,
                     True) for b in config.time_budgets]
    return points


def nothing_to_run(config: Config, plan: Plan) -> str:
    """Why the plan has no point at all (every strategy left out on every scene), in one line;
    '' when it has points."""
    if plan.points:
        return ""
    why = "; ".join(f"{x['scene']} / {x['strategy']}: {x['reason']}" for x in plan.left_out)
    return (f"{config.source}: nothing to run: every strategy is left out on every scene ({why}); add a "
            f"strategy that renders these scenes, or name the strategies to run anyway (marked in the "
            f"report) in experiment.allow_unsupported")


def estimated_seconds(plan: Plan, config: Config, rates: dict[str, float], pixels: dict[str, int],
                      cached_references: set[str]) -> dict[str, float]:
    """Seconds per scene: timed + warm-up renders of the points, and missing references.

    ``rates`` are samples per second measured on this machine (a pilot render per scene);
    time-budget points cost their budget per render. A progressive point renders its largest
    spp once per seed, after a warm-up of its first two pass sizes (no pilots for a budget).
    """
    seconds = {}
    for scene in config.scenes:
        rate, px = rates[scene.name], pixels[scene.name]
        total = 0.0
        for point in plan.for_scene(scene.name):
            if point.progressive:
                warmup = px * sum(warmup_sizes(point.passes)) / rate
                per_seed = point.budget_s if point.spp is None else px * point.spp / rate
                total += warmup + len(point.seeds) * per_seed
                continue
            renders = len(point.seeds) + 1
            total += renders * (point.budget_s if point.spp is None else px * point.spp / rate)
        if scene.name not in cached_references:
            total += px * config.reference_for(scene).spp / rate
        seconds[scene.name] = total
    return seconds
