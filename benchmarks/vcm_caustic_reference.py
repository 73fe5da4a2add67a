"""Is lab_vcm's extra light behind the volumetric caustic's glass ball real, and is its bias small?

lab_bdpt cannot sample light that reaches the fog through the ball and leaves it through the ball
to the camera (spot light, delta refractions, fog, delta refractions, pinhole camera); lab_vcm's
merging at the fog vertex can, and renders the ball's pixels about 19% brighter
(results/2026-11-29-volumetric-caustic.md). Two checks, each printing the mean over the pixels
whose camera rays hit the ball (``vcm_caustic_diagnosis.through_mask``), +- one standard error over
the seeds:

``bias``: lab_vcm (every technique, no pilot) on scenes/volumetric_caustic.xml with its radii
(surface and volume) at 1, 2 and 4 times the automatic r_1, at --iterations each. Merging's blur
grows with the radius (bias ~ r^2 where the light is smooth); a ball mean that does not move from r_1
to 4 r_1 bounds the bias of lab_vcm at r_1 and more iterations (its radii only shrink from there).

``variant``: the same scene with the spot replaced by a spherical area light (radius 0.2) of the
same intensity in a black tube that keeps its light to about the spot's cone. Its light is no longer
delta, so lab_bdpt samples the path (a camera subpath through the ball, the fog and the ball
again hits the light), as do Mitsuba's volpathmis and lab_vcm: the three should agree over the
ball's pixels (lab_bdpt's ~19% deficit belongs to the spot alone). The pixels that see the light
mirrored in the ball are left out (``reflection_mask``): a small sphere's reflection is a tiny
image of high radiance that made every estimator's ball mean jump from seed to seed.

    PYTHONPATH=src python benchmarks/vcm_caustic_reference.py bias [--iterations 64,256] [--seeds 4]
    PYTHONPATH=src python benchmarks/vcm_caustic_reference.py variant [--spp 256] [--seeds 4]

``rescore``: a sweep's stored renders of the volumetric caustic (``--sweep OUTDIR``) scored against
its reference (``--reference``: the cached EXR) per region of the scene's regions file and over the
ball's pixels and the others: floor-corrected relMSE (mean over seeds +- standard error), efficiency
1 / mean over seeds of (corrected relMSE x time), and the ball's mean over the reference's.

    PYTHONPATH=src python benchmarks/vcm_caustic_reference.py rescore --sweep OUTDIR --reference CACHE/KEY.exr
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import json
import tempfile
import tomllib

import mitsuba as mi
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from vcm_caustic_diagnosis import ROOT, pixel_rays, synced_render, through_mask  # noqa: E402

from mitsuba_lab.images import read_exr  # noqa: E402
from mitsuba_lab.metrics import fraction_rect_to_pixels  # noqa: E402
from mitsuba_lab.plugins.integrators.common.footprint import pixel_footprint  # noqa: E402
from mitsuba_lab.runtime import versions  # noqa: E402
from mitsuba_lab.scene import load_scene, make_integrator  # noqa: E402

SCENE = os.path.join(ROOT, "scenes", "volumetric_caustic.xml")
#: the spot's intensity (scenes/volumetric_caustic.xml) and the stand-in sphere's radius: large enough that
#: a camera subpath through the ball, the fog and the ball again hits it often (lab_bdpt's only technique for
#: that light), so that its estimate is not carried by rare samples
INTENSITY, SPHERE_RADIUS = (60.0, 55.0, 45.0), 0.2
#: the black tube around the sphere: radius, and how far it reaches below the light's centre
#: (half-opening atan(0.3 / 0.9) = 18 degrees from the sphere's centre, the spot's cutoff 16)
TUBE_RADIUS, TUBE_BELOW = 0.3, 0.9


def reflection_mask(scene, shape_id, res, sub=4) -> np.ndarray:
    """Pixels whose sensor rays (sub x sub per pixel) hit ``shape_id`` and, mirrored there, hit any
    other shape than the fog box (the sphere light or its tube): the light's reflection in the glass, a
    tiny image of high radiance that every estimator finds only by chance (all variance, the same light)."""
    out = np.zeros((res, res), dtype=bool)
    keep = [s for s in scene.shapes() if s.id() in (shape_id, "fog_box", "floor")]
    for ray in pixel_rays(scene, res, sub):
        si = scene.ray_intersect(ray)
        on = si.is_valid() & (si.shape == mi.ShapePtr(keep[[s.id() for s in keep].index(shape_id)]))
        d = mi.reflect(-ray.d, si.n)
        hit = scene.ray_intersect(si.spawn_ray(d))
        other = hit.is_valid()
        for s in keep:
            other &= hit.shape != mi.ShapePtr(s)
        out |= np.array(on & other).reshape(res, res)
    return out


def sphere_variant(text: str) -> str:
    """The scene's XML with the spot replaced by a sphere of radiance I / (pi r^2) (the spot's
    intensity I on axis) inside a black tube capped above, all in the fog."""
    radiance = ", ".join(f"{i / (np.pi * SPHERE_RADIUS ** 2):.6g}" for i in INTENSITY)
    black = '<bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf><ref name="exterior" id="fog"/>'
    light = f"""
    <shape type="sphere">
        <point name="center" x="0" y="3.2" z="0"/>
        <float name="radius" value="{SPHERE_RADIUS}"/>
        <emitter type="area"><rgb name="radiance" value="{radiance}"/></emitter>
        <ref name="exterior" id="fog"/>
    </shape>
    <shape type="cylinder">
        <point name="p0" x="0" y="{3.2 - TUBE_BELOW}" z="0"/>
        <point name="p1" x="0" y="3.3" z="0"/>
        <float name="radius" value="{TUBE_RADIUS}"/>
        {black}
    </shape>
    <shape type="disk">
        <transform name="to_world"><scale value="{TUBE_RADIUS}"/><rotate x="1" angle="-90"/><translate y="3.3"/></transform>
        {black}
    </shape>"""
    out, count = re.subn(r'<emitter type="spot">.*?</emitter>', light, text, flags=re.S)
    if count != 1:
        sys.exit("vcm_caustic_reference: the scene has no single spot emitter to replace")
    return out


def ball_means(scene, plugin, params, spp, seeds, mask):
    integrator = make_integrator(plugin, params)
    synced_render(scene, integrator, 1, 0)                 # warm-up: compile
    means, secs = [], 0.0
    for s in range(seeds):
        image, t = synced_render(scene, integrator, spp, 500 + s)
        means.append(float(image[mask].mean()))
        secs += t
    means = np.array(means)
    return means.mean(), means.std(ddof=1) / np.sqrt(seeds), secs, means


def rescore(sweep: str, reference: str, res: int, mask) -> None:
    """Print the per-region table of the sweep's stored renders (``rescore`` above)."""
    ref = read_exr(reference)[0][..., :3].astype(np.float64)
    var = read_exr(os.path.splitext(reference)[0] + ".var.exr")[0][..., :3].astype(np.float64)
    weight = 1.0 / (ref * ref + 1e-2)
    floor = (var * weight).mean(-1)
    masks = {"image": np.ones((res, res), bool)}
    with open(os.path.splitext(SCENE)[0] + ".regions.toml", "rb") as f:
        for name, rect in tomllib.load(f)["regions"].items():
            x0, y0, x1, y1 = fraction_rect_to_pixels(rect, res, res)
            masks[name] = np.zeros((res, res), bool)
            masks[name][y0:y1, x0:x1] = True
    masks["not ball"], masks["ball"] = ~mask, mask
    points = {}
    with open(os.path.join(sweep, "results.jsonl")) as f:
        for line in f:
            row = json.loads(line)
            if row.get("kind") == "run" and row.get("budget_s"):
                points.setdefault((row["budget_s"], row["strategy"]), {})[row["seed"]] = row
    print("cells: corrected relMSE +- se (efficiency 1 / mean(relMSE x s))")
    print(" | ".join(["budget", "strategy", "spp", "median s", "image MSE efficiency", *masks, "ball mean / reference's"]))
    for (budget, strategy), seeds in sorted(points.items()):
        rows = list(seeds.values())
        images = [read_exr(os.path.join(sweep, r["image"]))[0][..., :3].astype(np.float64) for r in rows]
        secs = np.array([r["wall_s"] for r in rows])
        mse = np.array([((im - ref) ** 2).mean() - var.mean() for im in images]) * secs
        cells = [f"{1 / mse.mean():.4g} +- {mse.std(ddof=1) / np.sqrt(len(mse)) / mse.mean() ** 2:.2g}"]
        for m in masks.values():
            errors = np.array([((im - ref) ** 2 * weight).mean(-1)[m].mean() - floor[m].mean() for im in images])
            cells.append(f"{errors.mean():.3g} +- {errors.std(ddof=1) / np.sqrt(len(errors)):.2g} "
                         f"({1 / np.mean(errors * secs):.3g})")
        ratios = np.array([im[mask].mean() / ref[mask].mean() for im in images])
        print(" | ".join([f"{budget:g} s", strategy, str(rows[0]["spp"]), f"{np.median(secs):.2f}", *cells,
                          f"{ratios.mean():.3f} +- {ratios.std(ddof=1) / np.sqrt(len(ratios)):.3f}"]), flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("check", choices=("bias", "variant", "rescore"))
    parser.add_argument("--sweep", help="rescore: the sweep's output folder")
    parser.add_argument("--reference", help="rescore: the reference's cached EXR (its .var.exr beside it)")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--max-depth", type=int, default=12)
    parser.add_argument("--iterations", default="64,256", help="bias: comma-separated iteration counts")
    parser.add_argument("--multipliers", default="1,2,4", help="bias: radii as multiples of the automatic r_1")
    parser.add_argument("--spp", type=int, default=256, help="variant: samples per pixel per seed")
    parser.add_argument("--strategies", default="lab_bdpt,lab_vcm,volpathmis", help="variant: which to render")
    parser.add_argument("--seeds", type=int, default=4)
    args = parser.parse_args(argv)
    print(versions())
    if args.check == "rescore":
        if not (args.sweep and args.reference):
            parser.error("rescore needs --sweep and --reference")
        scene = load_scene(SCENE, res=args.res, max_depth=args.max_depth)
        rescore(args.sweep, args.reference, args.res, through_mask(scene, "ball", args.res))
        return 0
    if args.check == "bias":
        scene = load_scene(SCENE, res=args.res, max_depth=args.max_depth)
        mask = through_mask(scene, "ball", args.res)
        r1 = pixel_footprint(scene, scene.sensors()[0])
        print(f"volumetric_caustic {args.res}^2, max_depth {args.max_depth}, {mask.sum()} ball pixels, r_1 {r1:.4g}, "
              f"{args.seeds} seeds: lab_vcm pilot = false, ball-pixel mean +- se")
        for n in (int(v) for v in args.iterations.split(",")):
            for m in (float(v) for v in args.multipliers.split(",")):
                params = {"max_depth": args.max_depth, "pilot": False, "radius": m * r1, "radius_volume": m * r1}
                mean, se, secs, _ = ball_means(scene, "lab_vcm", params, n, args.seeds, mask)
                print(f"iterations {n:5d} radius {m:g} r_1 = {m * r1:.4f}: {mean:.5f} +- {se:.5f} ({secs:.1f} s)", flush=True)
        return 0
    with open(SCENE) as f:
        text = sphere_variant(f.read())
    with tempfile.NamedTemporaryFile("w", suffix=".xml", dir=os.path.dirname(SCENE), delete=False) as f:
        f.write(text)                                       # beside the original: its relative paths hold
    try:
        scene = load_scene(f.name, res=args.res, max_depth=args.max_depth)
    finally:
        os.unlink(f.name)
    mask = through_mask(scene, "ball", args.res)
    glint = reflection_mask(scene, "ball", args.res)
    glint = glint | np.roll(glint, 1, 0) | np.roll(glint, -1, 0) | np.roll(glint, 1, 1) | np.roll(glint, -1, 1)
    mask &= ~glint                                          # with a pixel's margin
    print(f"volumetric_caustic with a sphere light (r {SPHERE_RADIUS}) in a tube, {args.res}^2, max_depth "
          f"{args.max_depth}, {mask.sum()} ball pixels (its reflection left out), {args.spp} spp x {args.seeds} seeds: ball-pixel mean +- se")
    for plugin in args.strategies.split(","):
        params = {"max_depth": args.max_depth, **({"pilot": False} if plugin == "lab_vcm" else {})}
        mean, se, secs, means = ball_means(scene, plugin, params, args.spp, args.seeds, mask)
        print(f"{plugin}: {mean:.5f} +- {se:.5f} ({secs:.1f} s); seeds {' '.join(f'{v:.4f}' for v in means)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
