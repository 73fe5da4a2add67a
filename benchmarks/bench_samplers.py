"""Render MSE, render time and blue-noise spectra of the lab samplers vs Mitsuba's.

    .venv/bin/python benchmarks/bench_samplers.py                 # 128^2, reference 16384 spp
    .venv/bin/python benchmarks/bench_samplers.py --res 64        # reduced
    .venv/bin/python benchmarks/bench_samplers.py --spp --blue-spp --samplers   # blue-noise study only
    .venv/bin/python benchmarks/bench_samplers.py --timing-only --spp 64 256 --seeds 10   # times only

Cornell box, C++ ``path`` integrator, max_depth 6. The reference comes from the
experiment runner's content-addressed reference cache
(``mitsuba_lab.experiment.reference.get_reference``; ``--ref-cache``, default
``$MITSUBA_LAB_CACHE`` or ``~/.cache/mitsuba_lab/references``, as ``mitsuba-lab
reference``): ``path`` on the Cornell box with its sampler replaced by
``--ref-sampler`` (default ``ldsampler``: a randomised QMC reference has a far
lower noise floor than an independent one of equal spp; the variant scene is
written under out/bench_samplers/ and its bytes are part of the key), in
``--ref-chunks`` independently seeded chunks. Its noise floor (per-pixel variance
of the chunk mean, averaged over the image) is subtracted from every MSE. Each
timed render comes after a warm-up render of the same configuration
(compilation) and ends with dr.eval + dr.sync_thread.

MSE is given with its standard error over the seeds, over the whole image and
without the pixels that see the light directly (reference luminance above
``--emitter-threshold``, grown by one pixel): on this scene much of a QMC
sampler's MSE sits on the light's edge, a 2D anti-aliasing problem on which every
(0,2)-net sampler behaves alike. The blue-noise spectra are likewise given on the
whole image and on the rows below the light (``spectrum.rows_below_bright``); the
low-spp blue-noise study repeats them on non-square pixel blocks (a crop window and a
res x res/2 film) and with a deliberately wrong layout. Every render binds the film to its
sampler first (``bind_film_layout``), as the lab's own renders do.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
from functools import partial
from pathlib import Path

import numpy as np

import mitsuba_lab  # noqa: F401
import drjit as dr
import mitsuba as mi
from mitsuba_lab.experiment.pipeline.config import DEFAULT_CACHE, PluginSpec
from mitsuba_lab.experiment.pipeline.reference import get_reference
from mitsuba_lab.experiment.report.spectrum import bright_mask, low_frequency_fraction, rows_below_bright
from pixel_integrals import exact_owen_pair, first_pair, integrand_families, pixel_integral_mse
from mitsuba_lab.plugins.samplers.common import log2_ceil
from mitsuba_lab.plugins.samplers.layout import bind_film_layout
from mitsuba_lab.scene_xml import edited_xml, plugin_spec

CORNELL = Path(__file__).resolve().parents[1] / "scenes" / "cornell_box.xml"
#: Where the Cornell box with another sampler is written for the reference cache.
VARIANTS = Path(__file__).resolve().parents[1] / "out" / "bench_samplers"
MITSUBA = ("independent", "stratified", "multijitter", "ldsampler", "orthogonal")
LAB = ("lab_independent", "lab_stratified", "lab_halton", "lab_sobol", "lab_zsobol")


def scene(sampler: str, res: int, spp: int, max_depth: int, film: str = "", sampler_params: str = ""):
    """The Cornell box with another sampler; ``film``: XML text added to the film (a crop
    window) or ``wide``: the box's wide film (``wide_film_xml``)."""
    xml = wide_film_xml(res) if film == "wide" else CORNELL.read_text()
    xml = xml.replace('<sampler type="independent">', f'<sampler type="{sampler}">{sampler_params}')
    if film and film != "wide":
        xml = xml.replace('<rfilter type="box"/>', f'<rfilter type="box"/>{film}')
    return mi.load_string(xml, res=res, spp=spp, max_depth=max_depth)


def wide_film_xml(res: int) -> str:
    """The Cornell box on a res x res/2 film, its field of view on the wider axis (the view
    stays inside the box; the light is above it): the blue-noise study's non-square film."""
    return (CORNELL.read_text()
            .replace('<integer name="height" value="$res"/>', f'<integer name="height" value="{res // 2}"/>')
            .replace('<string name="fov_axis" value="smaller"/>', '<string name="fov_axis" value="larger"/>'))


