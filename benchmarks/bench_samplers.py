"""Render MSE, render time and blue-noise spectra of the lab samplers vs Mitsuba's.

    .venv/bin/python benchmarks/bench_samplers.py                 # issue size: 128^2, ref 16384 spp
    .venv/bin/python benchmarks/bench_samplers.py --res 64        # reduced
    .venv/bin/python benchmarks/bench_samplers.py --spp --blue-spp --samplers   # blue-noise study only

Cornell box, C++ ``path`` integrator, max_depth 6. The reference is rendered
with ``path`` + ``independent`` in ``--ref-chunks`` independent chunks; its
noise floor (per-pixel variance of the chunk mean, averaged over the image) is
subtracted from every MSE. Each timed render comes after a warm-up render of
the same configuration (compilation) and ends with dr.eval + dr.sync_thread.
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

import mitsuba_lab  # noqa: F401
import drjit as dr
import mitsuba as mi
from mitsuba_lab.experiment.spectrum import low_frequency_fraction

CORNELL = Path(__file__).resolve().parents[1] / "scenes" / "cornell_box.xml"
MITSUBA = ("independent", "stratified", "multijitter", "ldsampler", "orthogonal")
LAB = ("lab_independent", "lab_stratified", "lab_halton", "lab_sobol", "lab_zsobol")


def scene(sampler: str, res: int, spp: int, max_depth: int):
    xml = CORNELL.read_text().replace('<sampler type="independent">', f'<sampler type="{sampler}">')
    return mi.load_string(xml, res=res, spp=spp, max_depth=max_depth)


def render(sc, seed: int) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    img = mi.render(sc, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    return np.array(img, dtype=np.float64), time.perf_counter() - t0


def reference(args) -> tuple[np.ndarray, float]:
    per_chunk = args.ref_spp // args.ref_chunks
    sc = scene("independent", args.res, per_chunk, args.max_depth)
    chunks = np.stack([render(sc, 100_000 + i)[0] for i in range(args.ref_chunks)])
    ref = chunks.mean(axis=0)
    floor = float(np.mean(chunks.var(axis=0, ddof=1) / args.ref_chunks))
    return ref, floor


def blue_noise_study(args):
    """Low-frequency share of the error power (lowest quarter of radial frequencies):
    lab_zsobol against lab_sobol (and independent, white-noise control) at low spp,
    per max_depth (2 = direct lighting only), each seed's error image apart."""
    print("\nblue noise: share of error power below 1/4 Nyquist (white noise: 0.0625), "
          "mean over seeds; ratio zsobol/sobol (< 1: bluer)")
    names = ("independent", "lab_sobol", "lab_zsobol")
    for depth in args.blue_depths:
        ref_args = argparse.Namespace(**{**vars(args), "max_depth": depth, "ref_spp": args.blue_ref_spp})
        ref, floor = reference(ref_args)
        for spp in args.blue_spp:
            scenes = {n: scene(n, args.res, spp, depth) for n in names}
            for n in names:
                render(scenes[n], 999)
            low, mse = {n: [] for n in names}, {n: [] for n in names}
            for seed in range(args.blue_seeds):
                for n in names:
                    err = render(scenes[n], seed)[0] - ref
                    low[n].append(low_frequency_fraction(err))
                    mse[n].append(float(np.mean(err ** 2)) - floor)
            lo = {n: statistics.mean(v) for n, v in low.items()}
            ratios = [z / s for z, s in zip(low["lab_zsobol"], low["lab_sobol"])]
            print(f"  max_depth {depth} spp {spp:4d}: " + "  ".join(
                f"{n} {lo[n]:.4f} (MSE {statistics.mean(mse[n]):.2e})" for n in names) +
                f"  ratio {lo['lab_zsobol'] / lo['lab_sobol']:.3f} (per seed {min(ratios):.2f}..{max(ratios):.2f})")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, nargs="*", default=[64, 256], help="none: skip the main table")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--blue-spp", type=int, nargs="*", default=[4, 16],
                    help="extra sample counts for the blue-noise comparison (lab_sobol, lab_zsobol only)")
    ap.add_argument("--ref-spp", type=int, default=16384)
    ap.add_argument("--ref-chunks", type=int, default=16)
    ap.add_argument("--max-depth", type=int, default=6)
    ap.add_argument("--samplers", nargs="+", default=list(MITSUBA + LAB))
    ap.add_argument("--blue-depths", type=int, nargs="*", default=[2, 6],
                    help="max_depth values of the low-spp blue-noise study (2 = direct lighting); none: skip it")
    ap.add_argument("--blue-study-spp", dest="blue_spp_study", type=int, nargs="+", default=[1, 2, 4, 16])
    ap.add_argument("--blue-seeds", type=int, default=8)
    ap.add_argument("--blue-ref-spp", type=int, default=4096)
    args = ap.parse_args()

    if not args.spp:
        args.spp, args.blue_spp = [], []
    if args.spp:
        t0 = time.perf_counter()
        ref, floor = reference(args)
        print(f"reference: {args.res}^2, {args.ref_spp} spp in {args.ref_chunks} chunks, "
              f"{time.perf_counter() - t0:.0f} s; noise floor (MSE of the reference) {floor:.3e}")

        rows, errors = {}, {}
        for spp in sorted(set(args.spp + args.blue_spp)):
            names = args.samplers if spp in args.spp else [n for n in ("lab_sobol", "lab_zsobol") if n in args.samplers]
            scenes = {name: scene(name, args.res, spp, args.max_depth) for name in names}
            mses = {name: [] for name in names}
            times = {name: [] for name in names}
            for name in names:
                render(scenes[name], 999)                        # warm-up: compile
            # Seeds interleaved across samplers, so load on the machine hits all alike;
            # the time reported is the minimum over the seeds.
            for seed in range(args.seeds):
                for name in names:
                    img, t = render(scenes[name], seed)
                    mses[name].append(float(np.mean((img - ref) ** 2)) - floor)
                    times[name].append(t)
                    errors.setdefault((name, spp), []).append(img - ref)
            for name in names:
                rows[name, spp] = (statistics.mean(mses[name]), min(times[name]), statistics.median(times[name]))

        print(f"\n{'sampler':16s} {'spp':>5s} {'MSE-floor':>10s} {'/bestMI':>8s} {'min ms':>8s} {'/indep':>7s} "
              f"{'med ms':>8s} {'/indep':>7s}")
        print("(/bestMI: against the best Mitsuba sampler that really uses the requested spp;"
              " orthogonal rounds spp up to a prime squared and is left out of it)")
        for spp in args.spp:
            best_mi = min(rows[n, spp][0] for n in MITSUBA if (n, spp) in rows and n != "orthogonal")
            _, t_ind, m_ind = rows["independent", spp]
            for name in args.samplers:
                mse, t, m = rows[name, spp]
                print(f"{name:16s} {spp:5d} {mse:10.3e} {mse / best_mi:8.3f} {1e3 * t:8.1f} {t / t_ind:7.3f} "
                      f"{1e3 * m:8.1f} {m / m_ind:7.3f}")

        if "lab_sobol" in args.samplers and "lab_zsobol" in args.samplers:
            print("\nblue noise: share of error power in the lowest quarter of radial frequencies")
            for spp in sorted(set(args.spp + args.blue_spp)):
                z = statistics.mean(low_frequency_fraction(e) for e in errors["lab_zsobol", spp])
                s = statistics.mean(low_frequency_fraction(e) for e in errors["lab_sobol", spp])
                print(f"  spp {spp:4d}: lab_zsobol {z:.4f} (MSE {rows['lab_zsobol', spp][0]:.3e})  "
                      f"lab_sobol {s:.4f} (MSE {rows['lab_sobol', spp][0]:.3e})  ratio {z / s:.3f}")

    if args.blue_depths:
        blue_noise_study(argparse.Namespace(**{**vars(args), "blue_spp": args.blue_spp_study}))


if __name__ == "__main__":
    main()
