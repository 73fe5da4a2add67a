"""Renders timed in alternating rounds, so that machine noise hits every contender alike.

Each integrator is warmed up once (kernel compilation), then every round renders each of them in
turn; each time is taken after dr.eval and dr.sync_thread (``mitsuba_lab.render``)."""
from __future__ import annotations

import argparse
import statistics
import sys

from mitsuba_lab.render import render


def common_arguments(parser: argparse.ArgumentParser, scene: str, res: int, spp: int, max_depth: int):
    parser.add_argument("--scene", default=scene)
    parser.add_argument("--res", type=int, default=res, help=f"image width (aspect kept; default: {res})")
    parser.add_argument("--spp", type=int, default=spp, help=f"samples per pixel (default: {spp})")
    parser.add_argument("--max-depth", type=int, default=max_depth,
                        help=f"max_depth of every integrator (default: {max_depth})")
    parser.add_argument("--rounds", type=int, default=7, help="timed rounds (default: 7)")


def time_rounds(scene, contenders: dict, spp: int, rounds: int) -> dict[str, list[float]]:
    """{name: wall times of its renders, one per round} (progress on stderr)."""
    for integrator in contenders.values():
        render(scene, integrator, spp=spp, seed=0)          # warm-up: compile
    times = {name: [] for name in contenders}
    for round_index in range(rounds):
        for name, integrator in contenders.items():
            _, stats = render(scene, integrator, spp=spp, seed=1 + round_index)
            times[name].append(stats.wall_s)
            print(f"round {round_index}: {name:34s} {stats.wall_s:.3f} s", file=sys.stderr)
    return times


def median_ratio(samples: list[float], baseline: list[float]) -> float:
    """The median of the per-round ratios samples / baseline."""
    return statistics.median([t / b for t, b in zip(samples, baseline)])
