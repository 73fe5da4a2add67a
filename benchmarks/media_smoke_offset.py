"""Image means of scenes/smoke.xml by several integrators over many independent renders, each
against the first: is an offset of about 0.1% between them real, and whose is it?

    PYTHONPATH=src .venv/bin/python benchmarks/media_smoke_offset.py [--integrators volpathmis,volpath,lab_mis]
        [--max-depth 16] [--res 32] [--spp 64] [--seeds 64] [--variant llvm_ad_rgb]

Each integrator renders --seeds renders (its own seed range) of --spp samples; the image mean
of a render is its mean over pixels and channels. Prints per integrator the mean of those, its
standard error, the ratio to the first integrator's and the Welch z of the difference, and the
CPU seconds spent. Results: experiments/results/2026-11-28-media-block.md.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--integrators", default="volpathmis,volpath,lab_mis")
    parser.add_argument("--max-depth", type=int, default=16)
    parser.add_argument("--res", type=int, default=32)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--seeds", type=int, default=64)
    parser.add_argument("--variant", default="llvm_ad_rgb")
    args = parser.parse_args(argv)

    import numpy as np

    import mitsuba_lab
    from mitsuba_lab.metrics import z_score
    from mitsuba_lab.render import render
    from mitsuba_lab.scene import load_scene, make_integrator

    mitsuba_lab.use_variant(args.variant)
    scene = load_scene(os.path.join(ROOT, "scenes", "smoke.xml"), res=args.res, max_depth=args.max_depth)
    print(f"smoke.xml {args.variant} res {args.res} max_depth {args.max_depth}: {args.seeds} renders x "
          f"{args.spp} spp each")
    print("| integrator | image mean | standard error | over the first | z | CPU s |")
    print("|---|---|---|---|---|---|")
    first = None
    for k, kind in enumerate(args.integrators.split(",")):
        integrator = make_integrator(kind, {"max_depth": args.max_depth})
        start = time.process_time()
        means = np.array([render(scene, integrator, spp=args.spp, seed=100_000 * k + s)[0].mean()
                          for s in range(args.seeds)], dtype=np.float64)
        seconds = time.process_time() - start
        mean, var = means.mean(), means.var(ddof=1) / len(means)
        first = first or (mean, var)
        z = float(z_score(mean, var, 1, first[0], first[1], 1)) if k else 0.0
        print(f"| {kind} | {mean:.6f} | {np.sqrt(var):.6f} ({np.sqrt(var) / mean:.4%}) | {mean / first[0]:.5f} | "
              f"{z:+.2f} | {seconds:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
