"""The block test over the agreement scenes, for the bidirectional family and lab_photon.

For every scene of tests/plugins/test_bdpt.py's agreement lists (the lab's scenes, the stiff
ones where `path` is right, tests/user_scenes.py's users' scenes) and every variant asked for:
--seeds renders of each estimator against --seeds renders of Mitsuba's `path` (other seeds,
--ref-scale x the samples), compared by tests/agreement.py's ``block_test`` (6x6-pixel block
means, Welch z over the seeds, Sidak-corrected alpha 0.01 over the blocks). Unbiased
estimators (lab_bdpt, lab_vcm mode bpt) must pass; consistent ones (lab_vcm modes vcm and ppm,
lab_photon) are shown at two sample counts, where their worst |z| should fall as the count
grows (their bias shrinks, the test's power stays).

    .venv/bin/python benchmarks/block_agreement.py [--variants llvm_ad_rgb,llvm_ad_spectral]
        [--seeds 64] [--spp 16] [--scenes cornell_box.xml,...] [--estimators bdpt,vcm_bpt,...]

Prints one Markdown row per scene, variant and estimator: worst |z|, the bound, the blocks
past it, and PASS / FAIL (unbiased) or the worst |z| at both counts (consistent).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [os.path.join(ROOT, "tests"), os.path.join(ROOT, "tests", "plugins")]

SCENES = ["cornell_box.xml", "caustic.xml", "veach_mis.xml", "glossy_small_light.xml",
          "stiff/all_specular.xml", "stiff/delta_lights_only.xml", "stiff/environment_only.xml",
          "stiff/grazing_camera.xml", "stiff/huge_dim_light.xml", "stiff/light_in_glass.xml",
          "stiff/scaled_1e4.xml"]
USER_SCENES = ["textured_mesh_room", "principled_and_blend", "spot_and_directional", "normal_bump_maps",
               "thinlens_envmap", "mixed_lights_crop"]
#: name -> (plugin, parameters, unbiased)
ESTIMATORS = {
    "bdpt": ("lab_bdpt", {}, True),
    "vcm_bpt": ("lab_vcm", {"mode": "bpt"}, True),
    "vcm": ("lab_vcm", {"mode": "vcm", "pilot": False}, False),   # (the estimator, not the pilot's choice)
    "ppm": ("lab_vcm", {"mode": "ppm"}, False),
    "photon": ("lab_photon", {"photons_per_pass": 20000}, False),
}
MAX_DEPTH = 8
RES = 24


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variants", default="llvm_ad_rgb,llvm_ad_spectral")
    parser.add_argument("--seeds", type=int, default=64)
    parser.add_argument("--spp", type=int, default=16, help="samples (passes: lab_photon) per render")
    parser.add_argument("--ref-scale", type=int, default=4)
    parser.add_argument("--scenes", default=",".join(SCENES + USER_SCENES))
    parser.add_argument("--estimators", default=",".join(ESTIMATORS))
    args = parser.parse_args(argv)

    import mitsuba_lab
    from agreement import block_test, renders
    from mitsuba_lab.scene import load_scene, make_integrator
    import user_scenes

    assets = user_scenes.write_assets(os.path.join(ROOT, "out", "block_agreement_assets"))
    lab_seeds, ref_seeds = range(args.seeds), range(10_000, 10_000 + args.seeds)
    print("| scene | variant | estimator | worst abs z | bound | blocks past | verdict | s |")
    print("|---|---|---|---|---|---|---|---|")
    failures = 0
    for variant in args.variants.split(","):
        mitsuba_lab.use_variant(variant)
        for name in args.scenes.split(","):
            if name in USER_SCENES:
                scene, depth = user_scenes.load(assets, name), user_scenes.max_depth(name)
            else:
                scene, depth = load_scene(os.path.join(ROOT, "scenes", name), res=RES), MAX_DEPTH
            ref = renders(scene, make_integrator("path", {"max_depth": depth}), args.spp * args.ref_scale, ref_seeds)
            for key in args.estimators.split(","):
                plugin, params, unbiased = ESTIMATORS[key]
                integrator = make_integrator(plugin, {"max_depth": depth, **params})
                start = time.perf_counter()
                counts = [args.spp] if unbiased else [max(1, args.spp // 4), args.spp]
                results = [block_test(renders(scene, integrator, spp, lab_seeds), ref) for spp in counts]
                seconds = time.perf_counter() - start
                last = results[-1]
                if unbiased:
                    verdict = "PASS" if not last.failing else "FAIL"
                    failures += verdict == "FAIL"
                else:
                    verdict = "converging: " + " -> ".join(f"{r.max_abs_z:.1f} at {c}" for r, c in zip(results, counts))
                print(f"| {name} | {variant} | {key} | {last.max_abs_z:.2f} | {last.bound:.2f} | "
                      f"{len(last.failing)} of {last.z.size} | {verdict} | {seconds:.0f} |", flush=True)
            del scene
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
