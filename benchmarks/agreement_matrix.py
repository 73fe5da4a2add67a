"""The full parameter matrices of agreement tests that the suite runs only in part.

Some of the suite's agreement tests exercise one code path over many parameter combinations;
the suite keeps the cases that each cover something distinct (each test module says which and
why), and this script runs every case of the full list with the test's own code:

    .venv/bin/python benchmarks/agreement_matrix.py [--only NAME] [--left-out] [--list]

Prints one line per case: PASS, or FAIL with the assertion's message (the tests print their
max |z| as they go).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [os.path.join(ROOT, "tests"), os.path.join(ROOT, "tests", "plugins")]

#: name -> (test module, test function, the module's attribute listing the full matrix)
MATRICES = {
    "vcm_spectral": ("test_vcm", "test_spectral_variant_agrees_with_mitsuba_path", "SPECTRAL_MATRIX"),
    "sensor_and_projector": ("test_sensor_and_projector", "test_agrees_with_mitsuba_path", "AGREEMENT_MATRIX"),
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", choices=sorted(MATRICES), help="one matrix (default: all)")
    parser.add_argument("--left-out", action="store_true", help="only the cases the suite leaves out")
    parser.add_argument("--list", action="store_true", help="print the cases and exit")
    args = parser.parse_args(argv)

    import importlib

    import mitsuba_lab  # noqa: F401  (selects the variant, registers the lab plugins)

    os.chdir(ROOT)                         # the tests name scenes relative to the project root
    failures = 0
    for name in [args.only] if args.only else list(MATRICES):
        module_name, function_name, matrix_name = MATRICES[name]
        module = importlib.import_module(module_name)
        test, matrix = getattr(module, function_name), getattr(module, matrix_name)
        in_suite = set(getattr(module, matrix_name.replace("MATRIX", "CASES"), []))
        for case in matrix:
            if args.left_out and case in in_suite:
                continue
            label = f"{name} {case}" + (" (in the suite)" if case in in_suite else "")
            if args.list:
                print(label)
                continue
            start = time.perf_counter()
            try:
                test(*case)
                verdict = "PASS"
            except AssertionError as error:
                failures += 1
                verdict = f"FAIL: {str(error).splitlines()[0] if str(error) else 'assertion'}"
            print(f"{label}: {verdict} ({time.perf_counter() - start:.0f} s)", flush=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
