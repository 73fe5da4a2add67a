"""Where lab_mis's error in fog_shafts' `shafts` region comes from (issue 44): per-sample variance and
cost of each medium sampling, split into single and multiple scattering.

For each strategy, SEEDS renders of SPP samples at res 48 with max_depth 2 (single scattering: the
camera ray's segment and its first vertex) and 16, the same seeds: a path's first two segments use
the same random numbers at both depths, so (depth 16 - depth 2) is the multiple-scattering part of
the same estimate. Prints the per-sample relative variance over the region's 20 pixels,
mean over pixels and channels of SPP var / (ref^2 + 0.01) (the sweep's relMSE per sample; ref the
mean of every strategy's depth-16 renders), at depth 16, 2, and of the difference; then each
strategy's CPU time (process time, all threads: steadier than wall time on a loaded machine) per
render of --time-spp samples at depth 16 over `distance`'s, median of --rounds alternating rounds,
and var x time over distance's: the efficiency ratio an equal-time comparison measures.

    PYTHONPATH=src .venv/bin/python benchmarks/media_shafts_variance.py [--seeds 32] [--spp 64]
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import mitsuba as mi

import mitsuba_lab

RES = 48
SHAFTS = (slice(15, 19), slice(22, 27))          # fog_shafts.regions.toml's `shafts` at res 48
STRATEGIES = {
    "distance": {"medium_sampling": "distance"},
    "equiangular": {"medium_sampling": "equiangular"},
    "mis": {},
    "mis_max": {"heuristic": "max"},
    "mis_n2": {"equiangular_samples": 2},
    "mis_max_n2": {"heuristic": "max", "equiangular_samples": 2},
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=32)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--time-spp", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args(argv)
    mitsuba_lab.use_variant("llvm_ad_rgb")
    from mitsuba_lab.scene import load_scene, make_integrator

    scene = load_scene("scenes/fog_shafts.xml", res=RES)

    def integrator(params, depth):
        return make_integrator("lab_mis", {"max_depth": depth, **params})

    stacks = {}
    for name, params in STRATEGIES.items():
        for depth in (2, 16):
            plugin = integrator(params, depth)
            stacks[name, depth] = np.stack([np.array(mi.render(scene, integrator=plugin, spp=args.spp, seed=s),
                                                     dtype=np.float64)[SHAFTS] for s in range(args.seeds)])
    ref = np.mean([stacks[name, 16].mean(0) for name in STRATEGIES], axis=0)

    def rel(stack):
        return float(np.mean(args.spp * stack.var(0, ddof=1) / (ref ** 2 + 1e-2)))

    plugins = {name: integrator(params, 16) for name, params in STRATEGIES.items()}
    times = {name: [] for name in plugins}
    for name, plugin in plugins.items():                       # compile once
        np.array(mi.render(scene, integrator=plugin, spp=args.time_spp, seed=1))
    for r in range(args.rounds):
        for name, plugin in plugins.items():
            start = time.process_time()
            np.array(mi.render(scene, integrator=plugin, spp=args.time_spp, seed=100 + r))
            times[name].append(time.process_time() - start)
    base = np.array(times["distance"])
    print(f"fog_shafts res {RES}, region shafts, {args.seeds} seeds x {args.spp} spp; CPU time at {args.time_spp} spp, "
          f"{args.rounds} rounds; region mean {ref.mean():.4f}")
    print(f"{'strategy':12s} {'mean':>7s} {'var d16':>8s} {'var d2':>7s} {'var ms':>7s} {'time/dist':>9s} "
          f"{'var x time over distance':>25s}")
    v_dist = rel(stacks["distance", 16])
    for name in STRATEGIES:
        v16, v2, vms = rel(stacks[name, 16]), rel(stacks[name, 2]), rel(stacks[name, 16] - stacks[name, 2])
        t = float(np.median(np.array(times[name]) / base))
        print(f"{name:12s} {stacks[name, 16].mean():7.4f} {v16:8.3f} {v2:7.3f} {vms:7.3f} {t:9.2f} "
              f"{v16 * t / v_dist:25.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
