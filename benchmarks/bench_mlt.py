"""The chain estimators' cost per mutation against their base estimators' (issue 45's speed
targets): a lab_pssmlt mutation within 1.5x of a lab_mis sample, a lab_mmlt mutation within 1.5x
of one lab_bdpt strategy evaluation.

Per scene, the four plugins at their defaults (max_depth ``--max-depth``) render ``--spp`` samples
(mutations) per pixel, alternating within each of ``--rounds`` rounds after a warm-up render of
each (which compiles the kernels; the timed renders report the kernels they compiled, which
should be 0), and the medians over the rounds are printed:

* lab_mis and lab_bdpt: the render's wall time over pixels x spp (a sample);
* lab_pssmlt and lab_mmlt: ``mlt_stats()['seconds_per_mutation']``, the chains' time over their
  mutations (the splats included, the bootstrap not: it is paid once per render, whatever the
  mutation count), and the whole render's wall time over its mutations beside it;
* a lab_bdpt strategy evaluation: a lab_bdpt sample's time over the strategies (s, t) it
  evaluated, counted from its rays (``ray_counts()``; counting is on by default): one per
  shadow ray (s = 1: ``shadow``; s, t >= 2: ``connection``; t = 1: ``sensor``) and one per
  camera segment (``camera`` and ``extension`` rays: the s = 0 strategy at its hit).

Every clock starts and stops after ``dr.sync_thread()`` (``render.timed_kernels``; the chains'
own clock in ``mlt/integrator.py`` synchronises too). Both chain estimators freeze their full
rounds by default (``mlt.integrator.FREEZE_ROUNDS``, ``mlt.mmlt.FREEZE_ROUNDS``); ``--freeze``
also times both with every round traced.

``--profile`` splits a lab_pssmlt lock-step round into its parts instead (``profile``; ``--lazy``
with lazy normal steps).

    PYTHONPATH=src .venv/bin/python benchmarks/bench_mlt.py [--scenes door.xml cornell_box.xml]
        [--res 32] [--spp 64] [--rounds 3] [--max-depth 8] [--freeze] [--lazy] [--wide 32768 ...]
        [--profile [--lazy]]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import drjit as dr
import mitsuba as mi

import mitsuba_lab  # noqa: F401  (selects the variant, registers the lab plugins)
from mitsuba_lab.render import timed_kernels
from mitsuba_lab.runtime import versions
from mitsuba_lab.scene import load_scene, make_integrator

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: Issue 45's target: each chain estimator's mutation within this factor of its reference unit.
TARGET = 1.5
#: The ray kinds of lab_bdpt that each stand for one strategy evaluation (the module docstring).
STRATEGY_RAYS = ("shadow", "connection", "sensor", "camera", "extension")
med = statistics.median


def log(*args):
    print(*args, file=sys.stderr, flush=True)


def measure(scene_name: str, res: int, spp: int, depth: int, rounds: int, freeze: bool, wide=(),
            lazy: bool = False) -> dict:
    from mitsuba_lab.plugins.integrators.mlt import integrator as pssmlt
    from mitsuba_lab.plugins.integrators.mlt import mmlt

    scene = load_scene(os.path.join(ROOT, "scenes", scene_name), res=res)
    pixels = res * res
    plugins = {name: make_integrator(name, {"max_depth": depth})
               for name in ("lab_mis", "lab_bdpt", "lab_pssmlt", "lab_mmlt")}
    defaults = {"lab_pssmlt": pssmlt.FREEZE_ROUNDS, "lab_mmlt": mmlt.FREEZE_ROUNDS}
    default = defaults["lab_pssmlt"]
    methods = [(name, plugin, defaults.get(name, False)) for name, plugin in plugins.items()]
    if freeze:
        methods.append(("lab_mmlt traced", plugins["lab_mmlt"], False))
        methods.append(("lab_pssmlt traced", plugins["lab_pssmlt"], False))
    if lazy:                # (the lazy normal steps the plugins made before 2026-11-29-mlt-speed.md)
        for name in ("lab_pssmlt", "lab_mmlt"):
            plugin = make_integrator(name, {"max_depth": depth})
            plugin.LAZY_STEPS = True
            methods.append((f"{name} lazy steps", plugin, defaults[name]))
    for n in wide:          # (wider lock-steps: not the defaults)
        methods.append((f"lab_pssmlt {n} chains", make_integrator("lab_pssmlt", {"max_depth": depth, "chains": n}),
                        default))
    times = {name: [] for name, _, _ in methods}
    chain_times = {name: [] for name, _, _ in methods}
    strategies, rays, lengths, misses = [], [], [], 0

    def run(plugin, frozen, seed):
        mmlt.FREEZE_ROUNDS = pssmlt.FREEZE_ROUNDS = frozen
        try:
            if hasattr(plugin, "ray_counts"):
                plugin.ray_counts(reset=True)
            return timed_kernels(lambda: mi.render(scene, integrator=plugin, spp=spp, seed=seed))
        finally:
            mmlt.FREEZE_ROUNDS, pssmlt.FREEZE_ROUNDS = defaults["lab_mmlt"], defaults["lab_pssmlt"]

    for name, plugin, frozen in methods:                   # warm-up: compiles every kernel
        log(f"{scene_name}: warm-up {name} {run(plugin, frozen, 0)[1]:.2f} s")
    for i in range(rounds):
        for name, plugin, frozen in methods:
            _, wall, history = run(plugin, frozen, 1 + i)
            misses += sum(1 for k in history if "cache_hit" in k and not k["cache_hit"])
            times[name].append(wall / (pixels * spp))
            if hasattr(plugin, "mlt_stats"):
                chain_times[name].append(plugin.mlt_stats()["seconds_per_mutation"])
            if name == "lab_bdpt":
                counts = plugin.ray_counts(reset=True)
                strategies.append(sum(counts[k] for k in STRATEGY_RAYS) / (pixels * spp))
                rays.append(sum(counts.values()) / (pixels * spp))
            if name == "lab_mmlt":
                per_length = plugin.mlt_stats()["chains_per_length"]
                lengths.append(sum((k + 1) * c for k, c in enumerate(per_length)) / max(sum(per_length), 1))
        log(f"  round {i}: " + ", ".join(f"{n} {times[n][-1] * 1e6:.2f} us" for n in times))
    return {"scene": scene_name, "times": times, "chain": chain_times, "strategies": strategies, "misses": misses,
            "rays": rays, "lengths": lengths, "path_rays": path_rays(scene, plugins, pixels, spp)}


def path_rays(scene, plugins: dict, pixels: int, spp: int) -> tuple[float, float]:
    """(rays per lab_mis sample, rays per lab_pssmlt mutation), untimed. The chains' rays are those
    of the mutations 2x the render's count adds to it with the same seed: the same bootstrap (its
    size then depends on ``bootstrap`` alone) and the same first mutations, so the difference is
    the later mutations' alone."""
    def rays(name, n):
        plugin = plugins[name]
        plugin.ray_counts(reset=True)
        mi.render(scene, integrator=plugin, spp=n, seed=99)
        return sum(plugin.ray_counts(reset=True).values())

    chains = plugins["lab_pssmlt"]
    assert chains.bootstrap_for(pixels * 2 * spp) == chains.bootstrap_for(pixels * spp), "bootstrap grows"
    mutations = rays("lab_pssmlt", 2 * spp) - rays("lab_pssmlt", spp)
    return rays("lab_mis", spp) / (pixels * spp), mutations / (pixels * spp)


