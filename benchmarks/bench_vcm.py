"""lab_vcm: one iteration's cost split into light tracing, grid, camera subpaths with their
connections, and merging; its light tracing per path against Mitsuba's `ptracer`.

Per scene, one render of --spp iterations (one sample per pixel each) of lab_vcm, mode `vcm`,
and the same render in mode `bpt` (the same light and camera subpaths: merging left out), each
timed after a warm-up render of the same size, in --rounds alternating rounds (medians):

* light: ``bdpt_stats()['light_s']``, the light passes (trace, light tracing's splats, storing
  every vertex with a smooth lobe), per iteration and per light subpath;
* grid: ``grid_s``, bucketing the stored vertices of each pass (a counting sort);
* camera + connections: mode `bpt`'s ``camera_s`` (camera subpaths, emitter hits, NEE, the
  connections to the lane's light subpath);
* merging: mode `vcm`'s ``camera_s`` minus mode `bpt`'s (the gathers from the grid and the
  third MIS quantity);
* merged: the share of stored light vertices in the grids (``merging_vertices``; below 1 with
  --merge-vertices caustic, which merges only those reached through a delta lobe);
* ptracer: Mitsuba's `ptracer` rendering W x H x spp light paths, per light path, against lab's
  light pass per light subpath (same max_depth; the Russian roulettes differ).

In a scene with participating media (issue 46; e.g. ``--scenes volumetric_caustic.xml``) a second
table splits the media's phases, and `volpath` stands in for `path` (`ptracer` has no media):

* in media: the share of stored light vertices that lie in media (``medium_merging_vertices``),
  and the light pass per light subpath (traced through the media);
* vol grid: ``volume_grid_s``, of ``grid_s`` the grid of the light vertices in media;
* vol merging: mode `vcm`'s ``camera_s`` minus that of the same render whose camera vertices in
  media look nothing up (``MediumGrid.merge`` replaced by a zero for that render only: the MIS
  weights are unchanged, so the rest of the kernel is the same), and surf merging the rest of merging;
* vol reads: light vertices read per camera subpath by the volume merges (``count_rays``' merge
  reads, the same difference).

Every clock stops after dr.eval + dr.sync_thread (``render.timed_kernels``); compilation is
left out by the warm-up and reported (kernels compiled during the timed renders, which
should be 0). The machine is shared, so single timings are noisy.

    .venv/bin/python benchmarks/bench_vcm.py [--rounds 3] [--res 64] [--spp 16] [--quick] [--merge-first]
                                             [--light-paths 1] [--aim 0] [--merge-vertices all]
    .venv/bin/python benchmarks/bench_vcm.py --pass-sizes --spp 64   # lab_vcm's pass sizes against fixed ones
    .venv/bin/python benchmarks/bench_vcm.py --scenes volumetric_caustic.xml --max-depth 12 --radius 0
"""
from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import sys

import mitsuba as mi

import mitsuba_lab  # noqa: F401  (selects the variant, registers the lab plugins)
from mitsuba_lab.render import timed_kernels
from mitsuba_lab.runtime import versions
from mitsuba_lab.plugins.integrators.vcm.volume_merging import MediumGrid
from mitsuba_lab.plugins.scene_traits import SceneTraits
from mitsuba_lab.scene import load_scene, make_integrator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ("cornell_box.xml", "caustic.xml", "sds.xml")
med = statistics.median


@contextlib.contextmanager
def no_volume_lookups(active: bool):
    """Camera vertices in media merge with nothing (a zero in place of ``MediumGrid.merge``) while
    ``active``: the render without the volume merges' lookups, to time them by difference."""
    merge = MediumGrid.merge
    if active:
        MediumGrid.merge = lambda self, cp, mei, phase, beta, *rest: mi.Spectrum(0)
    try:
        yield
    finally:
        MediumGrid.merge = merge


def timed_render(scene, integrator, spp, seed, novolume=False):
    """(wall seconds, kernels compiled, the integrator's statistics) of one synchronised render."""
    with no_volume_lookups(novolume):
        _, wall, history = timed_kernels(lambda: mi.render(scene, integrator=integrator, spp=spp, seed=seed))
    compiled = sum(1 for k in history if "cache_hit" in k and not k["cache_hit"])
    stats = integrator.bdpt_stats() if hasattr(integrator, "bdpt_stats") else {}
    if hasattr(integrator, "work_counts"):
        stats["merge_reads"] = integrator.work_counts().get("merge", 0)
    return wall, compiled, stats


