"""Speed of the path family in participating media as a ratio to Mitsuba's `volpath`, in one run.

scenes/fog_shafts.xml (a point light shining into thin homogeneous fog) at 128x128, 16 spp, max_depth 16 by
default. Each integrator is warmed up once (kernel compilation), then the renders alternate
between `volpath` and the lab's for --rounds rounds, so that machine noise hits all of them
alike; each time is taken after dr.eval and dr.sync_thread (mitsuba_lab.render). Prints the median
wall time of each and the median of the per-round ratios to volpath: lab_mis with free flights
alone (``medium_sampling = distance``, volpath's estimator but for exact shadow-ray
transmittance) and with equi-angular sampling added (``mis``, the default), whose ratio to
``distance`` is the equi-angular step's cost; and ``mis`` with two equi-angular samples on camera
rays' segments (``equiangular_samples = 2``), alone and with the max heuristic, whose light samples
of weight 0 trace no shadow ray (2026-11-29-fog-shafts-mis.md).

    .venv/bin/python benchmarks/bench_media.py [--scene scenes/fog_shafts.xml] [--res 128] [--spp 16]
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
    common_arguments(parser, os.path.join(ROOT, "scenes", "fog_shafts.xml"), res=128, spp=16, max_depth=16)
    args = parser.parse_args(argv)

    scene = load_scene(args.scene, res=args.res)
    depth = {"max_depth": args.max_depth}
    contenders = {
        "volpath": make_integrator("volpath", depth),
        "lab_mis(distance)": make_integrator("lab_mis", {**depth, "medium_sampling": "distance"}),
        "lab_mis(mis)": make_integrator("lab_mis", depth),
        "lab_mis(equiangular)": make_integrator("lab_mis", {**depth, "medium_sampling": "equiangular"}),
        "lab_mis(mis, n_E 2)": make_integrator("lab_mis", {**depth, "equiangular_samples": 2}),
        "lab_mis(mis, max, n_E 2)": make_integrator("lab_mis", {**depth, "heuristic": "max", "equiangular_samples": 2}),
    }
    times = time_rounds(scene, contenders, args.spp, args.rounds)

    print(f"{os.path.basename(args.scene)} at {args.res} wide, {args.spp} spp, max_depth {args.max_depth}, "
          f"{args.rounds} alternating rounds; {versions()}")
    print(f"{'integrator':24s} {'median s':>9s} {'ratio to volpath':>17s} {'ratio to distance':>18s}")
    for name, samples in times.items():
        to_volpath = median_ratio(samples, times["volpath"])
        to_distance = median_ratio(samples, times["lab_mis(distance)"])
        print(f"{name:24s} {statistics.median(samples):9.3f} {to_volpath:17.3f} {to_distance:18.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
