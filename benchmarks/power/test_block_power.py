"""Power proof that left tests/plugins/test_block_agreement.py (a 64-seed lab_bdpt stack of its
own): lab_bdpt with its light-tracing (t = 1) weights x 1.03 fails the block test on the material
grid (``check_light_tracing_bias_fails``; a per-pixel z-test at these sample counts does not see
it). Prints the block test's summary (recorded in experiments/results/2026-11-28-power-proofs.md).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/power/test_block_power.py
"""
from test_block_agreement import assets, check_light_tracing_bias_fails  # noqa: F401  (a fixture)


def test_a_three_percent_bias_on_one_strategy_fails_the_block_test(assets, monkeypatch):  # noqa: F811
    check_light_tracing_bias_fails(assets, monkeypatch)
