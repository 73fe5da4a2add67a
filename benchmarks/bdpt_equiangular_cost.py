"""lab_bdpt's equi-angular sampling on fog_shafts: cost in the region `shafts` against lab_mis, with
the contenders rendered in alternating rounds (as benchmarks/alternating.py), so that the load of a
shared machine hits them alike (a sweep's points run one after another, and on 2 shared cores the
load moved their equal-time ratios by up to 1.8x between two sweeps of the same code).

Each round renders every contender once at --spp (its own seed per round); the region's relMSE is
taken against a reference image (an EXR of the same scene and resolution: a sweep's cached
reference) and the cost is mean relMSE x median time, relative to lab_mis's.

    PYTHONPATH=src .venv/bin/python benchmarks/bdpt_equiangular_cost.py --reference REF.exr
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys

import numpy as np

import mitsuba as mi  # noqa: E402

import mitsuba_lab  # noqa: E402,F401
from mitsuba_lab.render import render  # noqa: E402
from mitsuba_lab.scene import load_scene, make_integrator  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: region `shafts` of scenes/fog_shafts.regions.toml (fractions x0, y0, x1, y1; inward rounding)
SHAFTS = (0.453125, 0.3125, 0.578125, 0.40625)
CONTENDERS = {
    "lab_mis": ("lab_mis", {}),
    "lab_bdpt off": ("lab_bdpt", {"equiangular_nee": "off"}),
    "lab_bdpt first": ("lab_bdpt", {"equiangular_nee": "first"}),
    "lab_bdpt all (default)": ("lab_bdpt", {}),
    "lab_vcm bpt (default)": ("lab_vcm", {"mode": "bpt"}),
}


def region(image, box):
    h, w = image.shape[:2]
    x0, y0 = int(np.ceil(box[0] * w)), int(np.ceil(box[1] * h))
    x1, y1 = int(np.floor(box[2] * w)), int(np.floor(box[3] * h))
    return image[y0:y1, x0:x1, :3]


def rel_mse(image, ref):
    a, b = region(image, SHAFTS), region(ref, SHAFTS)
    return float(np.mean((a - b) ** 2 / (b ** 2 + 0.01)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", required=True, help="EXR reference of fog_shafts at --res")
    parser.add_argument("--res", type=int, default=48)
    parser.add_argument("--spp", type=int, default=128)
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--max-depth", type=int, default=16)
    args = parser.parse_args()
    mi.set_variant("llvm_ad_rgb")
    scene = load_scene(os.path.join(ROOT, "scenes", "fog_shafts.xml"), res=args.res)
    ref = np.array(mi.Bitmap(args.reference).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32))
    contenders = {name: make_integrator(kind, {"max_depth": args.max_depth, **p})
                  for name, (kind, p) in CONTENDERS.items()}
    errors = {name: [] for name in contenders}
    times = {name: [] for name in contenders}
    for integrator in contenders.values():
        render(scene, integrator, spp=args.spp, seed=0)            # warm-up: compile
    for round_index in range(args.rounds):                         # (as benchmarks/alternating.py)
        for name, integrator in contenders.items():
            image, stats = render(scene, integrator, spp=args.spp, seed=1 + round_index)
            times[name].append(stats.wall_s)
            errors[name].append(rel_mse(np.array(image), ref))
            print(f"round {round_index}: {name:24s} {stats.wall_s:.3f} s", file=sys.stderr)
    base = statistics.mean(errors["lab_mis"]) * statistics.median(times["lab_mis"])
    print(f"fog_shafts {args.res} px, {args.spp} spp, {args.rounds} alternating rounds; region shafts:")
    for name in contenders:
        err, t = statistics.mean(errors[name]), statistics.median(times[name])
        sem = statistics.stdev(errors[name]) / len(errors[name]) ** 0.5
        print(f"  {name:24s} relMSE {err:.5f} +- {sem:.5f}  median {t:.3f} s  cost over lab_mis "
              f"{err * t / base:.2f}x")


if __name__ == "__main__":
    main()