def measure(name, res, spp, depth, radius, rounds, merge_first=False, light_paths=1.0, aim=0.0,
            merge_vertices="all"):
    scene = load_scene(os.path.join(ROOT, "scenes", name), res=res)
    media = SceneTraits.from_scene(scene).media
    vcm_params = {"mode": "vcm", "max_depth": depth, "radius": radius, "pilot": False, "merge_first": merge_first,
                  "light_paths": light_paths, "aim": aim, "merge_vertices": merge_vertices, "count_rays": True}
    methods = {
        "vcm": make_integrator("lab_vcm", vcm_params),
        "bpt": make_integrator("lab_vcm", {"mode": "bpt", "max_depth": depth, "light_paths": light_paths,
                                           "aim": aim}),
        # (ptracer has no media; volpath is path's counterpart there)
        "ptracer": None if media else make_integrator("ptracer", {"max_depth": depth}),
        "path": make_integrator("volpath" if media else "path", {"max_depth": depth}),
        "vcm_novol": make_integrator("lab_vcm", vcm_params) if media else None,
    }
    methods = {key: integrator for key, integrator in methods.items() if integrator is not None}
    for key, integrator in methods.items():                   # warm-up: compile every kernel
        timed_render(scene, integrator, spp, seed=1, novolume=key == "vcm_novol")
    runs = {key: [] for key in methods}
    for r in range(rounds):
        for key, integrator in methods.items():
            runs[key].append(timed_render(scene, integrator, spp, seed=100 + r, novolume=key == "vcm_novol"))
    pixels = res * res
    vcm, bpt = runs["vcm"], runs["bpt"]
    light = med(s["light_s"] for _, _, s in vcm)
    if media:
        novol = runs["vcm_novol"]
        vol_merge = med(s["camera_s"] for _, _, s in vcm) - med(s["camera_s"] for _, _, s in novol)
        media_split = {
            "in_media": vcm[0][2]["medium_merging_vertices"] / max(vcm[0][2]["light_vertices_stored"], 1),
            "vol_grid_ms": 1e3 * med(s["volume_grid_s"] for _, _, s in vcm) / spp,
            "surf_merge_ms": 1e3 * (med(s["camera_s"] for _, _, s in novol)
                                    - med(s["camera_s"] for _, _, s in bpt)) / spp,
            "vol_merge_ms": 1e3 * vol_merge / spp,
            "vol_reads": (vcm[0][2]["merge_reads"] - novol[0][2]["merge_reads"]) / (pixels * spp),
            "reads": vcm[0][2]["merge_reads"] / (pixels * spp),
            "radius": vcm[0][2]["radius_first"], "radius_volume": vcm[0][2]["radius_volume_first"],
        }
    else:
        media_split = None
    return {
        "scene": name,
        "iterations": spp,
        "light_ms": 1e3 * light / spp,
        "grid_ms": 1e3 * med(s["grid_s"] for _, _, s in vcm) / spp,
        "camera_ms": 1e3 * med(s["camera_s"] for _, _, s in bpt) / spp,
        "merge_ms": 1e3 * (med(s["camera_s"] for _, _, s in vcm) - med(s["camera_s"] for _, _, s in bpt)) / spp,
        "vcm_ms": 1e3 * med(w for w, _, _ in vcm) / spp,
        "bpt_ms": 1e3 * med(w for w, _, _ in bpt) / spp,
        "path_ms": 1e3 * med(w for w, _, _ in runs["path"]) / spp,
        "light_ns_per_path": 1e9 * light / med(s["light_subpaths"] for _, _, s in vcm),
        "ptracer_ns_per_path": (1e9 * med(w for w, _, _ in runs["ptracer"]) / (pixels * spp)
                                if "ptracer" in runs else float("nan")),
        "merged": vcm[0][2]["merging_vertices"] / max(vcm[0][2]["light_vertices_stored"], 1),
        "passes": vcm[0][2]["passes"],
        "compiled": sum(c for key in runs for _, c, _ in runs[key]),
        "media": media_split,
    }


