"""lab_vcm's pilot costs: nanoseconds per unit of counted work, fitted to measured pass times.

lab_vcm's pilot (``pilot = true``, ``pilot_costs = counted``) prices a render by the work its
pilot renders counted (``work_counts()``: camera, extension and shadow rays, connections, merge
lookups, light-subpath and sensor rays, stored light vertices, passes) times a cost per kind, the
``cost_*`` parameters of ``params.LAB_VCM``. This script measures those costs once: per scene,
lab_vcm in each mode (which does a different mix of the kinds) and lab_mis (path tracing alone,
the pilot's other choice) render at 1 and at --spp iterations, each timed after a warm-up, in
--rounds alternating rounds (medians); then non-negative least squares, relative to each time,
fits

* the light passes + grids (``light_s + grid_s``) to light rays, sensor rays, stored vertices and
  passes,
* the camera passes (``camera_s``) to camera, extension and shadow rays, connections, merge
  lookups and passes,
* lab_mis's render time to its rays (``ray_counts()``: camera + extension, and shadow) and one
  render's fixed cost,

and prints the fitted costs (ns; a pass's in ns too) and each row's fitted / measured time. The
defaults in ``params.LAB_VCM`` are one run of it (see its docstring there); the machine is
shared, so single timings are noisy and only the order of magnitude matters to the pilot.

    .venv/bin/python benchmarks/bench_pilot_costs.py [--rounds 3] [--res 48] [--spp 8] [--quick]

``--shares`` measures something else, without a clock: the pilot's share of the render's counted
work (``pilot_share``'s bound) and its choice, with lab_vcm's defaults (and ``--pilot-share``),
over ``--share-res`` x ``--share-spp`` on ``--share-scenes``; with ``--predict``, the pilot alone
(``Pilot.run``) and the render's counted cost predicted from 8 iterations of the chosen estimator
(spp x its counted seconds per iteration, plus its passes), for sizes whose render would be long.

    .venv/bin/python benchmarks/bench_pilot_costs.py --shares [--pilot-share 0.125] [--predict]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np
from scipy.optimize import nnls

import mitsuba_lab  # noqa: F401  (selects the variant, registers the lab plugins)
from mitsuba_lab.runtime import versions
from mitsuba_lab.scene import load_scene, make_integrator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ("cornell_box.xml", "caustic.xml", "stiff/light_in_glass.xml")
MODES = ("vcm", "bpt", "bpm", "pt", "lt")
LIGHT_KINDS = ("passes", "light", "sensor", "light_vertices")
CAMERA_KINDS = ("passes", "camera", "extension", "shadow", "connection", "merge")
PATH_KINDS = ("renders", "path_rays", "shadow")


def lab_vcm_row(scene, mode, spp, seed, depth, radius):
    """(light + grid seconds, camera seconds, counts) of one lab_vcm render with work counting."""
    integrator = make_integrator("lab_vcm", {"mode": mode, "max_depth": depth, "radius": radius, "pilot": False})
    mi.render(scene, integrator=integrator, spp=spp, seed=seed)
    stats = integrator.bdpt_stats()
    return stats["light_s"] + stats["grid_s"], stats["camera_s"], integrator.work_counts()


def lab_mis_row(scene, spp, seed, depth):
    """(seconds, counts) of one lab_mis render, after dr.eval + dr.sync_thread."""
    integrator = make_integrator("lab_mis", {"max_depth": depth})
    integrator.ray_counts()
    start = time.perf_counter()
    image = mi.render(scene, integrator=integrator, spp=spp, seed=seed)
    dr.eval(image)
    dr.sync_thread()
    seconds = time.perf_counter() - start
    rays = integrator.ray_counts()
    return seconds, {"renders": 1, "path_rays": rays["camera"] + rays["extension"], "shadow": rays["shadow"]}


def fit(rows, kinds):
    """Non-negative costs per kind (seconds per unit) minimising the relative squared error."""
    a = np.array([[counts.get(k, 0) for k in kinds] for _, counts in rows], dtype=float)
    t = np.array([seconds for seconds, _ in rows])
    costs, _ = nnls(a / t[:, None], np.ones(len(t)))
    return dict(zip(kinds, costs)), a @ costs / t


def shares(scenes, resolutions, spps, share: float, predict: bool, depth: int, seed: int = 1) -> None:
    """Print, per scene, film size and spp: the pilot's iterations per render, its counted seconds,
    the render's, the pilot's share of their sum and the choice."""
    from mitsuba_lab.plugins.integrators.common.footprint import pixel_footprint
    from mitsuba_lab.plugins.integrators.vcm import selection

    print(f"pilot_share {share:g}, max_depth {depth}, seed {seed}; counted seconds (cost_* x counts), no clock")
    print("| scene | film | spp | pilot iterations / render | pilot (counted s) | render (counted s) | pilot share "
          "| choice |")
    print("|---|---|---|---|---|---|---|---|")
    for name in scenes:
        for res in resolutions:
            scene = load_scene(os.path.join(ROOT, "scenes", name), res=res)
            sensor = scene.sensors()[0]
            for spp in spps:
                integrator = make_integrator("lab_vcm", {"count_rays": True, "max_depth": depth,
                                                         "pilot_share": share})
                values, note = integrator.values, ""
                if not predict:
                    mi.render(scene, integrator=integrator, spp=spp, seed=seed)
                    stats = integrator.bdpt_stats()
                    choice = (None if stats["chose_path_tracing"]
                              else stats["light_paths_chosen"] / values["light_paths"])
                    pilot, render = stats["pilot_counted_s"], stats["render_counted_s"]
                    iterations = stats["pilot_iterations"]
                else:
                    integrator.first_radius = values["radius"] or pixel_footprint(scene, sensor)
                    pilot_ = integrator.pilot
                    choice = pilot_.run(scene, sensor, seed, spp, pilot_.companion(), pilot_.path_tracer())[0]
                    pilot, iterations, note = pilot_.counted_s, pilot_.iterations, " (predicted)"
                    if choice is None:
                        lab_mis = make_integrator("lab_mis", {"count_rays": True, "max_depth": depth})
                        lab_mis.ray_counts()
                        mi.render(scene, integrator=lab_mis, spp=8, seed=seed)
                        render = selection.seconds(lab_mis.ray_counts(), "path_tracing", values) * spp / 8
                    else:
                        every = pilot_.companion(choice)
                        mi.render(scene, integrator=every, spp=8, seed=seed)
                        work = every.work_counts()
                        per_iteration = (selection.seconds(work, "light", values)
                                         + selection.seconds(work, "camera", values)) / 8
                        passes = -(-spp // every.pass_iterations(res * res))
                        render = spp * per_iteration + passes * 1e-9 * values["cost_pass"]
                chosen = "path tracing" if choice is None else f"every technique, {choice * values['light_paths']:g}"
                print(f"| {name} | {res}x{res} | {spp} | {iterations} | {pilot:.3f} | {render:.3f}{note} | "
                      f"{pilot / (pilot + render):.3f} | {chosen} |", flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3, help="alternating timed rounds (default: 3)")
    parser.add_argument("--res", type=int, default=48, help="film width and height (default: 48)")
    parser.add_argument("--spp", type=int, default=8, help="iterations of the larger renders (default: 8)")
    parser.add_argument("--max-depth", type=int, default=8, help="max_depth (default: 8)")
    parser.add_argument("--radius", type=float, default=0.03, help="lab_vcm's first radius (default: 0.03)")
    parser.add_argument("--quick", action="store_true", help="smoke run: 16x16, 2 spp, 1 round, the Cornell box")
    parser.add_argument("--shares", action="store_true", help="the pilot's counted share of the render instead")
    parser.add_argument("--pilot-share", type=float, default=0.125, help="with --shares: pilot_share (default 1/8)")
    parser.add_argument("--predict", action="store_true", help="with --shares: the render's counted cost predicted")
    parser.add_argument("--share-scenes", default="cornell_box.xml,caustic.xml", help="with --shares (comma-separated)")
    parser.add_argument("--share-res", default="16,32,64", help="with --shares: film sizes (comma-separated)")
    parser.add_argument("--share-spp", default="4,16,64,256", help="with --shares: spp (comma-separated)")
    args = parser.parse_args(argv)
    if args.shares:
        print(versions())
        shares(args.share_scenes.split(","), [int(r) for r in args.share_res.split(",")],
               [int(n) for n in args.share_spp.split(",")], args.pilot_share, args.predict, args.max_depth)
        return 0
    scenes = SCENES
    if args.quick:
        args.res, args.spp, args.rounds, scenes = 16, 2, 1, SCENES[:1]
    print(versions())
    print(f"{args.res}x{args.res}, 1 and {args.spp} iterations, max_depth {args.max_depth}, medians of "
          f"{args.rounds} rounds, {dr.thread_count()} threads")
    light_rows, camera_rows, path_rows = [], [], []
    for name in scenes:
        scene = load_scene(os.path.join(ROOT, "scenes", name), res=args.res)
        for mode in MODES:                                      # warm-up: compile every kernel
            lab_vcm_row(scene, mode, args.spp, 1, args.max_depth, args.radius)
        lab_mis_row(scene, args.spp, 1, args.max_depth)
        for spp in (1, args.spp):
            runs = {mode: [] for mode in MODES + ("mis",)}
            for r in range(args.rounds):
                for mode in MODES:
                    runs[mode].append(lab_vcm_row(scene, mode, spp, 100 + r, args.max_depth, args.radius))
                runs["mis"].append(lab_mis_row(scene, spp, 100 + r, args.max_depth))
            for mode in MODES:
                light = statistics.median(x[0] for x in runs[mode])
                camera = statistics.median(x[1] for x in runs[mode])
                counts = runs[mode][0][2]                       # (the same every round but the seed)
                if counts["light"]:
                    light_rows.append((light, counts))
                if counts["camera"]:
                    camera_rows.append((camera, counts))
            path_rows.append((statistics.median(x[0] for x in runs["mis"]), runs["mis"][0][1]))
            print(f"{name} {spp} spp: measured", flush=True)
    for title, rows, kinds in (("light passes + grids", light_rows, LIGHT_KINDS),
                               ("camera passes", camera_rows, CAMERA_KINDS),
                               ("lab_mis renders", path_rows, PATH_KINDS)):
        costs, ratios = fit(rows, kinds)
        print(f"{title}: " + ", ".join(f"{k} {1e9 * c:.4g} ns" for k, c in costs.items()))
        print(f"  fitted / measured time per row: {' '.join(f'{r:.2f}' for r in ratios)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
