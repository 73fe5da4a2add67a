"""The sweep plan: scene x strategy x sampler x (spp | time budget), R seeds per point.

Strategies that cannot work on a scene are left out with their reason, and
strategies that are provably the same estimator on a scene are run once and
reported as aliases of the one that runs: each lab integrator's estimator class
answers both from the scene's traits (``mitsuba_lab.scene.strategy_applicability``,
``equivalent_strategies``; ``plugins/integrators/estimator.py``). Point ids are stable strings, so a resumed sweep and a
report find the same points again.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .config import Config, SceneSpec

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


@dataclass
class Plan:
    points: list[Point]
    left_out: list[dict] = field(default_factory=list)   # {scene, strategy, reason}
    aliases: list[dict] = field(default_factory=list)    # {scene, strategy, same_as, reason}

    def for_scene(self, scene: str) -> list[Point]:
        return [p for p in self.points if p.scene == scene]


def point_id(scene, strategy, sampler, spp=None, budget=None) -> str:
    level = f"spp{spp}" if spp is not None else f"t{budget:g}s"
    return f"{scene}/{strategy}/{sampler}/{level}"


def build_plan(config: Config, assess=None) -> Plan:
    """Expand the configuration. ``assess(scene_spec, strategies)`` returns
    ``(left_out: {name: reason}, aliases: {name: (canonical, reason)})``."""
    plan = Plan(points=[])
    base = config.seed * SEED_STRIDE
    seeds = tuple(base + 1 + r for r in range(config.repetitions))
    for scene in config.scenes:
        left_out, aliases = assess(scene, config.strategies) if assess else ({}, {})
        for name, reason in left_out.items():
            plan.left_out.append({"scene": scene.name, "strategy": name, "reason": reason})
        for name, (canonical, reason) in aliases.items():
            plan.aliases.append({"scene": scene.name, "strategy": name, "same_as": canonical,
                                 "reason": reason})
        for strategy in config.strategies:
            if strategy.name in left_out or strategy.name in aliases:
                continue
            for sampler in config.samplers:
                levels = [(spp, None) for spp in config.spp] + [(None, b) for b in config.time_budgets]
                for spp, budget in levels:
                    plan.points.append(Point(point_id(scene.name, strategy.name, sampler.name, spp, budget),
                                             scene.name, strategy.name, sampler.name, spp, budget, seeds,
                                             base))
    return plan


def scene_pixels(scene: SceneSpec, default_resolution: tuple[int, int]) -> int:
    if scene.resolution:
        return scene.resolution ** 2
    return default_resolution[0] * default_resolution[1]


def estimated_seconds(plan: Plan, config: Config, rates: dict[str, float], pixels: dict[str, int],
                      cached_references: set[str]) -> dict[str, float]:
    """Seconds per scene: timed + warm-up renders of the points, and missing references.

    ``rates`` are samples per second measured on this machine (a pilot render per scene);
    time-budget points cost their budget per render.
    """
    seconds = {}
    for scene in config.scenes:
        rate, px = rates[scene.name], pixels[scene.name]
        total = 0.0
        for point in plan.for_scene(scene.name):
            renders = len(point.seeds) + 1
            total += renders * (point.budget_s if point.spp is None else px * point.spp / rate)
        if scene.name not in cached_references:
            total += px * config.reference.spp / rate
        seconds[scene.name] = total
    return seconds
