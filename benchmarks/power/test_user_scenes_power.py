"""Power proof that left tests/plugins/test_user_scenes.py (it renders a stack of its own; the suite
keeps lab_mis x 1.03, which scales its kept Latin-square stack): lab_mis with one bounce too few
fails the agreement check on textured_mesh_room. Prints both max |z| (recorded in
experiments/results/2026-11-28-power-proofs.md).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/power/test_user_scenes_power.py
"""
import pytest

from agreement import Z_BOUND
from test_user_scenes import RGB, agreement, assets, describe, variant  # noqa: F401  (fixtures)


@pytest.mark.parametrize("variant", [RGB], indirect=True)
def test_a_biased_renderer_fails(variant, assets):  # noqa: F811
    name = "textured_mesh_room"
    scaled = agreement(assets, name, "lab_mis", "lab_sobol", scale=1.03)
    print(f"lab_mis x 1.03 on {name}: max |z| {scaled.max_abs_z:.2f}")
    assert scaled.max_abs_z > Z_BOUND, describe(scaled, name, "lab_mis x 1.03", "lab_sobol", variant)
    shallow = agreement(assets, name, "lab_mis", "lab_sobol", depth_change=-1)
    print(f"lab_mis max_depth - 1 on {name}: max |z| {shallow.max_abs_z:.2f}")
    assert shallow.max_abs_z > Z_BOUND, describe(shallow, name, "lab_mis (max_depth - 1)", "lab_sobol", variant)