def render(sc, seed: int, bind: bool = True) -> tuple[np.ndarray, float]:
    """One timed render; the film is bound to the sampler first (lab_zsobol learns the
    film's layout; ``bind=False``: plain ``mi.render``, as a user outside the lab)."""
    if bind:
        bind_film_layout(sc)
    t0 = time.perf_counter()
    img = mi.render(sc, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    return np.array(img, dtype=np.float64), time.perf_counter() - t0


def reference_scene(sampler: str, wide_res: int = 0) -> Path:
    """The Cornell box rendered by ``sampler``: the scene file itself for its own sampler,
    else a copy with the sampler replaced (rewritten only when its text changes);
    ``wide_res``: on the wide film (``wide_film_xml``)."""
    if wide_res:
        text = wide_film_xml(wide_res).replace('<sampler type="independent">', f'<sampler type="{sampler}">')
        path = VARIANTS / f"{CORNELL.stem}.{sampler}.wide{wide_res}.xml"
    elif plugin_spec(str(CORNELL), "sampler")[0] == sampler:
        return CORNELL
    else:
        text = edited_xml(str(CORNELL), None, {"type": sampler})
        path = VARIANTS / f"{CORNELL.stem}.{sampler}.xml"
    if not path.exists() or path.read_text() != text:
        VARIANTS.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(text)
        os.replace(tmp, path)          # never a half-written scene
    return path


def reference(args, wide: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Mean of the chunks and its per-pixel noise floor (variance of the chunk mean,
    channels averaged), so a floor can be taken over any set of pixels; built or
    found in the runner's reference cache. ``wide``: of the wide film."""
    cache = os.path.abspath(os.path.expanduser(args.ref_cache))
    integrator = PluginSpec("reference", "path", {"max_depth": args.max_depth})
    path = reference_scene(args.ref_sampler, args.res if wide else 0)
    ref, _ = get_reference(str(path), None if wide else args.res, {"res": args.res} if wide else {},
                           integrator, args.ref_spp, args.ref_chunks, cache)
    return ref.image.astype(np.float64), ref.variance.astype(np.float64).mean(axis=-1)


def low_fractions(errors, row0: int) -> tuple[list[float], list[float]]:
    """Low-frequency share of each error image: whole image, and rows ``row0`` on."""
    return ([low_frequency_fraction(e) for e in errors],
            [low_frequency_fraction(e[row0:]) for e in errors])


def print_blue_noise(label: str, errors: dict, mse: dict, row0: int):
    """lab_zsobol against lab_sobol: mean low-frequency share and their ratio (< 1: bluer),
    with the range of per-seed ratios, whole image and below the light."""
    full, crop = {}, {}
    for n in ("lab_sobol", "lab_zsobol"):
        full[n], crop[n] = low_fractions(errors[n], row0)
    def ratio(d):
        per_seed = [z / s for z, s in zip(d["lab_zsobol"], d["lab_sobol"])]
        return (f"{statistics.mean(d['lab_zsobol']) / statistics.mean(d['lab_sobol']):.3f} "
                f"(per seed {min(per_seed):.2f}..{max(per_seed):.2f})")
    print(f"  {label}: MSE zsobol {mse['lab_zsobol']:.3e} sobol {mse['lab_sobol']:.3e} | "
          f"below the light (rows {row0}..): zsobol {statistics.mean(crop['lab_zsobol']):.4f} "
          f"sobol {statistics.mean(crop['lab_sobol']):.4f} ratio {ratio(crop)} | "
          f"whole image: ratio {ratio(full)}")


def blue_noise_study(args):
    """Low-frequency share of the error power (lowest quarter of radial frequencies):
    lab_zsobol against lab_sobol at low spp, per max_depth (2 = direct lighting only),
    each seed's error image apart; on the square film, on a non-square crop window of it
    (its lower half: same pixels and reference, a res x res/2 block), on a non-square
    res x res/2 film (``wide_film_xml``), and on that film with a deliberately wrong
    layout (lab_zsobol given width res/2 + 1 in a plain mi.render: the measure's power)."""
    print("\nblue noise: share of error power below 1/4 Nyquist (white noise: 0.0625), "
          "mean over seeds; ratio zsobol/sobol (< 1: bluer)")
    names = ("lab_sobol", "lab_zsobol")
    res, half = args.res, args.res // 2
    crop = (f'<integer name="crop_offset_y" value="{half}"/><integer name="crop_height" value="{half}"/>'
            f'<integer name="crop_width" value="{res}"/>')
    for depth in args.blue_depths:
        ref_args = argparse.Namespace(**{**vars(args), "max_depth": depth, "ref_spp": args.blue_ref_spp})
        ref, floor_map = reference(ref_args)
        wide_ref, wide_floor = reference(ref_args, wide=True)
        cases = (  # label, film, reference, its noise floor map
            (f"square {res}x{res}", "", ref, floor_map),
            (f"crop {res}x{half} (lower half)", crop, ref[half:], floor_map[half:]),
            (f"film {res}x{half}", "wide", wide_ref, wide_floor))
        wrong_width = f'<integer name="width" value="{half + 1}"/>'
        for spp in args.blue_spp:
            for label, film, case_ref, case_floor in cases:
                row0 = rows_below_bright(case_ref, args.emitter_threshold)
                scenes = {n: scene(n, res, spp, depth, film) for n in names}
                errors, mse = blue_errors(scenes, case_ref, case_floor, args.blue_seeds)
                print_blue_noise(f"max_depth {depth} spp {spp:4d} {label:24s}", errors, mse, row0)
                if not film:     # the square film's errors on the crop's rows, for comparison
                    print_blue_noise(f"max_depth {depth} spp {spp:4d} {'square, rows of the crop':24s}",
                                     errors, mse, half)
            # the wide film (the last case; its lab_sobol errors kept), lab_zsobol in a wrong layout
            wrong = {"lab_zsobol": scene("lab_zsobol", res, spp, depth, "wide", wrong_width)}
            wrong_errors, wrong_mse = blue_errors(wrong, wide_ref, wide_floor, args.blue_seeds, bind=False)
            print_blue_noise(f"max_depth {depth} spp {spp:4d} {'film, width ' + str(half + 1) + ' (wrong)':24s}",
                             {**errors, **wrong_errors}, {**mse, **wrong_mse}, row0)


def blue_errors(scenes: dict, ref: np.ndarray, floor_map: np.ndarray, seeds: int, bind: bool = True):
    """Error images of each scene's renders (after a warm-up render), seeds 0..seeds-1, and
    each scene's mean MSE less the reference's noise floor."""
    errors = {}
    for n, sc in scenes.items():
        render(sc, 999, bind)
        errors[n] = [render(sc, seed, bind)[0] - ref for seed in range(seeds)]
    mse = {n: statistics.mean(float(np.mean(e ** 2)) for e in errs) - float(floor_map.mean())
           for n, errs in errors.items()}
    return errors, mse


def paired_ratio(times, reference_times) -> float:
    """Median over rounds of time / reference time in the same round: renders of one
    round run back to back, so slow phases of a shared machine cancel (nan without
    a reference)."""
    if not reference_times:
        return float("nan")
    return statistics.median(t / r for t, r in zip(times, reference_times))


def timing_study(args):
    """Render time of every sampler against Mitsuba's ``independent``, nothing else (no
    reference, no MSE): warm-up renders, then ``--seeds`` rounds in which every sampler
    renders once, in an order rotated by one each round (no sampler always follows the
    same one); the paired ratio is the median over rounds of time / independent's time."""
    names = ["independent"] + [n for n in args.samplers if n != "independent"]
    print(f"render time against independent: Cornell box {args.res}^2, path max_depth {args.max_depth}, "
          f"{args.seeds} rounds (paired: median of per-round ratios)")
    print(f"{'sampler':18s} {'spp':>5s} {'min ms':>8s} {'/indep':>7s} {'paired /indep':>14s} {'IQR':>13s}")
    for spp in args.spp:
        scenes = {name: scene(name, args.res, spp, args.max_depth) for name in names}
        for name in names:
            render(scenes[name], 999)                        # warm-up: compile
        times = {name: [] for name in names}
        for seed in range(args.seeds):
            shift = seed % len(names)
            for name in names[shift:] + names[:shift]:
                times[name].append(render(scenes[name], seed)[1])
        t_ind = min(times["independent"])
        for name in names:
            ratios = sorted(t / r for t, r in zip(times[name], times["independent"]))
            q1, q3 = np.percentile(ratios, [25, 75])
            print(f"{name:18s} {spp:5d} {1e3 * min(times[name]):8.1f} {min(times[name]) / t_ind:7.3f} "
                  f"{paired_ratio(times[name], times['independent']):14.3f}   {q1:.3f}..{q3:.3f}")


def integrand_study(args):
    """Pixel-integral MSE of each sampler's first dimension pair on smooth and
    discontinuous 2D integrands, against multijitter: where Owen-scrambled nets win."""
    names = [n for n in args.samplers if n != "orthogonal"]   # orthogonal changes the spp
    exact = "lab_sobol" in names and all(1 << log2_ceil(n) == n for n in args.integrand_spp)
    if exact:
        names.append("exact Owen")
    print(f"\n2D pixel integrals ({args.integrand_pixels} random integrands per family, "
          f"{args.integrand_seeds} seeds): MSE / multijitter's (+- relative standard error)")
    families = integrand_families(args.integrand_pixels, np.random.default_rng(2024))
    print(f"{'sampler':16s} " + " ".join(f"{fam + ' ' + str(spp):>17s}"
                                         for fam in families for spp in args.integrand_spp))
    sq = {}
    for name in names:
        pair = exact_owen_pair if name == "exact Owen" else partial(first_pair, name)
        for spp in args.integrand_spp:
            per_seed = pixel_integral_mse(pair, spp, families, range(args.integrand_seeds))
            for fam, values in per_seed.items():
                sq[name, fam, spp] = mean_se(values)
    for name in names:
        cells = []
        for fam in families:
            for spp in args.integrand_spp:
                (m, se), base = sq[name, fam, spp], sq["multijitter", fam, spp][0]
                cells.append(f"{m / base:8.3f} +-{100 * se / m:4.1f}%")
        print(f"{name:16s} " + " ".join(f"{c:>17s}" for c in cells))
    if exact:
        print("(exact Owen: the same Sobol points with exactly nested uniform scrambling in numpy,"
              " a reference for lab_sobol's hash-based scramble)")


def mean_se(values) -> tuple[float, float]:
    return statistics.mean(values), statistics.stdev(values) / len(values) ** 0.5


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, nargs="*", default=[64, 256], help="none: skip the main table")
    ap.add_argument("--seeds", type=int, default=8,
                    help="renders (rounds) per sampler and spp, each timed")
    ap.add_argument("--blue-spp", type=int, nargs="*", default=[4, 16],
                    help="extra sample counts for the blue-noise comparison (lab_sobol, lab_zsobol only)")
    ap.add_argument("--ref-spp", type=int, default=16384)
    ap.add_argument("--ref-chunks", type=int, default=16)
    ap.add_argument("--ref-sampler", default="ldsampler",
                    help="sampler of the reference renders (its spp per chunk must suit it)")
    ap.add_argument("--ref-cache", default=os.environ.get("MITSUBA_LAB_CACHE") or DEFAULT_CACHE,
                    help=f"reference cache folder (default: $MITSUBA_LAB_CACHE, else {DEFAULT_CACHE})")
    ap.add_argument("--max-depth", type=int, default=6)
    ap.add_argument("--emitter-threshold", type=float, default=5.0,
                    help="reference luminance above which a pixel sees the light directly")
    ap.add_argument("--samplers", nargs="+", default=None,
                    help="default: every Mitsuba and lab sampler (with --timing-only: the lab samplers)")
    ap.add_argument("--blue-depths", type=int, nargs="*", default=[2, 6],
                    help="max_depth values of the low-spp blue-noise study (2 = direct lighting); none: skip it")
    ap.add_argument("--blue-study-spp", dest="blue_spp_study", type=int, nargs="+", default=[1, 2, 4, 16])
    ap.add_argument("--blue-seeds", type=int, default=8)
    ap.add_argument("--blue-ref-spp", type=int, default=4096)
    ap.add_argument("--integrand-spp", type=int, nargs="*", default=[16, 64, 256],
                    help="sample counts of the 2D pixel-integral study (none: skip it)")
    ap.add_argument("--integrand-pixels", type=int, default=4096, help="random integrands per family")
    ap.add_argument("--integrand-seeds", type=int, default=8)
    ap.add_argument("--timing-only", action="store_true",
                    help="only the render-time table of --samplers (default: the lab samplers) against "
                         "independent at each --spp, --seeds rounds; no reference, MSE or studies")
    args = ap.parse_args()
    if args.samplers is None:
        args.samplers = list(LAB if args.timing_only else MITSUBA + LAB)
    for spp in {args.ref_spp, args.blue_ref_spp}:
        if args.ref_chunks < 2 or spp % args.ref_chunks:
            ap.error(f"--ref-chunks ({args.ref_chunks}) must be >= 2 and divide the reference spp ({spp})")
    if args.timing_only:
        timing_study(args)
        return
    if args.integrand_spp and "multijitter" not in args.samplers:
        ap.error("the 2D pixel-integral study compares with multijitter: add it to --samplers or pass --integrand-spp")

    if not args.spp:
        args.spp, args.blue_spp = [], []
    if args.spp:
        t0 = time.perf_counter()
        ref, floor_map = reference(args)
        lit = bright_mask(ref, args.emitter_threshold)
        floor, floor_unlit = float(floor_map.mean()), float(floor_map[~lit].mean())
        print(f"reference: {args.res}^2, {args.ref_spp} spp ({args.ref_sampler}) in {args.ref_chunks} chunks, "
              f"{time.perf_counter() - t0:.0f} s; noise floor (MSE of the reference) {floor:.3e}; "
              f"{int(lit.sum())} pixels see the light (or touch one that does)")

        rows, errors = {}, {}
        for spp in sorted(set(args.spp + args.blue_spp)):
            names = args.samplers if spp in args.spp else [n for n in ("lab_sobol", "lab_zsobol") if n in args.samplers]
            scenes = {name: scene(name, args.res, spp, args.max_depth) for name in names}
            mses = {name: ([], []) for name in names}
            times = {name: [] for name in names}
            for name in names:
                render(scenes[name], 999)                        # warm-up: compile
            # Seeds interleaved across samplers, so load on the machine hits all alike.
            for seed in range(args.seeds):
                for name in names:
                    img, t = render(scenes[name], seed)
                    sq = np.mean((img - ref) ** 2, axis=-1)
                    mses[name][0].append(float(sq.mean()) - floor)
                    mses[name][1].append(float(sq[~lit].mean()) - floor_unlit)
                    times[name].append(t)
                    errors.setdefault((name, spp), []).append(img - ref)
            for name in names:
                rows[name, spp] = (mean_se(mses[name][0]), mean_se(mses[name][1]),
                                   min(times[name]), paired_ratio(times[name], times.get("independent")))

        print(f"\n{'sampler':16s} {'spp':>5s} {'MSE-floor':>19s} {'/bestMI':>8s} {'unlit MSE':>19s} {'/bestMI':>8s} "
              f"{'min ms':>8s} {'/indep':>7s} {'paired /indep':>14s}")
        print("(+- one standard error over the seeds; unlit: without the pixels that see the light; /bestMI:"
              " against the best Mitsuba sampler that really uses the requested spp, orthogonal rounds spp up"
              " to a prime squared and is left out of it; min ms /indep: ratio of the fastest renders;"
              " paired /indep: median over the seeds of the time over independent's in the same round)")
        for spp in args.spp:
            best = [min(rows[n, spp][k][0] for n in MITSUBA if (n, spp) in rows and n != "orthogonal")
                    for k in (0, 1)]
            t_ind = rows["independent", spp][2]
            for name in args.samplers:
                (mse, se), (mse_u, se_u), t, paired = rows[name, spp]
                print(f"{name:16s} {spp:5d} {mse:10.3e}+-{se:7.1e} {mse / best[0]:8.3f} "
                      f"{mse_u:10.3e}+-{se_u:7.1e} {mse_u / best[1]:8.3f} "
                      f"{1e3 * t:8.1f} {t / t_ind:7.3f} {paired:14.3f}")

        if "lab_sobol" in args.samplers and "lab_zsobol" in args.samplers:
            print("\nblue noise: share of error power in the lowest quarter of radial frequencies")
            row0 = rows_below_bright(ref, args.emitter_threshold)
            for spp in sorted(set(args.spp + args.blue_spp)):
                print_blue_noise(f"spp {spp:4d}", {n: errors[n, spp] for n in ("lab_sobol", "lab_zsobol")},
                                 {n: rows[n, spp][0][0] for n in ("lab_sobol", "lab_zsobol")}, row0)

    if args.integrand_spp:
        integrand_study(args)
    if args.blue_depths:
        blue_noise_study(argparse.Namespace(**{**vars(args), "blue_spp": args.blue_spp_study}))


if __name__ == "__main__":
    main()
