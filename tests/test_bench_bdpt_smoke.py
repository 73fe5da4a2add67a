"""Smoke run of benchmarks/bench_bdpt.py --quick: it runs and prints its three tables and verdicts.

Timings are not checked (the machine is shared); the memory bound is deterministic and is."""
import importlib.util
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.slow
def test_bench_bdpt_quick(capsys):
    spec = importlib.util.spec_from_file_location("bench_bdpt", os.path.join(ROOT, "benchmarks", "bench_bdpt.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--quick"]) == 0
    out = capsys.readouterr().out
    for heading in ("1. Light subpath tracing vs ptracer", "2. Full render", "3. Light-vertex memory"):
        assert heading in out
    assert out.count("VERDICT") == 4
    assert "VERDICT memory: peak_vertex_bytes <= max_vertices x" in out and out.rstrip().endswith("MET")
    assert "NOT MET" not in out.splitlines()[-1]
