"""A case of tests/plugins/test_media_block.py against references of more samples per render:
does a block past the bound come from the estimator, or from a heavy-tailed reference (or
estimator) whose render means the Welch z over the renders does not describe?

    PYTHONPATH=src .venv/bin/python benchmarks/media_block_reference.py --scene point_in_fog
        --configs mis,equiangular [--variant llvm_ad_rgb] [--seeds 64] [--scales 1,16] [--reference volpathmis]
        [--seed-offset 0]

Each of --configs renders --seeds renders of the test's SPP (the test's seeds, plus
--seed-offset); the reference renders --seeds renders (likewise) at SPP x each of --scales.
Prints the block test of every config against every reference (worst |z|, blocks past the
bound, the worst block's ratio) and the ratio of the whole-image means. Results: experiments/results/2026-11-28-media-block.md.
"""
from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [os.path.join(ROOT, "tests"), os.path.join(ROOT, "tests", "plugins")]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", required=True)
    parser.add_argument("--configs", default="mis")
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--seeds", type=int, default=64)
    parser.add_argument("--scales", default="1,16")
    parser.add_argument("--reference", default="volpathmis")
    parser.add_argument("--seed-offset", type=int, default=0, help="added to both sides' seeds (a fresh draw)")
    args = parser.parse_args(argv)

    import numpy as np

    import mitsuba_lab
    mitsuba_lab.use_variant(args.variant)
    from agreement import block_test, renders
    from mitsuba_lab.scene import make_integrator
    from test_media_block import DEPTH, SPP, lab, load

    first = args.seed_offset
    seeds_lab, seeds_ref = range(first, first + args.seeds), range(first + 1000, first + 1000 + args.seeds)
    stacks = {c: lab(args.scene, c, seeds_lab) for c in args.configs.split(",")}
    print(f"{args.scene} {args.variant}, {args.seeds} renders a side, {SPP} spp (lab)")
    print("| estimator | reference spp | worst abs z | bound | blocks past | worst block ratio | image mean ratio |")
    print("|---|---|---|---|---|---|---|")
    for scale in (int(s) for s in args.scales.split(",")):
        ref = renders(load(args.scene), make_integrator(args.reference, {"max_depth": DEPTH}), SPP * scale, seeds_ref)
        for config, stack in stacks.items():
            result = block_test(stack, ref)
            y, x = np.unravel_index(np.argmax(np.abs(result.z)), result.z.shape)
            print(f"| {config} | {args.reference} {SPP * scale} | {result.max_abs_z:.2f} | {result.bound:.2f} | "
                  f"{len(result.failing)} of {result.z.size} | ({y},{x}) {result.ratio[y, x]:.4f} | "
                  f"{stack.mean() / ref.mean():.4f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
