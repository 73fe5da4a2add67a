"""A fog box standing on the floor: its null bottom face on the floor's plane (issue 46).

Part 1 counts, over rays aimed at the box's footprint on the floor's plane (from inside the box
downwards, from below upwards), how many meet the null face before the floor, and how many of
those meet anything after passing it (offset to its far side, as every renderer spawns the next
ray). Part 2 renders tests/media_scenes.py's ``smoke`` without card and environment (the spot
light only, max_depth 2) with the box standing and sunk 0.05 into the floor (``smoke_sunk``):
`volpath`, lab_bdpt's light tracing and its camera strategies, each against `volpath` on the
sunk box (image means, worst |z| of tests/agreement.py's 8x8 blocks).

    PYTHONPATH=src .venv/bin/python benchmarks/media_coplanar.py [--seeds 12] [--spp 16]
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests"))


def ties(scene, n: int = 20000) -> None:
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    rng = np.random.default_rng(1)
    foot = np.stack([rng.uniform(-0.5, 0.5, n), np.zeros(n), rng.uniform(-0.5, 0.5, n)], 1)
    for label, sign in [("down from inside the box", -1), ("up from below the floor", 1)]:
        d = rng.normal(size=(n, 3))
        d[:, 1] = (np.abs(d[:, 1]) + 0.3) * sign
        d /= np.linalg.norm(d, axis=1)[:, None]
        o = (foot - 0.2 * d).astype(np.float32)
        ray = mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.astype(np.float32).T))
        si = scene.ray_intersect(ray)
        null = si.is_medium_transition()
        after = scene.ray_intersect(si.spawn_ray(ray.d), active=null)
        print(f"{label}: null face first {dr.mean(mi.Float(null))[0]:.3f}, of those {int(dr.count(null & after.is_valid())[0])} "
              f"of {int(dr.count(null)[0])} meet a surface after passing it (|y| of the hits <= "
              f"{float(np.abs(si.p.y.numpy()).max()):.1e})")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=12)
    parser.add_argument("--spp", type=int, default=16)
    args = parser.parse_args(argv)

    import numpy as np

    import mitsuba as mi
    import mitsuba_lab
    mitsuba_lab.use_variant("llvm_ad_rgb")
    import media_scenes
    from agreement import renders, z_scores
    from mitsuba_lab.scene import make_integrator

    def spot_only(build):
        scene = build()
        del scene["card"], scene["environment"]
        return mi.load_dict(scene)

    standing, sunk = spot_only(media_scenes.smoke), spot_only(media_scenes.smoke_sunk)
    ties(standing)
    lab, ref_seeds = range(args.seeds), range(1000, 1000 + args.seeds)
    ref = renders(sunk, make_integrator("volpath", {"max_depth": 2}), args.spp, ref_seeds)
    for box, scene in [("standing", standing), ("sunk", sunk)]:
        for name, params, seeds in [("volpath", {}, ref_seeds), ("lab_bdpt", {"strategies": "light"}, lab),
                                    ("lab_bdpt", {"strategies": "camera"}, lab)]:
            if box == "sunk" and name == "volpath":
                continue
            stack = renders(scene, make_integrator(name, {"max_depth": 2, **params}), args.spp, seeds)
            result = z_scores(stack, ref)
            print(f"{box} box, {name} {params}: image mean / volpath's on the sunk box - 1 = "
                  f"{np.round(result.rel_diff, 4)}, worst |z| {result.max_abs_z:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