def table(results: list[dict], args) -> None:
    print(f"\nCost per sample / mutation, medians of {args.rounds} alternating rounds "
          f"({args.res}x{args.res}, {args.spp} per pixel, max_depth {args.max_depth}, every plugin's defaults; "
          f"{versions()})")
    print("| scene | lab_mis sample | lab_pssmlt mutation (whole render) | ratio | lab_bdpt sample | strategies per "
          "sample | lab_bdpt strategy | lab_mmlt mutation (whole render) | ratio to a strategy | ratio to a sample |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        t, c = r["times"], r["chain"]
        mis, bdpt = med(t["lab_mis"]), med(t["lab_bdpt"])
        n = med(r["strategies"])
        strategy = bdpt / n
        rows = [("lab_pssmlt", "lab_mmlt", "")]
        if "lab_mmlt traced" in t:
            rows.append(("lab_pssmlt traced", "lab_mmlt traced", " (every round traced)"))
        for ps_key, key, label in rows:
            ps, mm = med(c[ps_key]), med(c[key])
            whole = med(t[ps_key])
            print(f"| {r['scene']}{label} | {mis * 1e6:.2f} us | {ps * 1e6:.2f} us ({whole * 1e6:.2f}) | "
                  f"**{ps / mis:.2f}** | {bdpt * 1e6:.2f} us | {n:.2f} | {strategy * 1e6:.2f} us | "
                  f"{mm * 1e6:.2f} us ({med(t[key]) * 1e6:.2f}) | **{mm / strategy:.2f}** | {mm / bdpt:.2f} |")
        for name in (k for k in c if k.endswith((" chains", " lazy steps"))):
            base = "lab_mmlt" if name.startswith("lab_mmlt") else "lab_pssmlt"
            print(f"  ({r['scene']}: {name}: {med(c[name]) * 1e6:.2f} us per mutation ({med(t[name]) * 1e6:.2f}), "
                  f"{med(c[name]) / mis:.2f}x a lab_mis sample, {med(c[name]) / med(c[base]):.2f}x {base}'s)")
        print(f"  (kernels compiled in the timed renders: {r['misses']}; target {TARGET}x)")
        # a path of k segments needs k rays (k - 1 traced and a connection, or k traced), none shared
        print(f"  ({r['scene']}: lab_bdpt traces {med(r['rays']):.2f} rays per sample, {med(r['rays']) / n:.2f} per "
              f"strategy; lab_mmlt's chains hold paths of {med(r['lengths']):.2f} segments on average, so a "
              f"mutation traces at least that many rays)")
        mis_rays, chain_rays = r["path_rays"]
        print(f"  ({r['scene']}: a lab_mis sample traces {mis_rays:.2f} rays, a lab_pssmlt mutation {chain_rays:.2f}: "
              f"the chains' paths are {chain_rays / mis_rays:.2f}x as long)")


def profile(scene_name: str, res: int, depth: int, rounds: int, lazy: bool, steps: int = 8) -> None:
    """A lab_pssmlt lock-step round by part, per mutation, on the chains of a warm-up render (its
    defaults; ``lazy``: the normal steps made lazily, as before 2026-11-29-mlt-speed.md), against
    a lab_mis sample (a render at 64 per pixel, and one at as many samples as there are chains);
    medians of ``rounds`` alternating rounds of ``steps`` lock-steps each, every clock after
    ``dr.sync_thread()``:

    * trace: Python building the round's kernels (the path loop's trace dominates; no kernel runs);
    * proposal kernel (eager steps): every stored number moved, chains x dims;
    * path kernel: the path loop reading the proposal (lazy: reading, mutating and writing each
      number it reads) and the weights; beside it the same path loop on fresh numbers (the primary
      sample's hash, no chain state), so their difference is the state's share of the kernel;
    * splat of the current sample and of the proposal (each in a kernel of its own here);
    * accept: the state's update (the flat arrays of chains x dims);
    * the whole round, traced, and frozen (``frozen.FrozenRounds``, recorded before the clock);
    * kernel only: the execution time of the largest kernel (Dr.Jit's kernel history) per lane, of
      the frozen rounds (their path kernel) and of lab_mis's renders.
    """
    from mitsuba_lab.plugins.integrators.bdpt import splats
    from mitsuba_lab.plugins.integrators.mlt import chain
    from mitsuba_lab.plugins.integrators.mlt import integrator as pssmlt
    from mitsuba_lab.plugins.integrators.mlt.frozen import FrozenRounds
    from mitsuba_lab.plugins.integrators.path import KernelPlan
    from mitsuba_lab.plugins.scene_traits import SceneTraits

    scene = load_scene(os.path.join(ROOT, "scenes", scene_name), res=res)
    pixels = res * res
    mis = make_integrator("lab_mis", {"max_depth": depth})
    ps = make_integrator("lab_pssmlt", {"max_depth": depth})
    ps.LAZY_STEPS = lazy
    saved, pssmlt.FREEZE_ROUNDS = pssmlt.FREEZE_ROUNDS, False
    try:
        mi.render(scene, integrator=ps, spp=64, seed=0)
    finally:
        pssmlt.FREEZE_ROUNDS = saved
    chains = ps._held.chains
    n = chains.chains
    narrow = max(1, n // pixels)
    for spp in (64, narrow):
        mi.render(scene, integrator=mis, spp=spp, seed=0)
    sensor = scene.sensors()[0]
    block = splats.new_block(sensor.film())
    ps._plan = (scene, KernelPlan.of(SceneTraits.from_scene(scene), ps.estimator))

    def evaluate(samples, active=True):
        value, payload, _ = ps.evaluate(scene, sensor, samples, res, res, active)
        return value, payload

    def splat(payload, weight):
        splats.splat(block, payload[1], type(mi.Ray3f().wavelengths)(), payload[0] * weight, weight > 0)

    frozen = FrozenRounds(chains, evaluate, splat, [scene, sensor, block, vars(ps.counters)], "lab_pssmlt")
    frozen()
    parts = ("trace", "proposal kernel", "path kernel", "path kernel, fresh numbers", "splat current",
             "splat proposal", "accept", "round traced", "round frozen", "lab_mis sample (64/px)",
             f"lab_mis sample ({narrow}/px: {narrow * pixels} lanes)", "kernel only: frozen round's path kernel",
             "kernel only: lab_mis (64/px)", f"kernel only: lab_mis ({narrow}/px)")
    times = {k: [] for k in parts}

    def clock():
        dr.sync_thread()
        return time.perf_counter()

    def largest_kernel(history) -> float:
        """Seconds per lane of the longest kernel in ``history``."""
        k = max(history, key=lambda k: k.get("execution_time", 0.0))
        return k["execution_time"] * 1e-3 / k["size"]

    for r in range(rounds):
        for spp, key, kernel in ((64, parts[9], parts[12]), (narrow, parts[10], parts[13])):
            _, wall, history = timed_kernels(lambda: mi.render(scene, integrator=mis, spp=spp, seed=r + 1))
            times[key].append(wall / (pixels * spp))
            times[kernel].append(largest_kernel(history))
        acc = dict.fromkeys(parts[:7], 0.0)
        for _ in range(steps):
            index = chains.step_index()
            key = chains.step_key(index)
            value, payload = evaluate(chain.PrimarySamples(n, chains.tail_keys(key)))
            t = clock()
            dr.eval(value, *payload)
            acc[parts[3]] += clock() - t
            t = clock()
            samples, large = chains.propose(key, index)
            if samples.lazy is None:
                dr.eval(samples.state)
                t1 = clock()
                acc[parts[1]] += t1 - t
                t = t1
            value, payload = evaluate(samples)
            a, w_current, w_proposal = chains.weigh(value)
            t1 = time.perf_counter()
            acc[parts[0]] += t1 - t
            dr.eval(value, *payload, a, w_current, w_proposal)
            t2 = clock()
            acc[parts[2]] += t2 - t1
            splat(chains.payload, w_current)
            dr.eval(block.tensor())
            t3 = clock()
            splat(payload, w_proposal)
            dr.eval(block.tensor())
            t4 = clock()
            chains.accept(key, samples, value, payload, a, large)
            dr.eval(*chains.arrays())
            acc[parts[4]] += t3 - t2
            acc[parts[5]] += t4 - t3
            acc[parts[6]] += clock() - t4
        for k, v in acc.items():
            times[k].append(v / (steps * n))
        for key, step in ((parts[7], lambda: chain.step(chains, evaluate, splat)), (parts[8], frozen)):
            t = clock()
            for _ in range(steps):
                step()
            times[key].append((clock() - t) / (steps * n))
        _, _, history = timed_kernels(frozen)
        times[parts[11]].append(largest_kernel(history))
        log(f"  round {r}: " + ", ".join(f"{k} {v[-1] * 1e6:.2f}" for k, v in times.items()))
    whole = med(times[parts[7]])
    print(f"\n{scene_name}: lab_pssmlt's round by part ({'lazy' if lazy else 'eager'} steps), us per mutation "
          f"(median of {rounds} rounds x {steps} lock-steps, {n} chains, {chains.dims} dims stored, {res}x{res}, "
          f"max_depth {depth}; {versions()})")
    print("| part | us per mutation | share of the traced round |\n|---|---|---|")
    for k in parts:
        print(f"| {k} | {med(times[k]) * 1e6:.3f} | {med(times[k]) / whole:.2f} |")
    print(f"  (frozen recordings: {frozen.recordings})")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["door.xml", "cornell_box.xml"])
    parser.add_argument("--res", type=int, default=32)
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--max-depth", type=int, default=8)
    parser.add_argument("--freeze", action="store_true",
                        help="also time lab_pssmlt and lab_mmlt with every round traced")
    parser.add_argument("--wide", type=int, nargs="*", default=[],
                        help="also time lab_pssmlt with these chain counts (wider lock-steps)")
    parser.add_argument("--profile", action="store_true", help="split a lab_pssmlt round into its parts")
    parser.add_argument("--lazy", action="store_true",
                        help="also time both chain estimators with lazy normal steps (--profile: profile those)")
    args = parser.parse_args(argv)
    if args.profile:
        for s in args.scenes:
            profile(s, args.res, args.max_depth, args.rounds, args.lazy)
        return 0
    results = [measure(s, args.res, args.spp, args.max_depth, args.rounds, args.freeze, args.wide, args.lazy)
               for s in args.scenes]
    table(results, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
