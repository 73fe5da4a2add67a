"""lab_bdpt: light-subpath throughput against Mitsuba's `ptracer`, the cost of a full render
against Mitsuba's `path`, and the light-vertex memory and its split into passes.

1. Light tracing (issue #16: within 1.5x of ptracer). `ptracer` renders W x H x spp light
   paths; lab's light tracing alone (``render_light_tracing``: t = 1 only, nothing stored)
   traces as many; the light pass inside a full lab_bdpt render traces as many again and also
   stores the connectable vertices (``bdpt_stats()['light_s'] / ['light_subpaths']``). Ptracer
   reports no ray counts, so the target is compared per light path at the same max_depth and
   rr_depth (the two Russian roulettes differ: lab's is relative to the emitted throughput, so
   the mean path lengths need not match). For lab the segments traced are counted
   (``light_vertices_reached``: surface hits, without the escaped rays and without the shadow
   rays to the sensor, at most one per hit and one per emitter point) and given as segments
   per second. Dr.Jit's kernel history splits each time into the kernel's execution and the
   rest of the render (tracing the Python loop, assembling the kernel, buffers): a cost per
   render that does not grow with the number of paths.
2. Full render: lab_bdpt (all strategies) against `path` at the same spp and max_depth, as
   seconds per sample per pixel and their ratio, and lab_bdpt's split into light_s (light
   pass) and camera_s (camera subpaths with their connections); the rest is the driver.
3. Memory (cornell box): peak_vertex_bytes of the default render against what storing every
   vertex of W x H x spp subpaths at once takes, and two small max_vertices that must split
   the render: into passes of fewer spp (8 x film pixels), and below one spp of light
   subpaths (film pixels / 2: passes share light subpaths). Checked: passes > 1 and
   peak_vertex_bytes <= max_vertices x vertex_bytes().

Timing: every clock stops after dr.eval + dr.sync_thread. Kernel compilation is excluded by
a warm-up render of every timed method at the same size first; the timed renders then run
with Dr.Jit's kernel history on and the report gives how many kernels they compiled (cache
misses, which should be 0). Methods alternate within each of --rounds rounds and medians are
reported; the machine is shared with other jobs, so single timings are noisy.

    .venv/bin/python benchmarks/bench_bdpt.py [--rounds 5] [--res 64] [--spp 16] [--max-depth 8]
        [--scenes cornell_box.xml ...] [--quick]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys

import drjit as dr
import mitsuba as mi

import mitsuba_lab  # noqa: F401  (selects the variant, registers the lab plugins)
from mitsuba_lab.plugins.integrators.common import spawn
from mitsuba_lab.plugins.integrators.bdpt.light_subpath import LightTracer, render_light_tracing
from mitsuba_lab.plugins.integrators.bdpt.vertices import vertex_bytes
from mitsuba_lab.plugins.samplers.layout import bind_film_layout
from mitsuba_lab.render import timed_kernels
from mitsuba_lab.runtime import versions
from mitsuba_lab.scene import SceneTraits, load_scene, make_integrator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ("cornell_box.xml", "caustic.xml", "veach_mis.xml")
RR_DEPTH = 5
#: Issue #16's target: lab light tracing within this factor of ptracer's time per light path.
TARGET = 1.5
med = statistics.median


def log(*args):
    print(*args, file=sys.stderr, flush=True)


def timed(fn):
    """(result, wall seconds, kernels compiled, [(size, execution seconds)] of the JIT kernels in
    launch order): the clock starts and stops synchronised (``render.timed_kernels``)."""
    out, wall, history = timed_kernels(fn)
    jit = [(k["size"], k["execution_time"] / 1e3) for k in history if k["type"] == dr.KernelType.JIT]
    return out, wall, sum(1 for k in history if "cache_hit" in k and not k["cache_hit"]), jit


def light_segments(scene, spp, depth, seed):
    """Surface hits of render_light_tracing's subpaths for ``seed`` (the same subpaths it traces:
    same tracer, count and seed), counted once outside the clock."""
    sensor = scene.sensors()[0]
    film = sensor.film()
    film.prepare([])
    block = film.create_block(mi.ScalarVector2u(0), True, False)
    tracer = LightTracer(scene, sensor, depth, RR_DEPTH, None, spawn.offset_floor(SceneTraits.from_scene(scene)))
    count = int(film.size()[0] * film.size()[1]) * spp
    reached, _, _ = tracer.trace(count, seed, block, 1.0)
    dr.eval(reached, block.tensor())
    return int(reached[0])


def measure(scene_name, res, spp, depth, rounds):
    """Per-round timings of the four methods on one scene (medians taken by the caller)."""
    scene = load_scene(os.path.join(ROOT, "scenes", scene_name), res=res)
    bind_film_layout(scene, 0)
    common = {"max_depth": depth, "rr_depth": RR_DEPTH}
    ptracer = make_integrator("ptracer", common)
    path = make_integrator("path", common)
    bdpt = make_integrator("lab_bdpt", common)
    paths = res * res * spp
    run = {
        "ptracer": lambda seed: mi.render(scene, integrator=ptracer, spp=spp, seed=seed),
        "light": lambda seed: render_light_tracing(scene, 0, seed, spp, depth, RR_DEPTH),
        "bdpt": lambda seed: mi.render(scene, integrator=bdpt, spp=spp, seed=seed),
        "path": lambda seed: mi.render(scene, integrator=path, spp=spp, seed=seed),
    }
    warm = {}
    for name, fn in run.items():                          # warm-up: compiles every kernel
        warm[name] = timed(lambda: fn(0))[1]
    log(f"{scene_name}: warm-up (with compilation) " + ", ".join(f"{k} {v:.2f} s" for k, v in warm.items()))
    r = {k: [] for k in ("ptracer", "light", "bdpt", "path", "light_s", "camera_s", "misses", "k_ptracer",
                         "k_light", "k_bdpt")}
    stats = []
    for i in range(rounds):
        misses = 0
        for name, fn in run.items():
            _, wall, m, jit = timed(lambda: fn(1 + i))
            r[name].append(wall)
            misses += m
            if name in ("ptracer", "light"):
                r["k_" + name].append(sum(t for _, t in jit))
            if name == "bdpt":
                s = bdpt.bdpt_stats()
                # one pass: its light kernel is the first one over all the pass's light subpaths
                light_kernels = [t for n, t in jit if n == s["light_subpaths"]][:1]
                if s["passes"] == 1 and light_kernels:
                    r["k_bdpt"].append(light_kernels[0])
                stats.append(s)
                r["light_s"].append(s["light_s"])
                r["camera_s"].append(s["camera_s"])
        r["misses"].append(misses)
        log(f"  round {i}: " + ", ".join(f"{k} {r[k][-1]:.3f} s" for k in ("ptracer", "light", "bdpt", "path"))
            + f" (bdpt light {r['light_s'][-1]:.3f} s, camera {r['camera_s'][-1]:.3f} s)")
    segments = [light_segments(scene, spp, depth, 1 + i) for i in range(min(rounds, 2))]
    return {"scene": scene_name, "paths": paths, "spp": spp, "res": res, "r": r, "stats": stats,
            "light_segments": statistics.mean(segments), "warm": warm}


def light_table(results):
    print(f"\n1. Light subpath tracing vs ptracer (max_depth {results[0]['depth']}, rr_depth {RR_DEPTH}; "
          f"medians over {len(results[0]['r']['ptracer'])} rounds; ratio = lab / ptracer time per light path)")
    print(f"  {'scene':16s} {'method':22s} {'paths':>7s} {'ns/path':>7s} {'seg/path':>8s} "
          f"{'M seg/s':>7s} {'ratio':>6s} {'kernel ns/path':>14s} {'k.ratio':>7s} {'other ms':>8s}")
    verdicts = []
    for res in results:
        r, paths = res["r"], res["paths"]
        t_pt, k_pt = med(r["ptracer"]) / paths, med(r["k_ptracer"]) / paths
        seg_light = res["light_segments"] / paths
        seg_bdpt = statistics.mean(s["light_vertices_reached"] / s["light_subpaths"] for s in res["stats"])
        subpaths = res["stats"][-1]["light_subpaths"]
        rows = [("ptracer", paths, t_pt, None, k_pt),
                ("render_light_tracing", paths, med(r["light"]) / paths, seg_light, med(r["k_light"]) / paths),
                ("lab_bdpt light pass", subpaths, med(x / s["light_subpaths"] for x, s in
                                                      zip(r["light_s"], res["stats"])), seg_bdpt,
                 med(r["k_bdpt"]) / subpaths if r["k_bdpt"] else None)]
        for name, n, t, seg, k in rows:
            ratio = t / t_pt
            print(f"  {res['scene']:16s} {name:22s} {n:7,d} {1e9 * t:7.0f} "
                  f"{'-' if seg is None else f'{seg:.2f}':>8s} "
                  f"{'-' if seg is None else f'{1e-6 * seg / t:.2f}':>7s} {ratio:6.2f} "
                  f"{'-' if k is None else f'{1e9 * k:.0f}':>14s} {'-' if k is None else f'{k / k_pt:.2f}':>7s} "
                  f"{'-' if k is None else f'{1e3 * (t - k) * n:.1f}':>8s}")
            if name != "ptracer":
                verdicts.append((res["scene"], name, ratio))
    worst = {m: max(v for _, n, v in verdicts if n == m) for m in ("render_light_tracing", "lab_bdpt light pass")}
    print("  (seg = light segments ending on a surface, light_vertices_reached; shadow rays to the sensor and "
          "escaped rays not counted; ptracer gives no counts. kernel = execution time of the JIT kernels "
          "alone, from Dr.Jit's kernel history: for the light pass its one light kernel; other = the rest of "
          "the wall time per render: tracing Python, assembling the kernel and, for lab_bdpt, the vertex "
          "buffer and the read-back of its count)")
    for m, v in worst.items():
        print(f"VERDICT light tracing ({m}) within {TARGET}x of ptracer per light path: "
              f"{'MET' if v <= TARGET else 'NOT MET'} (worst scene ratio {v:.2f})")


def render_table(results):
    print("\n2. Full render: lab_bdpt (all strategies) vs path, same spp and max_depth (medians; "
          "s/spp = seconds per sample per pixel of the whole film)")
    print(f"  {'scene':16s} {'res':>4s} {'spp':>4s} {'path s/spp':>10s} {'bdpt s/spp':>10s} {'ratio':>6s} "
          f"{'light_s':>8s} {'camera_s':>8s} {'other':>6s} {'passes':>6s} {'misses':>6s}")
    ratios = []
    for res in results:
        r, spp = res["r"], res["spp"]
        t_path, t_bdpt = med(r["path"]), med(r["bdpt"])
        light, camera = med(r["light_s"]), med(r["camera_s"])
        ratios.append(t_bdpt / t_path)
        print(f"  {res['scene']:16s} {res['res']:4d} {spp:4d} {1e3 * t_path / spp:8.2f}ms {1e3 * t_bdpt / spp:8.2f}ms "
              f"{ratios[-1]:6.2f} {light / t_bdpt:7.0%} {camera / t_bdpt:8.0%} "
              f"{max(0.0, t_bdpt - light - camera) / t_bdpt:6.0%} {res['stats'][-1]['passes']:6d} "
              f"{max(r['misses']):6d}")
    print("  (light_s / camera_s / other: shares of lab_bdpt's median wall time; misses: kernels compiled in "
          "any timed round, all methods)")
    print(f"VERDICT full lab_bdpt render vs path at equal spp: {min(ratios):.1f}x to {max(ratios):.1f}x the time "
          f"(no target; BDPT does more per sample)")


def memory_table(res, spp, depth):
    """The default max_vertices, one that splits the render into passes of fewer spp, and one below
    a single spp of light subpaths (passes trace fewer light subpaths than camera ones)."""
    scene = load_scene(os.path.join(ROOT, "scenes", "cornell_box.xml"), res=res)
    px = res * res
    vb = vertex_bytes()
    print(f"\n3. Light-vertex memory (cornell_box.xml {res}x{res}, {spp} spp, max_depth {depth}; "
          f"{vb} bytes per vertex; one warm-up render per row, then one timed)")
    print(f"  {'max_vertices':>12s} {'passes':>6s} {'retraces':>8s} {'subpaths':>9s} {'stored':>9s} "
          f"{'all at once':>11s} {'peak bytes':>11s} {'bound':>11s} {'seconds':>8s} {'misses':>6s}")
    ok = True
    budgets = {"default": 1 << 21, "split by spp": max(1024, 8 * px), "shared subpaths": max(1024, px // 2)}
    for label, max_vertices in budgets.items():
        bdpt = make_integrator("lab_bdpt", {"max_depth": depth, "rr_depth": RR_DEPTH,
                                            "max_vertices": max_vertices})
        timed(lambda: mi.render(scene, integrator=bdpt, spp=spp, seed=0))          # compile, learn
        _, wall, misses, _ = timed(lambda: mi.render(scene, integrator=bdpt, spp=spp, seed=1))
        s = bdpt.bdpt_stats()
        # one pass holding the stored vertices of all film pixels x spp light subpaths at once
        all_at_once = round(s["light_vertices_stored"] / s["light_subpaths"] * px * spp) * vb
        bound = max_vertices * vb
        ok &= s["peak_vertex_bytes"] <= bound and (label == "default" or s["passes"] > 1)
        print(f"  {max_vertices:12,d} {s['passes']:6d} {s['retraces']:8d} {s['light_subpaths']:9,d} "
              f"{s['light_vertices_stored']:9,d} {all_at_once:11,d} {s['peak_vertex_bytes']:11,d} {bound:11,d} "
              f"{wall:8.3f} {misses:6d}  {label}")
    print(f"  (film {px:,} px x {spp} spp = {px * spp:,} camera samples; 'all at once' = stored vertices per "
          f"light subpath x {px * spp:,} x bytes per vertex; bound = max_vertices x bytes per vertex; "
          f"misses = kernels compiled in the timed render)")
    print(f"VERDICT memory: peak_vertex_bytes <= max_vertices x {vb} B and small budgets split into passes: "
          f"{'MET' if ok else 'NOT MET'}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5, help="alternating timed rounds (default: 5)")
    parser.add_argument("--res", type=int, default=64, help="film width and height (default: 64)")
    parser.add_argument("--spp", type=int, default=16, help="samples (light paths) per pixel (default: 16)")
    parser.add_argument("--max-depth", type=int, default=8, help="max_depth of every method (default: 8)")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), help="scene files under scenes/")
    parser.add_argument("--quick", action="store_true",
                        help="smoke run (seconds): 32x32, 4 spp, 2 rounds, cornell box only; its timings "
                             "are not a measurement")
    args = parser.parse_args(argv)
    if args.quick:
        args.res, args.spp, args.rounds, args.scenes = 32, 4, 2, ["cornell_box.xml"]
    if min(args.rounds, args.res, args.spp) < 1:
        parser.error("--rounds, --res and --spp must be >= 1")
    missing = [n for n in args.scenes if not os.path.isfile(os.path.join(ROOT, "scenes", n))]
    if missing:
        parser.error(f"no such scene under scenes/: {', '.join(missing)}")
    print(versions())
    print("timings are noisy: the machine is shared with other jobs (medians over rounds)")
    if args.quick:
        print("--quick: a smoke run; renders this small are dominated by the fixed cost per render, so its "
              "ratios and verdicts are not a measurement")
    results = []
    for name in args.scenes:
        results.append(measure(name, args.res, args.spp, args.max_depth, args.rounds))
        results[-1]["depth"] = args.max_depth
    light_table(results)
    render_table(results)
    memory_table(args.res, args.spp, args.max_depth)
    return 0


if __name__ == "__main__":
    sys.exit(main())
