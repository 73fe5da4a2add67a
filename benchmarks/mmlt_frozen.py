"""lab_mmlt's frozen lock-step rounds (``mlt/frozen.py``) against traced ones: the same seeds
rendered both ways in alternating rounds, seconds per mutation (``mlt_stats()``, timed with
``dr.sync_thread()``) and the largest pixel difference between the two images of a seed.

    PYTHONPATH=src python benchmarks/mmlt_frozen.py --scene scenes/door.xml --spp 64 --rounds 3
"""
from __future__ import annotations

import argparse
import os
import statistics

import mitsuba as mi

mi.set_variant("llvm_ad_rgb")

import numpy as np  # noqa: E402

import mitsuba_lab.plugins  # noqa: E402,F401
from mitsuba_lab.plugins.integrators.mlt import mmlt  # noqa: E402
from mitsuba_lab.scene import make_integrator  # noqa: E402
from mitsuba_lab.scene_xml import load_scene_variant  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default=os.path.join(ROOT, "scenes", "door.xml"))
    parser.add_argument("--res", type=int, default=32)
    parser.add_argument("--spp", type=int, default=64, help="mutations per pixel (default: 64)")
    parser.add_argument("--chains", type=int, default=8192)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    scene = load_scene_variant(args.scene, args.res)
    integrator = make_integrator("lab_mmlt", {"max_depth": 8, "chains": args.chains})
    times = {False: [], True: []}
    for frozen in (False, True):               # warm-up: compile both
        mmlt.FREEZE_ROUNDS = frozen
        mi.render(scene, integrator=integrator, spp=args.spp, seed=1000)
    for r in range(args.rounds):
        images = {}
        for frozen in (False, True) if r % 2 == 0 else (True, False):
            mmlt.FREEZE_ROUNDS = frozen
            images[frozen] = np.array(mi.render(scene, integrator=integrator, spp=args.spp, seed=r), dtype=np.float64)
            stats = integrator.mlt_stats()
            times[frozen].append(stats["seconds_per_mutation"] * 1e6)
            print(f"round {r} {'frozen' if frozen else 'traced'}: {times[frozen][-1]:.2f} us/mutation, "
                  f"image mean {images[frozen][..., :3].mean():.7f}, recordings {stats['frozen_recordings']}",
                  flush=True)
        diff = np.abs(images[True] - images[False]).max()
        print(f"round {r}: largest pixel difference {diff:.3g} (largest pixel {images[False].max():.3g})", flush=True)
    traced, frozen = statistics.median(times[False]), statistics.median(times[True])
    print(f"median us/mutation: traced {traced:.2f}, frozen {frozen:.2f}, ratio {traced / frozen:.2f}")


if __name__ == "__main__":
    main()
