"""Same images before and after a refactor: every lab integrator and sampler, fixed seeds.

Renders each configuration below on two scenes (the Cornell box and Veach's MIS scene, plus
the glass-sphere caustic for lab_photon) with fixed seeds and either saves the images
(``--save DIR``) or compares them with saved ones (``--compare DIR``), printing per
configuration the largest per-pixel relative difference |a - b| / max(|b|, 1e-2) (pixels
darker than 1e-2 are compared absolutely, at the same scale). A behaviour-preserving change
keeps every row at or below ``--tolerance`` (default 1e-4); exit status 1 otherwise.

    .venv/bin/python benchmarks/image_regression.py --save out/images_before
    .venv/bin/python benchmarks/image_regression.py --compare out/images_before
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

import mitsuba_lab  # noqa: F401  (registers the plugins)
from mitsuba_lab.render import render
from mitsuba_lab.scene_xml import load_scene_variant

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = ("cornell_box.xml", "veach_mis.xml")
RES, SPP, SEED, DEPTH = 32, 16, 7, 6

INTEGRATORS = {
    "naive": ("lab_naive", {}),
    "nee": ("lab_nee", {}),
    "mis_balance": ("lab_mis", {"heuristic": "balance"}),
    "mis_power": ("lab_mis", {"heuristic": "power"}),
    "mis_power_b3": ("lab_mis", {"heuristic": "power", "beta": 3.0}),
    "mis_max": ("lab_mis", {"heuristic": "max"}),
    "mis_average": ("lab_mis", {"heuristic": "average"}),
    "mis_balance_nl2": ("lab_mis", {"heuristic": "balance", "emitter_samples": 2}),
    "mis_power_nl3": ("lab_mis", {"heuristic": "power", "emitter_samples": 3}),
    "mis_hidden": ("lab_mis", {"hide_emitters": True, "rr_depth": 2}),
    "photon_nee": ("lab_photon", {"photons_per_pass": 20000, "passes": 2, "direct": "nee"}),
    "photon_photons": ("lab_photon", {"photons_per_pass": 20000, "passes": 2, "direct": "photons"}),
}
SAMPLERS = {
    "independent": {"type": "lab_independent"},
    "stratified": {"type": "lab_stratified"},
    "stratified_nojitter": {"type": "lab_stratified", "jitter": False},
    "halton_owen": {"type": "lab_halton"},
    "halton_permute": {"type": "lab_halton", "randomization": "permute_digits"},
    "sobol": {"type": "lab_sobol"},
    "zsobol": {"type": "lab_zsobol"},
}


def configurations():
    """(name, scene file, integrator type, parameters, sampler dict or None, spp)."""
    for scene in SCENES:
        for name, (kind, params) in INTEGRATORS.items():
            spp = 2 if kind == "lab_photon" else SPP
            yield f"{scene[:-4]}/{name}", scene, kind, params, None, spp
        for name, sampler in SAMPLERS.items():
            yield f"{scene[:-4]}/sampler_{name}", scene, "lab_mis", {}, sampler, SPP
    for name in ("photon_nee", "photon_photons"):
        kind, params = INTEGRATORS[name]
        yield f"caustic/{name}", "caustic.xml", kind, params, None, 2


def render_all(only: str | None = None):
    from mitsuba_lab.scene import make_integrator

    for name, scene_file, kind, params, sampler, spp in configurations():
        if only and only not in name:
            continue
        scene = load_scene_variant(os.path.join(ROOT, "scenes", scene_file), RES, sampler, {})
        integrator = make_integrator(kind, {"max_depth": DEPTH, **params})
        image, _ = render(scene, integrator, spp=spp, seed=SEED)
        yield name, image


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--save", metavar="DIR", help="write the images to DIR")
    group.add_argument("--compare", metavar="DIR", help="compare with the images saved in DIR")
    parser.add_argument("--tolerance", type=float, default=1e-4, help="largest relative difference")
    parser.add_argument("--only", help="only configurations whose name contains this")
    args = parser.parse_args(argv)
    worst, failures = 0.0, 0
    for name, image in render_all(args.only):
        path = os.path.join(args.save or args.compare, name.replace("/", "__") + ".npy")
        if args.save:
            os.makedirs(args.save, exist_ok=True)
            np.save(path, image)
            print(f"saved {name}: mean {image.mean():.6g}")
            continue
        before = np.load(path)
        diff = np.abs(image.astype(np.float64) - before) / np.maximum(np.abs(before), 1e-2)
        worst = max(worst, float(diff.max()))
        bad = not float(diff.max()) <= args.tolerance
        failures += bad
        print(f"{'FAIL' if bad else 'ok  '} {name:40s} max rel diff {diff.max():.3g}  "
              f"(mean {image.mean():.6g} vs {before.mean():.6g})")
    if args.compare:
        print(f"{failures} configuration(s) over {args.tolerance:g}; largest relative difference {worst:.3g}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
