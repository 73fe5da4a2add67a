"""Power proof that left tests/plugins/test_block_agreement.py (a 64-seed lab_bdpt stack of its
own): lab_bdpt with its light-tracing (t = 1) weights x 1.03 fails the block test on the material
grid (a per-pixel z-test at these sample counts does not see it). Prints the block test's
summary (recorded in experiments/results/2026-11-28-power-proofs.md).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/power/test_block_power.py
"""
from agreement import block_test
from test_block_agreement import SEEDS_LAB, assets, direct_reference, load, material_grid, stack  # noqa: F401


def test_a_three_percent_bias_on_one_strategy_fails_the_block_test(assets, monkeypatch):  # noqa: F811
    from mitsuba_lab.plugins.integrators.bdpt import integrator
    from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights

    class Perturbed(BdptWeights):
        def light_to_camera(self, *args, **kwargs):
            return 1.03 * super().light_to_camera(*args, **kwargs)

    monkeypatch.setattr(integrator, "BdptWeights", Perturbed)
    scene = load(assets, "grid", material_grid())
    result = block_test(stack(scene, "lab_bdpt", {}, SEEDS_LAB), direct_reference(scene, "grid"))
    print("t = 1 weight x 1.03:", result.summary())
    assert result.failing
