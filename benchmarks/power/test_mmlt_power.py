"""The power proof of tests/plugins/test_mmlt.py's block test (8 lab_mmlt renders beside the
suite's `path` stack, about 10 CPU s, so it left the suite); prints its summary (recorded in
experiments/results/2026-11-28-power-proofs.md).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/power/test_mmlt_power.py
"""
from agreement import block_test, renders
from mitsuba_lab.scene import make_integrator
from test_mmlt import BLOCK, MMLT, SPP, cornell, path_reference


def test_leaving_out_the_strategy_probability_fails_the_block_test(monkeypatch):
    """Power: a sample not divided by its strategy's probability 1 / (k + 1) is the image over
    k + 1 on average: 8 renders fail (measured: max |z| 42.2, 16 of 16 blocks, ratios 0.24-0.48)."""
    from mitsuba_lab.plugins.integrators.mlt import mmlt

    monkeypatch.setattr(mmlt, "strategy_probability", lambda n_strategies: 1.0)
    lab = renders(cornell(), make_integrator("lab_mmlt", MMLT), SPP, range(8))
    result = block_test(lab, path_reference(), BLOCK)
    print(f"strategy probability left out: {result.summary()}")
    assert result.failing
