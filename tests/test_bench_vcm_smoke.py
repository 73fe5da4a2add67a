"""Smoke run of benchmarks/bench_vcm.py --quick: it runs and prints one row per scene with every
column (timings are not checked: the machine is shared), and nothing compiles while timed."""
import importlib.util
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_bench_vcm_quick(capsys):
    spec = importlib.util.spec_from_file_location("bench_vcm", os.path.join(ROOT, "benchmarks", "bench_vcm.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--quick"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-2].startswith("scene | light | grid | camera+conn | merging")
    row = lines[-1].split(" | ")
    assert row[0] == "cornell_box.xml" and len(row) == 13
    assert row[-1] == "0"                                     # no kernel compiled while timed
