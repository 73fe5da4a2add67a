"""lab_vcm's ppm against lab_photon at equal light vertices, at the size the check was written for.

``benchmarks/agreement/test_vcm_matrix.py::test_merging_has_lab_photons_variance_at_equal_light_vertices``
(the suite's copy until 2026-11-28, ``test_vcm.check_merging_has_lab_photons_variance_at_equal_light_vertices``) runs
it on 8 seeds a side (the ratio within 0.6, 5 bootstrap standard errors there: enough to catch
the bug it guards, a pass's lanes sharing light vertices, at 2.36). Here, as first written: 24
seeds a side, the ratio of the mean per-pixel variances on sds.xml's directly lit back wall must
be 1 within 0.2 (5 standard errors of ~0.038), and iterations in blocks of 64 lanes (8 seeds)
must measure above 1.2. About 65 CPU seconds.

    .venv/bin/python benchmarks/vcm_variance.py [--seeds 24] [--blocked-seeds 8]

Prints both ratios with their bootstrap standard errors; exits 1 if either bound fails.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [os.path.join(ROOT, "tests"), os.path.join(ROOT, "tests", "plugins")]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=24, help="seeds a side for the ratio (default 24)")
    parser.add_argument("--blocked-seeds", type=int, default=8, help="seeds of the blocked lanes' ppm (default 8)")
    parser.add_argument("--bound", type=float, default=0.2, help="|ratio - 1| bound (default 0.2)")
    args = parser.parse_args(argv)

    import mitsuba_lab  # noqa: F401  (selects the variant, registers the lab plugins)

    os.chdir(ROOT)
    import test_vcm as t

    start = time.process_time()
    lab, photon = t.ppm_and_photon_wall(range(args.seeds))
    blocked, _ = t.ppm_and_photon_wall(range(args.blocked_seeds), blocked=True)
    ratio, wrong = t.variance_ratio(lab, photon), t.variance_ratio(blocked, photon)
    print(f"ppm / lab_photon, {args.seeds} seeds a side: {ratio:.3f} +- {t.bootstrap_error(lab, photon):.3f}")
    print(f"blocks of 64 lanes, {args.blocked_seeds} seeds: {wrong:.3f} +- {t.bootstrap_error(blocked, photon):.3f}")
    print(f"CPU {time.process_time() - start:.0f} s")
    ok = abs(ratio - 1) < args.bound and wrong > 1 + args.bound
    print("PASS" if ok else f"FAIL (bound {args.bound})")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
