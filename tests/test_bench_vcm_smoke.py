"""Smoke run of benchmarks/bench_vcm.py --quick: it runs and prints one row per scene with every
column (timings are not checked: the machine is shared), and nothing compiles while timed."""
import importlib.util
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.slow
@pytest.mark.parametrize("extra", [[], ["--merge-first"], ["--light-paths", "0.25"], ["--aim", "0.5"],
                                   ["--merge-vertices", "caustic"]])
def test_bench_vcm_quick(capsys, extra):
    spec = importlib.util.spec_from_file_location("bench_vcm", os.path.join(ROOT, "benchmarks", "bench_vcm.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--quick", *extra]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert f"merge_first {'true' if '--merge-first' in extra else 'false'}" in lines[-3]
    assert f"light_paths {'0.25' if '--light-paths' in extra else '1'}," in lines[-3]
    assert f"aim {'0.5' if '--aim' in extra else '0'}," in lines[-3]
    caustic = "--merge-vertices" in extra
    assert f"merge_vertices {'caustic' if caustic else 'all'};" in lines[-3]
    assert lines[-2].startswith("scene | light | grid | camera+conn | merging")
    row = lines[-1].split(" | ")
    assert row[0] == "cornell_box.xml" and len(row) == 14
    assert float(row[-3]) == (0.0 if caustic else 1.0)       # the box has no delta lobe to merge after
    assert row[-1] == "0"                                     # no kernel compiled while timed


@pytest.mark.slow
def test_bench_vcm_pass_sizes_quick(capsys):
    """--pass-sizes prints lab_vcm's ms per iteration with its own pass sizes and fixed ones, and
    puts the integrator's constants back."""
    spec = importlib.util.spec_from_file_location("bench_vcm", os.path.join(ROOT, "benchmarks", "bench_vcm.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    import sys

    from mitsuba_lab.scene import make_integrator

    module = sys.modules[type(make_integrator("lab_vcm", {})).__module__]
    before = module.FIRST_PASS_LIGHT_SUBPATHS
    assert bench.main(["--quick", "--pass-sizes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-2] == "scene | adaptive | 2^14 | 2^16 | 2^18"
    row = lines[-1].split(" | ")
    assert row[0] == "cornell_box.xml" and len(row) == 5 and all(cell.endswith("(1)") for cell in row[1:])
    assert module.FIRST_PASS_LIGHT_SUBPATHS == before
