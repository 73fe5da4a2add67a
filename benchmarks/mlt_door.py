"""The door ajar (issue 45): where Metropolis light transport's error comes from, and how hard the
scene is for a path tracer.

``count``: every strategy at the same samples per pixel (mutations per pixel for the chain
estimators), several seeds: floor-corrected relMSE against the runner's cached reference (the one
``mitsuba-lab sweep`` made at the same resolution and max_depth), wall seconds per sample, and their
product (relMSE x seconds per sample: lower is more efficient; the relMSE of one second per pixel).

``slit``: how the near room's light gets there. lab_mis's image mean of the scene as it is,
against the same scene with the far room's floor, ceiling and three walls black (a black liner
a millimetre inside them): what remains is the light that went from the lamp through the slit
without touching those surfaces (the lamp's direct light through the slit, and what the door's
and the dividing wall's far faces reflect through it). Veach's door has almost nothing left.

``time``: chain settings at equal time, one render per seed (not a progressive run, so a render
knows its whole mutation count and settings can be chosen from it). Per plan, the mutations per
pixel that fill ``--budget`` seconds are fitted (time = fixed + per spp x spp through two pilot
renders, ``--pilots``), then each seed renders that many. Plans (``--plans``): ``shipped`` (every
strategy as it ships, ``bootstrap_share`` included); the others with the chain estimators'
``bootstrap_share`` 0: ``defaults`` (otherwise the defaults: 8192 chains, 100000 bootstrap paths);
``long``: fewer, longer chains, chains = pixels x N / ``--min-steps`` (N the defaults' fitted count,
so each chain runs at least that many mutations; between 256 and 8192); ``boot``: a bootstrap that
grows with the budget, ``--boot-share`` x pixels x N paths (between 100000 and ``--boot-cap``);
``long+boot``.
``--freeze``: lab_mmlt's rounds frozen in every plan (``mlt.mmlt.FREEZE_ROUNDS``; the default since
2026-11-29-mlt-speed.md, so the flag changes nothing now).

    PYTHONPATH=src python benchmarks/mlt_door.py count --spp 256 --seeds 0 1 2
    PYTHONPATH=src python benchmarks/mlt_door.py slit --spp 1024
    PYTHONPATH=src python benchmarks/mlt_door.py time --budget 16 --strategies lab_mmlt [--scene scenes/cornell_box.xml]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import mitsuba as mi

mi.set_variant("llvm_ad_rgb")

import drjit as dr  # noqa: E402
import numpy as np  # noqa: E402

import mitsuba_lab.plugins  # noqa: E402,F401  (registers the lab's plugins)
from mitsuba_lab import metrics  # noqa: E402
from mitsuba_lab.experiment.pipeline.config import DEFAULT_CACHE, PluginSpec  # noqa: E402
from mitsuba_lab.experiment.pipeline.reference import load_cached, reference_key  # noqa: E402
from mitsuba_lab.scene import make_integrator  # noqa: E402
from mitsuba_lab.scene_xml import edited_xml, load_scene_variant  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOOR = os.path.join(ROOT, "scenes", "door.xml")
STRATEGIES = {
    "lab_mis": {"type": "lab_mis", "heuristic": "power"},
    "lab_bdpt": {"type": "lab_bdpt"},
    "lab_pssmlt": {"type": "lab_pssmlt"},
    "lab_mmlt": {"type": "lab_mmlt"},
}
#: The far room's five surfaces (z in [-4, 0]), a millimetre inside the box, black.
FAR_LINER = """
    <bsdf type="diffuse" id="black-liner"><rgb name="reflectance" value="0"/></bsdf>
    <shape type="rectangle"><transform name="to_world"><scale value="2, 1.25, 1"/>
        <translate value="0, 1.25, -3.999"/></transform><ref id="black-liner"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="2, 2, 1"/><rotate x="1" angle="-90"/>
        <translate value="0, 0.001, -2"/></transform><ref id="black-liner"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="2, 2, 1"/><rotate x="1" angle="90"/>
        <translate value="0, 2.499, -2"/></transform><ref id="black-liner"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="2, 1.25, 1"/><rotate y="1" angle="90"/>
        <translate value="-1.999, 1.25, -2"/></transform><ref id="black-liner"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="2, 1.25, 1"/><rotate y="1" angle="-90"/>
        <translate value="1.999, 1.25, -2"/></transform><ref id="black-liner"/></shape>
