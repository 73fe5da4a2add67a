"""The block test over the agreement scenes, for the bidirectional family and lab_photon.

For every scene of tests/plugins/test_bdpt.py's agreement lists (the lab's scenes, the stiff
ones where `path` is right, tests/user_scenes.py's users' scenes; on request the media scenes of
``MEDIA_SCENES``) and every variant asked for: --seeds renders of each estimator against --seeds
renders of Mitsuba's `path` (`volpath`, `volpathmis` or lab_bdpt in media: ``MEDIA_SCENES``; other seeds,
--ref-scale x the samples), compared by tests/agreement.py's ``block_test`` (6x6-pixel block
means, Welch z over the seeds, Sidak-corrected alpha 0.01 over the blocks). Unbiased
estimators (lab_bdpt, lab_vcm mode bpt) must pass; consistent ones (lab_vcm modes vcm and ppm,
lab_photon) are rendered at three sample counts (--spp / 4, --spp, 4 x --spp) and judged by their
bias, which must shrink as the count grows: the root mean square over the blocks of the relative
difference of block means, with the part the two sides' noise explains taken out (``block_bias``,
its standard error by resampling the seeds). Their worst |z| need not fall: a merging radius that
shrinks slowly (alpha < 1) leaves a bias that falls more slowly than the standard error.

    .venv/bin/python benchmarks/block_agreement.py [--variants llvm_ad_rgb,llvm_ad_spectral]
        [--seeds 64] [--spp 16] [--scenes cornell_box.xml,...] [--estimators bdpt,vcm_bpt,...]

Prints one Markdown row per scene, variant and estimator: worst |z|, the bound, the blocks
past it, and PASS / FAIL (unbiased) or, for consistent ones, their bias at each count with a
verdict: "converging" (it fell from the first count to the last by more than two standard
errors), "falling (not resolved)", "no bias resolved" (within two standard errors of zero at
every count), "bias resolved only at larger counts" (the first count's noise hides it) or "NOT
SHRINKING" (resolved at the first count and no lower at the last).
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
#: Scenes with participating media, and their reference: volpath, or lab_bdpt on the volumetric
#: caustic, whose light no Mitsuba integrator renders (lab_bdpt agrees with volpath where both apply:
#: tests/plugins/test_bdpt_media.py), and volpathmis on fog_shafts (the path family's reference there,
#: tests/plugins/test_media_block.py). fog_box: tests/media_scenes.py's, sigma_t 2.5.
MEDIA_SCENES = {"fog_box": "volpath", "volumetric_caustic.xml": "lab_bdpt", "fog_shafts.xml": "volpathmis"}
#: (tests/media_scenes.py's other scenes, by name: reference volpath.) A fog box standing on the
#: floor: volpath's reference is rendered with the box sunk into the floor, as volpath lets light
#: through the floor where the two surfaces tie (2026-11-28-bdpt-media-defects.md).
REFERENCE_SCENES = {"fog_on_floor": "fog_on_floor_sunk", "smoke": "smoke_sunk"}
USER_SCENES = ["textured_mesh_room", "principled_and_blend", "spot_and_directional", "normal_bump_maps",
               "thinlens_envmap", "mixed_lights_crop"]
#: name -> (plugin, parameters, unbiased)
ESTIMATORS = {
    "bdpt": ("lab_bdpt", {}, True),
    "vcm_bpt": ("lab_vcm", {"mode": "bpt"}, True),
    "vcm": ("lab_vcm", {"mode": "vcm", "pilot": False}, False),   # (the estimator, not the pilot's choice)
    "ppm": ("lab_vcm", {"mode": "ppm"}, False),
    # a radius set by hand: grazing_camera's floor, black at ppm's automatic radius (a pixel's width)
    "ppm_r0.2": ("lab_vcm", {"mode": "ppm", "radius": 0.2}, False),
    "photon": ("lab_photon", {"photons_per_pass": 20000}, False),
    # huge_dim_light.xml only (its shapes' ids): the light's directions aimed at the stage (aim.py), so
    # that a share of its light subpaths reach it instead of about 2e-4
    "ppm_aim_stage": ("lab_vcm", {"mode": "ppm", "aim": 0.9, "aim_at": "floor,back_wall"}, False),
    "photon_aim_stage": ("lab_photon", {"photons_per_pass": 20000, "aim": 0.9, "aim_at": "floor,back_wall"}, False),
}
MAX_DEPTH = 8
RES = 24
#: Resamplings of the seeds behind each bias's standard error.
RESAMPLES = 200


def block_bias(lab_blocks, ref_blocks, rng) -> tuple[float, float]:
    """(bias, standard error) of the lab's block means (seeds, blocks_y, blocks_x) against the
    reference's: sqrt(max(0, mean_b(d_b^2 - s_b^2))), d_b the relative difference of block b's
    means and s_b^2 its variance from both sides' spread over the seeds; the error is the spread
    of that number over resamplings of both sides' seeds."""
    import numpy as np

    def bias(a, b):
        ma, mb = a.mean(axis=0), b.mean(axis=0)
        lit = mb > 0
        d = (ma[lit] - mb[lit]) / mb[lit]
        s2 = (a.var(axis=0, ddof=1)[lit] / len(a) + b.var(axis=0, ddof=1)[lit] / len(b)) / mb[lit] ** 2
        return float(np.sqrt(max(0.0, float(np.mean(d * d - s2)))))

    draws = [bias(lab_blocks[rng.integers(0, len(lab_blocks), len(lab_blocks))],
                  ref_blocks[rng.integers(0, len(ref_blocks), len(ref_blocks))]) for _ in range(RESAMPLES)]
    return bias(lab_blocks, ref_blocks), float(np.std(draws, ddof=1))


