"""lab_vcm's and lab_photon's automatic first merging radius, scene by scene (issue 41).

``radii``: per scene and film size, the old default (a pixel's width, ``footprint.pixel_footprint``)
and the new one (``density_radius.first_radius``: the footprint, or the radius at which the median
probe pixel's disc holds ``K_EXPECTED`` light vertices of one iteration, capped), with r_density
and the cap, and the milliseconds each takes (wall clock, best of 3), for lab_vcm's modes vcm (its
default aim) and ppm and lab_photon (the block test's 20,000 photons per pass and the default;
``direct = nee`` stores from the second segment). Their user scenes (tests/user_scenes.py) have
their own films: one row each.

``--save DIR`` / ``--compare DIR``: renders of lab_vcm's default mode and ppm and lab_photon at
fixed seeds (run with ``PYTHONPATH`` at the code to save from: this script needs only
``mitsuba_lab.scene``), then the largest absolute per-pixel difference.

    PYTHONPATH=src .venv/bin/python benchmarks/first_radius.py radii [--res 24,64] [--scenes a.xml,...]
    PYTHONPATH=/base/src .venv/bin/python benchmarks/first_radius.py images --save out/radius_before
    PYTHONPATH=src .venv/bin/python benchmarks/first_radius.py images --compare out/radius_before
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ["cornell_box.xml", "caustic.xml", "sds.xml", "veach_mis.xml", "glossy_small_light.xml",
          "stiff/all_specular.xml", "stiff/delta_lights_only.xml", "stiff/environment_only.xml",
          "stiff/grazing_camera.xml", "stiff/huge_dim_light.xml", "stiff/light_in_glass.xml",
          "stiff/scaled_1e4.xml"]
#: name -> (plugin, parameters): what the radii are printed for and the images rendered with
CONFIGS = {
    "vcm": ("lab_vcm", {}),
    "ppm": ("lab_vcm", {"mode": "ppm"}),
    "photon_20k": ("lab_photon", {"photons_per_pass": 20000}),
    "photon": ("lab_photon", {}),
}
DEPTH, SPP, SEED = 8, 8, 7


USER_SCENES = ["textured_mesh_room", "principled_and_blend", "spot_and_directional", "normal_bump_maps",
               "thinlens_envmap", "mixed_lights_crop"]


def load(name: str, res: int):
    """A scene of scenes/ at ``res``, or one of tests/user_scenes.py's (its own film) by name."""
    from mitsuba_lab.scene import load_scene
    if name in USER_SCENES:
        sys.path.insert(0, os.path.join(ROOT, "tests"))
        import user_scenes
        return user_scenes.load(user_scenes.write_assets(os.path.join(ROOT, "out", "block_agreement_assets")), name)
    return load_scene(os.path.join(ROOT, "scenes", name), res=res)


def timed(call) -> float:
    """Milliseconds of one call, Dr.Jit synchronised on both sides."""
    import drjit as dr
    dr.sync_thread()
    start = time.perf_counter()
    call()
    dr.sync_thread()
    return 1000 * (time.perf_counter() - start)


def radii(args) -> None:
    from mitsuba_lab.plugins.integrators.common.footprint import pixel_footprint
    from mitsuba_lab.scene import make_integrator
    print("| scene | res | integrator | old r_1 (footprint) | new r_1 | new / old | r_density | cap | old ms | "
          "new ms |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for res in map(int, args.res.split(",")):
        for name in args.scenes.split(","):
            if name in USER_SCENES and res != int(args.res.split(",")[0]):
                continue                                   # (their own film: once)
            scene = load(name, res)
            sensor = scene.sensors()[0]
            for key, (plugin, params) in CONFIGS.items():
                integrator = make_integrator(plugin, {"max_depth": DEPTH, **params})
                new = integrator.default_radius(scene, sensor)
                again = integrator.default_radius(scene, sensor)
                assert new == again, (name, key, new, again)     # a function of the scene and settings
                probe = integrator.radius_probe
                # (best of 3 after those two calls, which compiled the kernels; a shared machine)
                ms_old = min(timed(lambda: pixel_footprint(scene, sensor)) for _ in range(3))
                ms_new = min(timed(lambda: integrator.default_radius(scene, sensor)) for _ in range(3))
                shown = "own" if name in USER_SCENES else res
                print(f"| {name} | {shown} | {key} | {probe.footprint:.4g} | {new:.4g} | {new / probe.footprint:.3g} | "
                      f"{probe.density:.4g} | {probe.cap:.4g} | {ms_old:.1f} | {ms_new:.0f} |", flush=True)


def images(args) -> int:
    import mitsuba_lab  # noqa: F401
    from mitsuba_lab.scene import make_integrator
    status = 0
    for name in args.scenes.split(","):
        scene = load(name, int(args.res.split(",")[0]))
        for key, (plugin, params) in CONFIGS.items():
            if key == "photon_20k":
                params = {**params, "passes": 2}
            integrator = make_integrator(plugin, {"max_depth": DEPTH, **params})
            image = np.array(integrator.render(scene, seed=SEED, spp=1 if plugin == "lab_photon" else SPP))
            path = os.path.join(args.save or args.compare, f"{name.replace('/', '_')}_{key}.npy")
            if args.save:
                os.makedirs(args.save, exist_ok=True)
                np.save(path, image)
                continue
            before = np.load(path)
            diff = float(np.abs(image - before).max())
            print(f"{name} {key}: max |diff| {diff:.3g} (image max {float(before.max()):.3g})", flush=True)
    return status


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("radii", "images"))
    parser.add_argument("--res", default="24,64")
    parser.add_argument("--scenes", default=",".join(SCENES + USER_SCENES))
    parser.add_argument("--save")
    parser.add_argument("--compare")
    args = parser.parse_args(argv)
    import mitsuba_lab
    mitsuba_lab.use_variant("llvm_ad_rgb")
    if args.what == "radii":
        radii(args)
        return 0
    if not (args.save or args.compare):
        parser.error("images needs --save DIR or --compare DIR")
    return images(args)


if __name__ == "__main__":
    sys.exit(main())