"""


def timed_render(scene, integrator, spp: int, seed: int):
    dr.sync_thread()
    start = time.perf_counter()
    image = np.array(mi.render(scene, integrator=integrator, spp=spp, seed=seed), dtype=np.float64)[..., :3]
    dr.sync_thread()
    return image, time.perf_counter() - start


def reference(path: str, res: int, max_depth: int, spp: int, chunks: int):
    spec = PluginSpec("reference", "path", {"max_depth": max_depth})
    key = reference_key(path, res, {}, spec, spp, chunks)
    cache = os.path.expanduser(os.environ.get("MITSUBA_LAB_CACHE") or DEFAULT_CACHE)
    ref = load_cached(cache, key)
    if ref is None:
        sys.exit(f"no cached reference {key} for {path} at {res} (run `mitsuba-lab sweep` on it first)")
    return ref


def count(args) -> None:
    ref = reference(args.scene, args.res, args.max_depth, args.ref_spp, args.ref_chunks)
    ref_image, floor = np.asarray(ref.image, dtype=np.float64)[..., :3], ref.rel_mse_floor()
    scene = load_scene_variant(args.scene, args.res)
    pixels = np.prod(ref_image.shape[:2])
    print(f"reference {ref.key}: mean {ref_image.mean():.5g}, relMSE floor {floor:.3g}")
    print(f"{'strategy':11s} {'spp':>5s} {'seed':>4s} {'relMSE':>9s} {'wall s':>7s} {'us/sample':>9s} "
          f"{'chains us/mut':>13s} {'mean/ref':>8s}")
    for name in args.strategies:
        params = dict(STRATEGIES[name], max_depth=args.max_depth)
        params.update(dict(kv.split("=", 1) for kv in args.set))
        kind = params.pop("type")
        integrator = make_integrator(kind, {k: _value(v) for k, v in params.items()})
        timed_render(scene, integrator, 4, 1000)          # warm-up: compile
        rows = []
        for seed in args.seeds:
            image, wall = timed_render(scene, integrator, args.spp, seed)
            err = metrics.rel_mse(image, ref_image) - floor
            chain_us = float("nan")
            if hasattr(integrator, "mlt_stats"):
                chain_us = integrator.mlt_stats()["seconds_per_mutation"] * 1e6
            rows.append((err, wall))
            print(f"{name:11s} {args.spp:5d} {seed:4d} {err:9.3g} {wall:7.2f} {wall / pixels / args.spp * 1e6:9.2f} "
                  f"{chain_us:13.2f} {image.mean() / ref_image.mean():8.3f}{_chain_line(integrator)}", flush=True)
        err, wall = (float(np.mean(c)) for c in zip(*rows))
        print(f"{name:11s} mean relMSE {err:.3g}, {wall / pixels / args.spp * 1e6:.2f} us/sample, "
              f"relMSE x us/sample {err * wall / pixels / args.spp * 1e6:.3g}", flush=True)


#: The default chains and bootstrap of both chain estimators (params.py), the bounds of the plans.
DEFAULT_CHAINS, DEFAULT_BOOTSTRAP, MIN_CHAINS, MAX_BOOTSTRAP = 8192, 100000, 256, 4194304


def plan_settings(plan: str, pixels: int, spp: int, min_steps: int, boot_share: float,
                  boot_cap: int = MAX_BOOTSTRAP) -> dict:
    """The chain settings of ``plan`` for a render of ``spp`` mutations per pixel (``time``)."""
    out = {"bootstrap_share": 0.0}          # (every plan's bootstrap fixed: the defaults' is 100000)
    if "long" in plan:
        out["chains"] = int(np.clip(pixels * spp // min_steps, MIN_CHAINS, DEFAULT_CHAINS))
    if "boot" in plan:
        out["bootstrap"] = int(np.clip(boot_share * pixels * spp, DEFAULT_BOOTSTRAP, boot_cap))
    return out


def fitted_spp(scene, integrator, budget: float, pilots) -> tuple[int, float, float]:
    """(spp filling ``budget`` seconds, fixed s, s per spp): time = fixed + per x spp through one
    render at each of the two ``pilots`` counts (a warm-up render first: compilation)."""
    timed_render(scene, integrator, pilots[0], 1000)
    (p1, t1), (p2, t2) = ((p, timed_render(scene, integrator, p, 1001 + i)[1]) for i, p in enumerate(pilots))
    per = max((t2 - t1) / (p2 - p1), 1e-9)
    fixed = max(t1 - per * p1, 0.0)
    return max(1, int((budget - fixed) / per)), fixed, per


def equal_time(args) -> None:
    if args.freeze:                  # (lab_mmlt's frozen rounds: a narrow round costs less than traced)
        from mitsuba_lab.plugins.integrators.mlt import mmlt

        mmlt.FREEZE_ROUNDS = True
    ref = reference(args.scene, args.res, args.max_depth, args.ref_spp, args.ref_chunks)
    ref_image, floor = np.asarray(ref.image, dtype=np.float64)[..., :3], ref.rel_mse_floor()
    scene = load_scene_variant(args.scene, args.res)
    pixels = int(np.prod(ref_image.shape[:2]))
    print(f"{os.path.basename(args.scene)} at {args.res}: reference {ref.key}, relMSE floor {floor:.3g}; "
          f"budget {args.budget} s, min steps {args.min_steps}, bootstrap share {args.boot_share}"
          f"{', lab_mmlt rounds frozen' if args.freeze else ''}")
    for name in args.strategies:
        base = dict(STRATEGIES[name], max_depth=args.max_depth)
        kind = base.pop("type")
        n_default = None
        for plan in args.plans:
            # (the chain estimators' bootstrap fixed, as before bootstrap_share; the others have none)
            settings = {"bootstrap_share": 0.0} if kind in ("lab_pssmlt", "lab_mmlt") else {}
            if plan == "shipped":
                settings = {}
            elif plan != "defaults":
                if n_default is None:
                    sys.exit("time: --plans must start with defaults (the others are chosen from its count)")
                settings = plan_settings(plan, pixels, n_default, args.min_steps, args.boot_share, args.boot_cap)
            integrator = make_integrator(kind, {**base, **settings})
            spp, fixed, per = fitted_spp(scene, integrator, args.budget, args.pilots)
            if plan == "defaults":
                n_default = spp
            rows = []
            for seed in args.seeds:
                image, wall = timed_render(scene, integrator, spp, seed)
                err = metrics.rel_mse(image, ref_image) - floor
                rows.append((err, wall))
                print(f"{name} {plan:10s} {settings} spp {spp} (fit: {fixed:.2f} s + {per * 1e3:.2f} ms/spp) "
                      f"seed {seed}: "
                      f"relMSE {err:.3g}, {wall:.1f} s, mean/ref {image.mean() / ref_image.mean():.3f}"
                      f"{_chain_line(integrator)}", flush=True)
            errs, walls = zip(*rows)
            print(f"{name} {plan:10s} mean relMSE {np.mean(errs):.3g} (seeds {' '.join(f'{e:.3g}' for e in errs)}), "
                  f"mean {np.mean(walls):.1f} s, {spp} mutations/px", flush=True)


def _chain_line(integrator) -> str:
    """What the chains did, where the strategy has chains: b's relative standard error, distinct
    starts, acceptance (all, large steps), steps per chain."""
    if not hasattr(integrator, "mlt_stats"):
        return ""
    st = integrator.mlt_stats()
    return (f"  b se {st['b_standard_error'] / st['b']:.3f}, starts {st['distinct_starts']}, acc "
            f"{st['acceptance']:.3f} (large {st['large_step_acceptance']:.4f}), "
            f"{st['chain_mutations'] / st['chains']:.0f} steps/chain, bootstrap {st['bootstrap_s']:.2f} s")


def _value(text):
    for kind in (int, float):
        try:
            return kind(text)
        except (TypeError, ValueError):
            pass
    return text


def slit(args) -> None:
    text = edited_xml(args.scene, args.res)
    lined = text.replace("</scene>", FAR_LINER + "</scene>")
    integrator = make_integrator("lab_mis", {"max_depth": args.max_depth, "heuristic": "power"})
    folder = os.path.dirname(os.path.abspath(args.scene))
    mi.file_resolver().prepend(folder)
    means = {}
    for label, xml in (("as is", text), ("far room black", lined)):
        scene = mi.load_string(xml)
        images = [timed_render(scene, integrator, args.spp, seed)[0] for seed in args.seeds]
        stack = np.stack(images)
        means[label] = stack.mean(axis=0)
        se = stack.mean(axis=(1, 2, 3)).std(ddof=1) / np.sqrt(len(images)) if len(images) > 1 else float("nan")
        print(f"{label:15s} image mean {stack.mean():.5g} (+- {se:.2g}, {len(images)} renders of {args.spp} spp)")
    full, lined_mean = means["as is"], means["far room black"]
    print(f"share of the near room's light left with the far room black: {lined_mean.mean() / full.mean():.3f}")
    lum = full.mean(axis=2)
    bright = lum >= np.quantile(lum, 0.9)
    print(f"... over the brightest 10% of pixels {lined_mean[bright].mean() / full[bright].mean():.3f}, "
          f"over the rest {lined_mean[~bright].mean() / full[~bright].mean():.3f}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=("count", "slit", "time"))
    parser.add_argument("--scene", default=DOOR)
    parser.add_argument("--res", type=int, default=32)
    parser.add_argument("--max-depth", type=int, default=8)
    parser.add_argument("--spp", type=int, default=256)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--strategies", nargs="+", default=list(STRATEGIES), choices=list(STRATEGIES))
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE",
                        help="a parameter of every strategy in --strategies (e.g. chains=4096)")
    parser.add_argument("--ref-spp", type=int, default=16384)
    parser.add_argument("--ref-chunks", type=int, default=8)
    parser.add_argument("--budget", type=float, default=16.0, help="time: seconds per render")
    parser.add_argument("--pilots", type=int, nargs=2, default=[16, 64], help="time: the pilot renders' spp")
    parser.add_argument("--plans", nargs="+", default=["defaults", "long", "boot", "long+boot"],
                        choices=("shipped", "defaults", "long", "boot", "long+boot"))
    parser.add_argument("--freeze", action="store_true", help="time: lab_mmlt with frozen rounds (every plan)")
    parser.add_argument("--min-steps", type=int, default=1024, help="time: plan long's mutations per chain")
    parser.add_argument("--boot-cap", type=int, default=MAX_BOOTSTRAP, help="time: plan boot's most paths")
    parser.add_argument("--boot-share", type=float, default=0.25,
                        help="time: plan boot's bootstrap paths per mutation")
    args = parser.parse_args(argv)
    {"count": count, "slit": slit, "time": equal_time}[args.command](args)


if __name__ == "__main__":
    main()
