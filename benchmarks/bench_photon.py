"""lab_photon: photon-tracing throughput against Mitsuba's `ptracer`, gather cost per pass, and the
caustic's relMSE at (roughly) equal time against lab_mis.

1. Throughput (per scene): `ptracer` renders W x H x spp light paths; lab_photon traces
   photons_per_pass x passes photons (``photon_stats()['trace_s']``, timed after dr.eval +
   dr.sync_thread; it includes storing the records and reading back their count). Both use
   the same max_depth and rr_depth. Warm-up once (compilation), then --rounds alternating
   rounds; medians. Ratio = lab_photon seconds per photon / ptracer seconds per light path
   ptracer does more per path (a camera connection and a splat per vertex), lab_photon
   stores a record per smooth vertex.
2. Gather cost: grid build and camera pass (gather) seconds per pass, from photon_stats().
3. Caustic (scenes/caustic.xml, region `caustic` of caustic.regions.toml): a path-traced
   reference (Mitsuba `path`, --ref-spp in 16 chunks, with its noise floor from the chunks'
   spread), built and cached by the sweep runner's reference cache
   (``mitsuba_lab.experiment.reference.get_reference``; ``$MITSUBA_LAB_CACHE`` or
   ~/.cache/mitsuba_lab/references), so a sweep of the same scene shares it. Each method gets the time budget --budget seconds:
   its sample count (spp for lab_mis, passes for lab_photon) is calibrated by two runs to
   fill the budget, then --seeds renders are timed. lab_photon runs both direct modes with
   --caustic-radius (a sharp caustic wants a radius below the pixel-footprint default) and
   --caustic-spp camera samples per pass, plus direct=nee with the automatic radius.
   Reported: relMSE in the region (raw and minus the reference's floor), median time, and
   the ratio lab_mis / lab_photon of relMSE x time (the equal-time relMSE ratio, robust to
   the budgets not being hit exactly). lab_mis's caustic error is heavy-tailed, so it is
   also given as expected from the reference chunks' variance (same estimator family).

    .venv/bin/python benchmarks/bench_photon.py [--rounds 5] [--budget 4] [--seeds 6]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import tomllib

import drjit as dr
import mitsuba as mi
import numpy as np

import mitsuba_lab  # noqa: F401
from mitsuba_lab.experiment.pipeline.config import DEFAULT_CACHE, PluginSpec
from mitsuba_lab.experiment.pipeline.reference import get_reference
from mitsuba_lab.metrics import fraction_rect_to_pixels, region
from mitsuba_lab.render import render
from mitsuba_lab.runtime import versions
from mitsuba_lab.scene import load_scene, make_integrator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CACHE = os.path.abspath(os.path.expanduser(os.environ.get("MITSUBA_LAB_CACHE") or DEFAULT_CACHE))
#: Reference chunks: their spread gives the reference's noise floor.
REF_CHUNKS = 16


def log(*args):
    print(*args, file=sys.stderr, flush=True)


def timed(fn):
    dr.sync_thread()
    start = time.perf_counter()
    out = fn()
    dr.eval(out)
    dr.sync_thread()
    return out, time.perf_counter() - start


def throughput(scene_name, res, spp, photons, passes, depth, rounds):
    scene = load_scene(os.path.join(ROOT, "scenes", scene_name), res=res)
    common = {"max_depth": depth, "rr_depth": 5}
    ptracer = make_integrator("ptracer", common)
    photon = {mode: make_integrator("lab_photon", {**common, "direct": mode, "photons_per_pass": photons,
                                                   "passes": passes}) for mode in ("photons", "nee")}
    paths = res * res * spp
    render(scene, ptracer, spp=spp, seed=0)
    for integrator in photon.values():
        render(scene, integrator, spp=1, seed=0)
    t_pt, t_ph = [], {m: [] for m in photon}
    gather, grid, ratio = {m: [] for m in photon}, {m: [] for m in photon}, {m: [] for m in photon}
    for r in range(rounds):
        _, stats = render(scene, ptracer, spp=spp, seed=1 + r)
        t_pt.append(stats.wall_s / paths)
        for mode, integrator in photon.items():
            render(scene, integrator, spp=1, seed=1 + r)
            s = integrator.photon_stats()
            t_ph[mode].append(s["trace_s"] / s["photons_traced"])
            gather[mode].append(s["gather_s_per_pass"])
            grid[mode].append(s["grid_s_per_pass"])
            ratio[mode].append(t_ph[mode][-1] / t_pt[-1])
        log(f"round {r}: ptracer {1e9 * t_pt[-1]:.0f} ns/path, " + ", ".join(
            f"photon[{m}] {1e9 * t_ph[m][-1]:.0f} ns/photon" for m in photon))
    med = statistics.median
    print(f"\n{scene_name} {res}x{res}, max_depth {depth}, rr_depth 5, {rounds} alternating rounds")
    print(f"  ptracer: {paths:,} light paths per render, median {1e9 * med(t_pt):.0f} ns/path "
          f"= {1e-6 / med(t_pt):.2f} M paths/s")
    for mode in photon:
        print(f"  lab_photon direct={mode}: {photons:,} photons x {passes} passes, median "
              f"{1e9 * med(t_ph[mode]):.0f} ns/photon = {1e-6 / med(t_ph[mode]):.2f} M photons/s; "
              f"time ratio to ptracer per path (median of rounds) {med(ratio[mode]):.2f}; "
              f"grid {1e3 * med(grid[mode]):.1f} ms/pass, gather (camera pass, {res}x{res} @ 1 spp) "
              f"{1e3 * med(gather[mode]):.1f} ms/pass")


def caustic_reference(res, ref_spp, depth):
    """The caustic scene's reference from the runner's cache (built on a miss): `path` with
    ``ref_spp`` samples per pixel in REF_CHUNKS chunks (mean image, variance of the mean)."""
    spp = ref_spp - ref_spp % REF_CHUNKS                             # the chunks must divide spp
    reference, cached = get_reference(os.path.join(ROOT, "scenes", "caustic.xml"), None, {"res": res},
                                      PluginSpec("reference", "path", {"max_depth": depth}), spp, REF_CHUNKS,
                                      CACHE, progress=lambda k, n: log(f"reference chunk {k}/{n}"))
    log(f"reference {'from the cache' if cached else 'built'}: {CACHE}/{reference.key}.exr")
    return reference


def caustic(res, ref_spp, depth, budget, seeds, photons, spp, radius):
    reference = caustic_reference(res, ref_spp, depth)
    with open(os.path.join(ROOT, "scenes", "caustic.regions.toml"), "rb") as f:
        rect = fraction_rect_to_pixels(tomllib.load(f)["regions"]["caustic"], res, res)
    ref_r = region(reference.image, rect).astype(np.float64)
    var_mean = region(reference.variance, rect)
    floor = float(np.mean(var_mean / ref_r**2))

    def rel(img):
        return float(np.mean((region(img, rect) - ref_r) ** 2 / ref_r**2))

    scene = load_scene(os.path.join(ROOT, "scenes", "caustic.xml"), res=res)

    def photon(direct, radius):
        return lambda n: (make_integrator("lab_photon", {
            "max_depth": depth, "direct": direct, "photons_per_pass": photons, "passes": n,
            "radius": radius}), spp)

    methods = {   # name -> (integrator and spp for a count n, what n counts)
        "lab_mis": (lambda n: (make_integrator("lab_mis", {"max_depth": depth}), n), "spp"),
        f"lab_photon(nee,r={radius})": (photon("nee", radius), "passes"),
        f"lab_photon(photons,r={radius})": (photon("photons", radius), "passes"),
        "lab_photon(nee,r=auto)": (photon("nee", 0.0), "passes"),
    }
    print(f"\ncaustic.xml {res}x{res}, max_depth {depth}, region {rect} (x0, y0, x1, y1); reference: path "
          f"{reference.meta['spp']} spp in {REF_CHUNKS} chunks, region mean {ref_r.mean():.3f}, noise floor "
          f"(per-pixel relMSE of the reference) {floor:.2e}; budget {budget} s, {seeds} seeds; lab_photon: "
          f"{photons} photons "
          f"and {spp} spp per pass")
    results = {}
    for name, (make, unit) in methods.items():
        n = 4
        for _ in range(2):                                   # calibrate twice: cost per unit at scale
            integrator, n_spp = make(n)
            mi.render(scene, integrator=integrator, spp=n_spp, seed=0)          # compile
            _, t = timed(lambda: mi.render(scene, integrator=integrator, spp=n_spp, seed=1))
            n = max(1, int(round(n * budget / t)))
        integrator, n_spp = make(n)
        errs, times = [], []
        for s in range(seeds):
            img, t = timed(lambda: mi.render(scene, integrator=integrator, spp=n_spp, seed=100 + s))
            errs.append(rel(np.array(img)))
            times.append(t)
            log(f"{name} {unit}={n} seed {s}: {t:.2f} s, relMSE {errs[-1]:.3e}")
        results[name] = (n, unit, float(np.mean(errs)), statistics.median(times))
    print(f"  {'method':32s} {'count':>12s} {'median s':>9s} {'relMSE':>10s} {'- floor':>10s} {'relMSE x s':>11s}")
    for name, (n, unit, err, t) in results.items():
        print(f"  {name:32s} {f'{n} {unit}':>12s} {t:9.2f} {err:10.3e} {err - floor:10.3e} {err * t:11.3e}")
    # lab_mis's error on the caustic is heavy-tailed, so a few seeds estimate it poorly. Mitsuba's
    # `path` is the same estimator (BSDF sampling + NEE, power heuristic; test_consistency checks
    # they agree), so the reference's 16 chunks give its variance per sample far more reliably.
    n_mis = results["lab_mis"][0]
    chunk_spp = reference.meta["spp"] // REF_CHUNKS
    chunk_variance = reference.variance * REF_CHUNKS                  # per chunk, from the mean's
    expected = float(np.mean(region(chunk_variance, rect) * chunk_spp / n_mis / ref_r**2))
    print(f"  lab_mis expected relMSE at {n_mis} spp from the reference chunks' variance: {expected:.3e}")
    results["lab_mis(expected)"] = (n_mis, "spp", expected + floor, results["lab_mis"][3])
    for base_name in ("lab_mis", "lab_mis(expected)"):
        base = results[base_name]
        for name, (n, unit, err, t) in results.items():
            if name.startswith("lab_photon"):
                print(f"  {base_name} / {name}: relMSE x time ratio {base[2] * base[3] / (err * t):.1f} "
                      f"(floor subtracted: {(base[2] - floor) * base[3] / max((err - floor) * t, 1e-30):.1f}); "
                      f"plain relMSE ratio {base[2] / err:.1f} at times {base[3]:.2f} s vs {t:.2f} s")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5, help="alternating rounds for throughput (default: 5)")
    parser.add_argument("--budget", type=float, default=4.0, help="caustic time budget in seconds (default: 4)")
    parser.add_argument("--seeds", type=int, default=6, help="timed renders per method on the caustic (default: 6)")
    parser.add_argument("--ref-spp", type=int, default=262144,
                        help="caustic reference spp, in 16 chunks (default: 262144; built once, then read "
                             "from the runner's reference cache)")
    parser.add_argument("--caustic-photons", type=int, default=200_000,
                        help="photons per pass on the caustic (default: 200000)")
    parser.add_argument("--caustic-spp", type=int, default=8,
                        help="camera samples per pixel per pass on the caustic (default: 8)")
    parser.add_argument("--caustic-radius", type=float, default=0.03,
                        help="first-pass radius on the caustic; r=auto is run too (default: 0.03)")
    parser.add_argument("--skip", choices=("throughput", "caustic"), action="append", default=[])
    args = parser.parse_args(argv)
    print(versions())
    if "throughput" not in args.skip:
        throughput("cornell_box.xml", 64, 64, 262_144, 4, 8, args.rounds)
        throughput("caustic.xml", 64, 64, 262_144, 4, 8, args.rounds)
    if "caustic" not in args.skip:
        caustic(64, args.ref_spp, 8, args.budget, args.seeds, args.caustic_photons, args.caustic_spp,
                args.caustic_radius)
    return 0


if __name__ == "__main__":
    sys.exit(main())
