"""Users' scenes, the full table: every scene x variant x lab estimator x lab sampler against
Mitsuba's `path`.

The scenes are tests/user_scenes.py's (OBJ and PLY meshes, PNG and EXR textures, normal and
bump maps, principled, blended and plastic materials, textured area, spot, directional and
point lights, environment maps, instancing, orthographic and thin-lens sensors, non-square
films and crop windows), written into a temporary folder and loaded under each variant.

Path tracers (lab_naive, lab_nee, lab_mis; those the estimator says apply) x every lab
sampler: --seeds renders at the scene's test spp x --spp-scale, against `path` (Mitsuba's
independent sampler, --seeds other seeds at --ref-scale x that spp), by z-scores of 8x8 block
means and image means per channel (tests/agreement.py). Under agreement each z is about
Student-t with >= seeds - 1 degrees of freedom. The full table computes ~15000 z-scores;
with 32 seeds P(|t_31| > 7.0) = 7.4e-8, so a correct table shows a false FAIL with
probability ~1e-3 (Bonferroni). "det. bias" is the smallest relative bias of the image mean
that the bound detects: Z x (standard error of the image-mean difference) / mean, worst
channel and worst sampler of the row. Every image is also checked for NaN/Inf and negative
pixels (spectral: negative luminance; its RGB film is negative outside the sRGB gamut).

lab_zsobol on a non-square block is first tried as users write it (no `width`); if that
fails, the error is shown and it runs again with `width` (marked "w").

lab_photon (consistent, not unbiased): relMSE against the reference mean after P passes of
--photons photons (1 camera sample per pass), and the log-log slope of relMSE against P
(-1 would be the variance-only rate). It passes when relMSE falls to <= 0.3 x from the
first to the last P and ends <= 0.1. Where the estimator says it does not apply, the
table shows the reason and the numbers anyway.

    .venv/bin/python benchmarks/user_scenes.py [--quick] [--seeds 32] [--spp-scale 2]

Measured on a shared 2-core machine: the full table in 5.7 minutes (84 rows, 0 FAIL),
--quick in 1.8 minutes. --quick: the test suite's Latin square (each sampler once per scene,
paired with a path tracer) at the test budget, lab_photon at 1 and 8 passes.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tests"))

import mitsuba_lab  # noqa: E402  (points Dr.Jit at libLLVM first; selects llvm_ad_rgb)
import mitsuba as mi  # noqa: E402
import user_scenes as us  # noqa: E402
from agreement import pixel_problem, renders, z_scores  # noqa: E402
from mitsuba_lab.metrics import rel_mse  # noqa: E402
from mitsuba_lab.scene import (SceneTraits, equivalence_reason, equivalent_strategies,  # noqa: E402
                               make_integrator, strategy_applicability)

VARIANTS = ("llvm_ad_rgb", "llvm_ad_mono", "llvm_ad_spectral")
SAMPLERS = ("lab_independent", "lab_stratified", "lab_sobol", "lab_zsobol", "lab_halton")
PATH_TRACERS = ("lab_naive", "lab_nee", "lab_mis")
Z_FULL = 7.0
Z_QUICK = 6.5          # ~2500 z-scores, as the test suite
PHOTON_FALL = 0.3
PHOTON_RELMSE = 0.1


def short_error(err: Exception) -> str:
    """The innermost cause's message, on one line (mi.render wraps errors in drjit.custom's)."""
    while err.__cause__ is not None:
        err = err.__cause__
    text = f"{type(err).__name__}: " + " ".join(str(err).split())
    return text if len(text) < 110 else text[:107] + "..."


class Table:
    """Runs the cases of one variant and collects the rows."""

    def __init__(self, args, assets):
        self.args, self.assets = args, assets
        self.z_max = Z_QUICK if args.quick else Z_FULL
        self.rows, self.photon_rows, self.errors = [], [], []
        self.variant = ""

    # -- helpers ---------------------------------------------------------------------
    def spp(self, name):
        base = 16 if name == "spot_and_directional" else 8
        return base if self.args.quick else base * self.args.spp_scale

    def seeds(self, base):
        return range(self.args.seed_offset + base, self.args.seed_offset + base + self.args.seeds)

    def lab_stack(self, name, estimator, sampler, params):
        scene = us.load(self.assets, name, sampler, self.spp(name), params)
        integrator = make_integrator(estimator, {"max_depth": us.max_depth(name)})
        return renders(scene, integrator, self.spp(name), self.seeds(0))

    # -- one variant ---------------------------------------------------------------------
    def run_variant(self, variant, names):
        mitsuba_lab.use_variant(variant)
        mi.set_log_level(mi.LogLevel.Error)     # Mitsuba logs to stdout: keep the table clean
        spectral = mi.is_spectral
        self.variant = variant
        for name in names:
            start, k = time.perf_counter(), list(us.SCENES).index(name)   # k: as in the tests
            depth = us.max_depth(name)
            ref_spp = self.args.ref_scale * self.spp(name)
            ref_scene = us.load(self.assets, name, "independent", ref_spp)
            ref = renders(ref_scene, make_integrator("path", {"max_depth": depth}), ref_spp, self.seeds(10_000))
            ref_problem = pixel_problem(ref, spectral)
            if ref_problem:
                self.errors.append(f"{variant} {name}: Mitsuba's path: {ref_problem}")
            traits = SceneTraits.from_scene(ref_scene)
            tracers = [e for e in PATH_TRACERS if strategy_applicability(traits, e, {"max_depth": depth})[0]]
            same = equivalent_strategies(traits, {e: (e, {"max_depth": depth}) for e in tracers})
            budget = f"{self.spp(name)} x {self.args.seeds}"
            for estimator in PATH_TRACERS:
                ok, reason = strategy_applicability(traits, estimator, {"max_depth": depth})
                if not ok:
                    self.rows.append([name, variant, estimator, "-", *["-"] * len(SAMPLERS), "-", f"n/a: {reason}"])
                    continue
                cells, det, failures = [], 0.0, []
                for i, sampler in enumerate(SAMPLERS):
                    if self.args.quick and tracers[(i + k) % len(tracers)] != estimator:
                        cells.append("")
                        continue
                    cell, result, stack = self.agreement_cell(name, estimator, sampler, ref)
                    if result is not None:
                        problem = pixel_problem(stack, spectral)
                        se = np.abs(result.rel_diff / np.where(result.image_z == 0, np.inf, result.image_z))
                        det = max(det, self.z_max * float(se.max()))
                        if result.max_abs_z > self.z_max or problem:
                            failures.append(f"{sampler}: |z| {result.max_abs_z:.1f}"
                                            + (f", {problem}" if problem else ""))
                    else:
                        failures.append(f"{sampler}: error")
                    cells.append(cell)
                verdict = "pass" if not failures else "FAIL (" + "; ".join(failures) + ")"
                if same[estimator] != estimator:
                    verdict += (f" (= {same[estimator]}: "
                                f"{equivalence_reason(traits, estimator, {'max_depth': depth})})")
                self.rows.append([name, variant, estimator, budget, *cells, f"{100 * det:.1f}%", verdict])
            self.photon_row(name, variant, traits, ref.mean(axis=0), spectral)
            print(f"{variant} {name}: {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)

    def agreement_cell(self, name, estimator, sampler, ref):
        """(cell text, Agreement or None, stack or None) for one estimator x sampler."""
        width, height = us.SCENES[name].block
        mark = ""
        try:
            stack = self.lab_stack(name, estimator, sampler, None)
        except Exception as err:       # noqa: BLE001 (any failure is a table entry)
            if sampler != "lab_zsobol" or width == height:
                self.errors.append(f"{self.variant} {name} / {estimator} / {sampler}: {short_error(err)}")
                return "ERR", None, None
            self.errors.append(f"{self.variant} {name} / {estimator} / {sampler} without width: "
                               f"{short_error(err)}")
            mark = " w"
            try:
                stack = self.lab_stack(name, estimator, sampler, {"width": width})
            except Exception as err2:  # noqa: BLE001
                self.errors.append(f"{self.variant} {name} / {estimator} / {sampler} with width: "
                                   f"{short_error(err2)}")
                return "ERR", None, None
        result = z_scores(stack, ref)
        return f"{result.max_abs_z:.2f}{mark}", result, stack

    def photon_row(self, name, variant, traits, ref_mean, spectral):

        passes = (1, 8) if self.args.quick else (1, 4, 16)
        ok, reason = strategy_applicability(traits, "lab_photon", {})
        sampler = SAMPLERS[list(us.SCENES).index(name) % len(SAMPLERS)]
        width, height = us.SCENES[name].block
        params = {"width": width} if sampler == "lab_zsobol" and width != height else None
        errors = []
        try:
            scene = us.load(self.assets, name, sampler, 1, params)
            for p in passes:
                integrator = make_integrator("lab_photon", {"photons_per_pass": self.args.photons, "passes": p,
                                                            "max_depth": us.max_depth(name)})
                image = renders(scene, integrator, 1, [self.args.seed_offset + 7])
                problem = pixel_problem(image, spectral)
                if problem:
                    raise ValueError(f"pixels: {problem}")
                errors.append(rel_mse(image[0], ref_mean))
        except Exception as err:       # noqa: BLE001
            self.photon_rows.append([name, variant, sampler, "-", "-", "-", f"ERROR: {short_error(err)}"])
            return
        slope = math.log(errors[-1] / errors[0]) / math.log(passes[-1] / passes[0])
        good = errors[-1] <= PHOTON_FALL * errors[0] and errors[-1] <= PHOTON_RELMSE
        verdict = ("pass" if good else "FAIL") + ("" if ok else f" (estimator says n/a: {reason})")
        self.photon_rows.append([name, variant, sampler, f"{self.args.photons} x {passes}",
                                 " / ".join(f"{e:.4f}" for e in errors), f"{slope:.2f}", verdict])


def markdown(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="Latin square at the test budget")
    parser.add_argument("--seeds", type=int, default=32, help="seeds per estimator and per reference (32)")
    parser.add_argument("--spp-scale", type=int, default=2, help="spp = test spp x this (2; --quick: 1)")
    parser.add_argument("--ref-scale", type=int, default=8, help="reference spp = lab spp x this (8)")
    parser.add_argument("--photons", type=int, default=40000, help="lab_photon photons per pass (40000)")
    parser.add_argument("--seed-offset", type=int, default=0, help="shift every seed (other seed sets)")
    parser.add_argument("--scenes", nargs="*", default=list(us.SCENES), choices=list(us.SCENES))
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=list(VARIANTS))
    args = parser.parse_args(argv)

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="user_scenes_") as tmp:
        table = Table(args, us.write_assets(tmp))
        try:
            for variant in args.variants:
                table.run_variant(variant, args.scenes)
        finally:
            mitsuba_lab.use_variant("llvm_ad_rgb")
    from mitsuba_lab.runtime import versions

    print(f"## Users' scenes against Mitsuba's path ({'quick' if args.quick else 'full'}; |z| <= "
          f"{table.z_max}; {versions()})\n")
    print(markdown(["scene", "variant", "estimator", "spp x seeds", *SAMPLERS, "det. bias", "result"], table.rows))
    print("\n### lab_photon: relMSE against the reference as passes grow\n")
    print(markdown(["scene", "variant", "sampler", "photons x passes", "relMSE", "slope", "result"],
                   table.photon_rows))
    if table.errors:
        print("\n### Errors\n")
        print("\n".join(f"- {e}" for e in table.errors))
    fails = sum("FAIL" in row[-1] for row in table.rows + table.photon_rows)
    print(f"\n{len(table.rows)} path-tracer rows, {len(table.photon_rows)} lab_photon rows, {fails} FAIL; "
          f"{time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
