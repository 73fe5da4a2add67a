"""Why lab_vcm loses to lab_bdpt over the volumetric caustic's image: its variants side by side.

Each variant renders scenes/volumetric_caustic.xml (or --scene) at --spp samples per pixel for
--seeds seeds, the variants alternating within each seed (one loaded run: the machine's noise
hits them alike), every clock stopped after dr.eval + dr.sync_thread. Against a reference of
lab_bdpt (--ref-chunks x --ref-spp, independent seeds; cached in --reference), per variant:
its mean time and phases (``bdpt_stats()``: light pass, grids, camera pass, pilot), and the
floor-corrected relMSE per region of the scene's regions file, over the whole image and split
into the pixels that see the specular shape --through (default the ball) and the others, with
the image mean over the reference's in the through pixels. Efficiency = 1 / (relMSE x time).

The through pixels need care: lab_bdpt (the reference) cannot sample light that reaches the
fog through the ball and leaves it through the ball again (a point light and a pinhole camera
with delta refractions on both sides of the medium vertex); merging can, so lab_vcm's image
there is brighter than the reference, and the excess does not vanish as its radius shrinks
(the ``fixed_r`` variants: alpha 0.999, a fixed radius).

    PYTHONPATH=src python benchmarks/vcm_caustic_diagnosis.py [--spp 64] [--seeds 8] [--variants bdpt,vcm,...]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import tomllib

import drjit as dr
import mitsuba as mi
import numpy as np

import mitsuba_lab  # noqa: F401  (the variant, the lab plugins)
from mitsuba_lab.metrics import fraction_rect_to_pixels
from mitsuba_lab.plugins.integrators.common.footprint import pixel_footprint
from mitsuba_lab.runtime import versions
from mitsuba_lab.scene import load_scene, make_integrator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: r_1 before the footprint looked through null-BSDF surfaces (a pixel at the fog box's far walls, 64x64)
OLD_RADIUS = 0.0811


def variants(r1: float) -> dict:
    """name -> (plugin, parameters): lab_bdpt, lab_vcm's defaults and the variants that isolate
    one cause each (``r1``: this scene's automatic radius)."""
    return {
        "bdpt": ("lab_bdpt", {}),
        "vcm": ("lab_vcm", {}),                                            # defaults: the pilot
        "vcm_old_radius": ("lab_vcm", {"radius": OLD_RADIUS}),             # the radius before the footprint fix
        "vcm_all": ("lab_vcm", {"pilot": False}),                         # every technique, no pilot
        "vcm_aim_0.5": ("lab_vcm", {"pilot": False, "aim": 0.5}),          # lab_bdpt's aim
        "vcm_no_volume_merge": ("lab_vcm", {"pilot": False, "radius": r1, "radius_volume": 1e-5}),
        "vcm_no_surface_merge": ("lab_vcm", {"pilot": False, "radius": 1e-5, "radius_volume": r1}),
        "vcm_bpt": ("lab_vcm", {"mode": "bpt"}),                           # lab_vcm's lab_bdpt
        "fixed_r_0.04": ("lab_vcm", {"pilot": False, "radius": 0.04, "radius_volume": 0.04, "alpha": 0.999}),
        "fixed_r_0.02": ("lab_vcm", {"pilot": False, "radius": 0.02, "radius_volume": 0.02, "alpha": 0.999}),
    }


def synced_render(scene, integrator, spp, seed):
    start = time.perf_counter()
    image = mi.render(scene, integrator=integrator, spp=spp, seed=seed)
    dr.eval(image)
    dr.sync_thread()
    return np.array(image)[..., :3], time.perf_counter() - start


def reference(scene, path, chunks, spp, depth):
    """(mean, variance of the mean) of lab_bdpt in ``chunks`` renders of ``spp``, cached at ``path``."""
    if path and os.path.isfile(path):
        stack = np.load(path)
    else:
        integrator = make_integrator("lab_bdpt", {"max_depth": depth})
        stack = np.array([synced_render(scene, integrator, spp, 7000 + i)[0] for i in range(chunks)])
        if path:
            np.save(path, stack)
    return stack.mean(0), stack.var(0, ddof=1) / len(stack)


def pixel_rays(scene, res, sub=4):
    """The sensor's rays through sub x sub points of every pixel of a res x res film: one batch
    (a ray per pixel, in row-major order) per point."""
    ys, xs = np.meshgrid(np.arange(res), np.arange(res), indexing="ij")
    sensor = scene.sensors()[0]
    for a in range(sub):
        for b in range(sub):
            pos = mi.Point2f(mi.Float((xs.ravel() + (a + 0.5) / sub) / res),
                             mi.Float((ys.ravel() + (b + 0.5) / sub) / res))
            yield sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5))[0]