def trend(biases) -> str:
    """The verdict on (bias, standard error) at increasing counts."""
    resolved = [b > 2 * s for b, s in biases]
    if not any(resolved):
        return "no bias resolved"
    if not resolved[0]:
        return "bias resolved only at larger counts"     # (the first count's noise hides it)
    (b1, s1), (b2, s2) = biases[0], biases[-1]
    if b1 - b2 > 2 * (s1 * s1 + s2 * s2) ** 0.5:
        return "converging"
    return "falling (not resolved)" if b2 < b1 else "NOT SHRINKING"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variants", default="llvm_ad_rgb,llvm_ad_spectral")
    parser.add_argument("--seeds", type=int, default=64)
    parser.add_argument("--spp", type=int, default=16, help="samples (passes: lab_photon) per render")
    parser.add_argument("--ref-scale", type=int, default=4)
    parser.add_argument("--scenes", default=",".join(SCENES + USER_SCENES),
                        help=f"also (media, not by default): {', '.join(MEDIA_SCENES)}")
    parser.add_argument("--estimators", default=",".join(ESTIMATORS))
    args = parser.parse_args(argv)

    import mitsuba_lab
    import numpy as np
    from agreement import block_test, grey_block_means, renders
    from mitsuba_lab.scene import load_scene, make_integrator
    import media_scenes
    import mitsuba as mi
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
            elif name == "fog_box":
                scene, depth = mi.load_dict(media_scenes.fog_box(sigma_t=2.5)), MAX_DEPTH
            elif name in media_scenes.SCENES:
                scene, depth = mi.load_dict(media_scenes.SCENES[name]()), MAX_DEPTH
            else:
                scene, depth = load_scene(os.path.join(ROOT, "scenes", name), res=RES), MAX_DEPTH
            reference = MEDIA_SCENES.get(name, "volpath" if name in media_scenes.SCENES else "path")
            ref_scene = (mi.load_dict(media_scenes.SCENES[REFERENCE_SCENES[name]]()) if name in REFERENCE_SCENES
                         else scene)
            ref = renders(ref_scene, make_integrator(reference, {"max_depth": depth}), args.spp * args.ref_scale,
                          ref_seeds)
            for key in args.estimators.split(","):
                plugin, params, unbiased = ESTIMATORS[key]
                integrator = make_integrator(plugin, {"max_depth": depth, **params})
                start = time.perf_counter()
                counts = [args.spp] if unbiased else [max(1, args.spp // 4), args.spp, 4 * args.spp]
                if plugin == "lab_photon":      # (its count is passes, each one camera sample per pixel)
                    stacks = [renders(scene, make_integrator(plugin, {"max_depth": depth, **params, "passes": n}), 1,
                                      lab_seeds) for n in counts]
                else:
                    stacks = [renders(scene, integrator, spp, lab_seeds) for spp in counts]
                results = [block_test(stack, ref) for stack in stacks]
                seconds = time.perf_counter() - start
                last = results[-1]
                if unbiased:
                    verdict = "PASS" if not last.failing else "FAIL"
                    failures += verdict == "FAIL"
                else:
                    rng = np.random.default_rng(0)
                    biases = [block_bias(grey_block_means(stack), grey_block_means(ref), rng) for stack in stacks]
                    verdict = trend(biases) + ": bias " + " -> ".join(
                        f"{b:.4f} +- {s:.4f} at {c}" for (b, s), c in zip(biases, counts)) + "; |z| " + " -> ".join(
                        f"{r.max_abs_z:.1f}" for r in results)
                    failures += verdict.startswith("NOT")
                print(f"| {name} | {variant} | {key} | {last.max_abs_z:.2f} | {last.bound:.2f} | "
                      f"{len(last.failing)} of {last.z.size} | {verdict} | {seconds:.0f} |", flush=True)
            del scene
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
