"""Speed of the lab integrators as a ratio to Mitsuba's C++ `path`, measured in one run.

Cornell box (scenes/cornell_box.xml) at 256x256, 64 spp, max_depth 8 by default.
Each integrator is warmed up once (kernel compilation), then the renders
alternate between `path` and the lab integrators for --rounds rounds, so that
machine noise hits all of them alike; each time is taken after dr.eval and
dr.sync_thread (mitsuba_lab.render). Prints the median wall time of each and
the median of the per-round ratios lab / path, and the cost of the ray
counters (count_rays on / off) for lab_mis.

    .venv/bin/python benchmarks/bench_integrators.py [--res 256] [--spp 64] [--rounds 7]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys

import mitsuba_lab  # noqa: F401
from alternating import common_arguments, median_ratio, time_rounds
from mitsuba_lab.runtime import versions
from mitsuba_lab.scene import load_scene, make_integrator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    common_arguments(parser, os.path.join(ROOT, "scenes", "cornell_box.xml"), res=256, spp=64, max_depth=8)
    args = parser.parse_args(argv)

    scene = load_scene(args.scene, res=args.res)
    depth = {"max_depth": args.max_depth}
    contenders = {
        "path": make_integrator("path", depth),
        "lab_mis(power)": make_integrator("lab_mis", {**depth, "heuristic": "power"}),
        "lab_nee": make_integrator("lab_nee", depth),
        "lab_naive": make_integrator("lab_naive", depth),
        "lab_mis(power, count_rays=false)": make_integrator("lab_mis", {**depth, "count_rays": False}),
    }
    times = time_rounds(scene, contenders, args.spp, args.rounds)

    print(f"{os.path.basename(args.scene)} {args.res}x{args.res}, {args.spp} spp, max_depth "
          f"{args.max_depth}, {args.rounds} alternating rounds; {versions()}")
    print(f"{'integrator':34s} {'median s':>9s} {'ratio to path (median of rounds)':>34s}")
    for name, samples in times.items():
        print(f"{name:34s} {statistics.median(samples):9.3f} {median_ratio(samples, times['path']):34.3f}")
    on, off = times["lab_mis(power)"], times["lab_mis(power, count_rays=false)"]
    counter_cost = median_ratio(on, off)
    print(f"ray counters: lab_mis time with / without = {counter_cost:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