def pass_sizes(name, res, spp, depth, radius, rounds):
    """ms per iteration of lab_vcm (mode vcm) with lab_vcm's own pass sizes (``adaptive``: about
    PASS_LIGHT_VERTICES stored vertices per pass) and with every pass fixed at 2^14, 2^16 and 2^18
    light subpaths, in alternating rounds (medians), and the passes each took."""
    scene = load_scene(os.path.join(ROOT, "scenes", name), res=res)
    integrator = make_integrator("lab_vcm", {"mode": "vcm", "max_depth": depth, "radius": radius, "pilot": False})
    module = sys.modules[type(integrator).__module__]
    own = {k: getattr(module, k) for k in ("FIRST_PASS_LIGHT_SUBPATHS", "MIN_PASS_LIGHT_SUBPATHS",
                                           "MAX_PASS_LIGHT_SUBPATHS")}
    settings = {"adaptive": own, **{f"2^{e}": dict.fromkeys(own, 1 << e) for e in (14, 16, 18)}}
    runs = {key: [] for key in settings}
    try:
        for r in range(rounds + 1):                     # round 0: the warm-up
            for key, values in settings.items():
                for k, v in values.items():
                    setattr(module, k, v)
                wall, _, stats = timed_render(scene, integrator, spp, seed=100 + r)
                if r:
                    runs[key].append((wall, stats["passes"]))
    finally:
        for k, v in own.items():
            setattr(module, k, v)
    return {key: (1e3 * med(w for w, _ in v) / spp, v[0][1]) for key, v in runs.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3, help="alternating timed rounds (default: 3)")
    parser.add_argument("--res", type=int, default=64, help="film width and height (default: 64)")
    parser.add_argument("--spp", type=int, default=16, help="iterations (samples per pixel) (default: 16)")
    parser.add_argument("--max-depth", type=int, default=8, help="max_depth of every method (default: 8)")
    parser.add_argument("--radius", type=float, default=0.03,
                        help="lab_vcm's first radius, 0: its default (a pixel's footprint) (default: 0.03)")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), help="scene files under scenes/")
    parser.add_argument("--pass-sizes", action="store_true",
                        help="instead: lab_vcm's ms per iteration with its own pass sizes and with fixed ones")
    parser.add_argument("--merge-first", action="store_true",
                        help="lab_vcm with merge_first = true (merging at the camera's first vertex too)")
    parser.add_argument("--light-paths", type=float, default=1.0,
                        help="lab_vcm's light_paths in modes vcm and bpt, in [1/64, 64] (default: 1)")
    parser.add_argument("--aim", type=float, default=0.0,
                        help="lab_vcm's aim in modes vcm and bpt (share of emitted directions aimed at the "
                             "specular shapes), in [0, 1) (default: 0)")
    parser.add_argument("--merge-vertices", choices=("all", "caustic"), default="all",
                        help="lab_vcm's merge_vertices in mode vcm: all, or caustic (only light vertices reached "
                             "through a delta lobe merge) (default: all)")
    parser.add_argument("--quick", action="store_true",
                        help="smoke run: 32x32, 4 spp, 1 round, cornell box only (not a measurement)")
    args = parser.parse_args(argv)
    if args.quick:
        args.res, args.spp, args.rounds, args.scenes = 32, 4, 1, ["cornell_box.xml"]
    if min(args.rounds, args.res, args.spp) < 1 or not args.radius >= 0:
        parser.error("--rounds, --res and --spp must be >= 1 and --radius >= 0")
    if not 1.0 / 64 <= args.light_paths <= 64:
        parser.error("--light-paths must be in [1/64, 64]")
    if not 0.0 <= args.aim < 1.0:
        parser.error("--aim must be in [0, 1)")
    missing = [n for n in args.scenes if not os.path.isfile(os.path.join(ROOT, "scenes", n))]
    if missing:
        parser.error(f"no such scene under scenes/: {', '.join(missing)}")
    print(versions())
    if args.pass_sizes:
        print(f"{args.res}x{args.res}, {args.spp} iterations, max_depth {args.max_depth}, medians of {args.rounds} "
              f"rounds; lab_vcm ms per iteration (passes) with light subpaths per pass:")
        print("scene | adaptive | 2^14 | 2^16 | 2^18")
        for name in args.scenes:
            m = pass_sizes(name, args.res, args.spp, args.max_depth, args.radius, args.rounds)
            print(" | ".join([name, *(f"{ms:.2f} ({passes})" for ms, passes in m.values())]), flush=True)
        return 0
    print(f"{args.res}x{args.res}, {args.spp} iterations, max_depth {args.max_depth}, medians of {args.rounds} "
          f"rounds, merge_first {str(args.merge_first).lower()}, light_paths {args.light_paths:g}, aim {args.aim:g}, "
          f"merge_vertices {args.merge_vertices}; "
          f"milliseconds per "
          f"iteration (one sample per pixel)")
    header = ("scene", "light", "grid", "camera+conn", "merging", "vcm total", "bpt total", "path",
              "light ns/path", "ptracer ns/path", "ratio", "merged", "passes", "compiled")
    print(" | ".join(header))
    media = []
    for name in args.scenes:
        m = measure(name, args.res, args.spp, args.max_depth, args.radius, args.rounds, args.merge_first,
                    args.light_paths, args.aim, args.merge_vertices)
        ptracer = (("-", "-") if m["media"] else        # (no ptracer in media)
                   (f"{m['ptracer_ns_per_path']:.0f}", f"{m['light_ns_per_path'] / m['ptracer_ns_per_path']:.2f}x"))
        print(" | ".join([m["scene"], *(f"{m[k]:.2f}" for k in ("light_ms", "grid_ms", "camera_ms", "merge_ms",
                                                                 "vcm_ms", "bpt_ms", "path_ms")),
                          f"{m['light_ns_per_path']:.0f}", *ptracer, f"{m['merged']:.3f}",
                          str(m["passes"]),
                          str(m["compiled"])]), flush=True)
        if m["media"]:
            media.append((name, m))
    if media:
        print("\nmedia (path: volpath; no ptracer): milliseconds per iteration; 'in media' the share of stored light "
              "vertices in media; reads: light vertices read per camera subpath by all merges and by the volume's")
        print("scene | in media | light ns/path | grid | vol grid | surf merging | vol merging | reads | vol reads "
              "| r_1 | r_v,1")
        for name, m in media:
            x = m["media"]
            print(" | ".join([name, f"{x['in_media']:.3f}", f"{m['light_ns_per_path']:.0f}", f"{m['grid_ms']:.2f}",
                              f"{x['vol_grid_ms']:.2f}", f"{x['surf_merge_ms']:.2f}", f"{x['vol_merge_ms']:.2f}",
                              f"{x['reads']:.2f}", f"{x['vol_reads']:.2f}", f"{x['radius']:.4g}",
                              f"{x['radius_volume']:.4g}"]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
