"""lab_vcm ppm's bias in media against a fixed merging radius: consistency where the default
schedule (alpha 0.75: the ball's radius falls as i^(-1/12)) shrinks too slowly to show it.

For each radius r (surface and ball alike, alpha 0.999, 16 light subpaths per camera subpath):
--seeds renders of 16 spp against --seeds renders of the reference at 64 spp (volpath on
tests/media_scenes.py's fog box at sigma_t 2.5; lab_bdpt on scenes/volumetric_caustic.xml at
24x24, whose cone no Mitsuba integrator renders), max_depth 8. Prints the block bias of
benchmarks/block_agreement.py (root mean square of the blocks' relative differences, the
noise's share taken out, +- its standard error by resampling the seeds) and the image mean's
relative difference. A consistent estimator's bias falls with r.

    .venv/bin/python benchmarks/media_radius_bias.py fog_box --radii 0.2,0.1,0.05 [--seeds 16]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [os.path.join(ROOT, "tests"), os.path.join(ROOT, "tests", "plugins"), os.path.join(ROOT, "benchmarks")]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", choices=("fog_box", "volumetric_caustic.xml"))
    parser.add_argument("--radii", default="0.2,0.1,0.05")
    parser.add_argument("--seeds", type=int, default=16)
    args = parser.parse_args(argv)

    import mitsuba as mi
    import numpy as np
    import mitsuba_lab
    mitsuba_lab.use_variant("llvm_ad_rgb")
    import media_scenes
    from agreement import grey_block_means, renders
    from block_agreement import block_bias
    from mitsuba_lab.scene import load_scene, make_integrator

    if args.scene == "fog_box":
        scene, reference = mi.load_dict(media_scenes.fog_box(sigma_t=2.5)), "volpath"
    else:
        scene, reference = load_scene(os.path.join(ROOT, "scenes", args.scene), res=24), "lab_bdpt"
    ref = renders(scene, make_integrator(reference, {"max_depth": 8}), 64, range(10_000, 10_000 + args.seeds))
    for r in (float(x) for x in args.radii.split(",")):
        start = time.perf_counter()
        ppm = make_integrator("lab_vcm", {"mode": "ppm", "max_depth": 8, "radius": r, "radius_volume": r,
                                          "alpha": 0.999, "light_paths": 16})
        stack = renders(scene, ppm, 16, range(args.seeds))
        bias, error = block_bias(grey_block_means(stack), grey_block_means(ref), np.random.default_rng(0))
        print(f"{args.scene} ppm r={r}: block bias {bias:.4f} +- {error:.4f}, image mean "
              f"{stack.mean() / ref.mean() - 1:+.4f} ({time.perf_counter() - start:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
