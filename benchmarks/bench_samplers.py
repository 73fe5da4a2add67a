"""Render MSE, render time and blue-noise spectra of the lab samplers vs Mitsuba's.

    .venv/bin/python benchmarks/bench_samplers.py                 # issue size: 128^2, ref 16384 spp
    .venv/bin/python benchmarks/bench_samplers.py --res 64        # reduced

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


def low_frequency_fraction(err: np.ndarray) -> float:
    """Share of the error image's power in the lowest quarter of radial frequencies."""
    e = err.mean(axis=-1)
    power = np.abs(np.fft.fftshift(np.fft.fft2(e - e.mean()))) ** 2
    n = e.shape[0]
    yy, xx = np.indices(power.shape)
    radius = np.hypot(yy - n // 2, xx - n // 2)
    return float(power[radius < (n / 2) / 4].sum() / power[radius <= n / 2].sum())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, nargs="+", default=[64, 256])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--blue-spp", type=int, nargs="*", default=[4, 16],
                    help="extra sample counts for the blue-noise comparison (lab_sobol, lab_zsobol only)")
    ap.add_argument("--ref-spp", type=int, default=16384)
    ap.add_argument("--ref-chunks", type=int, default=16)
    ap.add_argument("--max-depth", type=int, default=6)
    ap.add_argument("--samplers", nargs="+", default=list(MITSUBA + LAB))
    args = ap.parse_args()

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
            rows[name, spp] = (statistics.mean(mses[name]), min(times[name]))

    print(f"\n{'sampler':16s} {'spp':>5s} {'MSE-floor':>10s} {'/bestMI':>8s} {'time ms':>8s} {'/indep':>7s}")
    print("(/bestMI: against the best Mitsuba sampler that really uses the requested spp;"
          " orthogonal rounds spp up to a prime squared and is left out of it)")
    for spp in args.spp:
        best_mi = min(rows[n, spp][0] for n in MITSUBA if (n, spp) in rows and n != "orthogonal")
        t_ind = rows["independent", spp][1]
        for name in args.samplers:
            mse, t = rows[name, spp]
            print(f"{name:16s} {spp:5d} {mse:10.3e} {mse / best_mi:8.3f} {1e3 * t:8.1f} {t / t_ind:7.3f}")

    if "lab_sobol" in args.samplers and "lab_zsobol" in args.samplers:
        print("\nblue noise: share of error power in the lowest quarter of radial frequencies")
        for spp in sorted(set(args.spp + args.blue_spp)):
            z = statistics.mean(low_frequency_fraction(e) for e in errors["lab_zsobol", spp])
            s = statistics.mean(low_frequency_fraction(e) for e in errors["lab_sobol", spp])
            print(f"  spp {spp:4d}: lab_zsobol {z:.4f} (MSE {rows['lab_zsobol', spp][0]:.3e})  "
                  f"lab_sobol {s:.4f} (MSE {rows['lab_sobol', spp][0]:.3e})  ratio {z / s:.3f}")


if __name__ == "__main__":
    main()