def through_mask(scene, shape_id, res, sub=4) -> np.ndarray:
    """Pixels whose sensor rays (sub x sub per pixel) hit the shape ``shape_id`` first."""
    shapes = [s for s in scene.shapes() if s.id() == shape_id]
    if not shapes:
        sys.exit(f"vcm_caustic_diagnosis: the scene has no shape with id '{shape_id}'")
    hit = np.zeros((res, res), dtype=bool)
    for ray in pixel_rays(scene, res, sub):
        si = scene.ray_intersect(ray)
        hit |= np.array(si.is_valid() & (si.shape == mi.ShapePtr(shapes[0]))).reshape(res, res)
    return hit


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scene", default=os.path.join(ROOT, "scenes", "volumetric_caustic.xml"))
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--max-depth", type=int, default=12)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--ref-spp", type=int, default=512)
    parser.add_argument("--ref-chunks", type=int, default=8)
    parser.add_argument("--reference", default="", help="a .npy to cache the reference's chunks in")
    parser.add_argument("--through", default="ball", help="id of the specular shape whose pixels are split off")
    parser.add_argument("--variants", default="", help="comma-separated names (default: all)")
    args = parser.parse_args(argv)
    scene = load_scene(args.scene, res=args.res, max_depth=args.max_depth)
    r1 = pixel_footprint(scene, scene.sensors()[0])
    table = variants(r1)
    names = [n for n in args.variants.split(",") if n] or list(table)
    unknown = [n for n in names if n not in table]
    if unknown:
        parser.error(f"unknown variants {unknown}; known: {', '.join(table)}")
    ref, ref_var = reference(scene, args.reference, args.ref_chunks, args.ref_spp, args.max_depth)
    weight = 1.0 / (ref * ref + 1e-2)
    floor = (ref_var * weight).mean(-1)                     # the reference's own relMSE per pixel
    regions_file = os.path.splitext(args.scene)[0] + ".regions.toml"
    masks = {"image": np.ones((args.res, args.res), bool)}
    with open(regions_file, "rb") as f:
        for name, rect in tomllib.load(f)["regions"].items():
            x0, y0, x1, y1 = fraction_rect_to_pixels(rect, args.res, args.res)
            masks[name] = np.zeros((args.res, args.res), bool)
            masks[name][y0:y1, x0:x1] = True
    through = through_mask(scene, args.through, args.res)
    masks[f"not {args.through}"], masks[args.through] = ~through, through

    integrators = {}
    for name in names:
        plugin, params = table[name]
        integrators[name] = make_integrator(plugin, {"max_depth": args.max_depth, **params})
        synced_render(scene, integrators[name], args.spp, 1)            # warm-up: compile
    runs = {name: [] for name in names}
    for s in range(args.seeds):
        for name, integrator in integrators.items():
            image, secs = synced_render(scene, integrator, args.spp, 100 + s)
            stats = integrator.bdpt_stats()
            runs[name].append((image, secs, [stats.get(k, 0.0) for k in ("light_s", "grid_s", "camera_s", "pilot_s")]))

    print(versions())
    print(f"{os.path.basename(args.scene)} {args.res}x{args.res}, max_depth {args.max_depth}, {args.spp} spp x "
          f"{args.seeds} seeds; automatic r_1 {r1:.4g}; reference lab_bdpt {args.ref_chunks} x {args.ref_spp} spp; "
          f"{through.sum()} pixels see '{args.through}'")
    print("cells: floor-corrected relMSE (mean over seeds +- standard error) and efficiency 1 / (relMSE x mean time)")
    print(" | ".join(["variant", "time s", "light/grid/camera/pilot s", *masks, f"mean/ref in {args.through}"]))
    for name, rows in runs.items():
        secs = float(np.mean([r[1] for r in rows]))
        phases = np.mean([r[2] for r in rows], axis=0)
        cells = []
        for mask in masks.values():
            errors = np.array([((r[0] - ref) ** 2 * weight).mean(-1)[mask].mean() - floor[mask].mean() for r in rows])
            mean = errors.mean()
            cells.append(f"{mean:.3g} +- {errors.std(ddof=1) / np.sqrt(len(errors)):.2g} ({1 / (mean * secs):.3g})")
        ratios = [r[0][through].mean() / ref[through].mean() for r in rows]
        print(" | ".join([name, f"{secs:.2f}", "/".join(f"{p:.2f}" for p in phases), *cells,
                          f"{np.mean(ratios):.3f} +- {np.std(ratios, ddof=1) / np.sqrt(len(ratios)):.3f}"]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
