"""Power proofs that left tests/plugins/test_bdpt.py and test_vcm.py (each renders stacks of its own
at 32-64 spp; the suite keeps test_bdpt's thin-lens density x1.25 and test_vcm's block-test and
roulette proofs). Same code; each prints its max |z| (recorded in
experiments/results/2026-11-28-power-proofs.md).

    PYTHONPATH=src .venv/bin/python -m pytest -q -s -p no:cacheprovider benchmarks/power/test_bdpt_vcm_power.py
"""
from agreement import SEEDS_LAB, Z_BOUND, assert_agrees, renders, scene_path, z_scores
from mitsuba_lab.scene import load_scene
from test_bdpt import POWER_LAB_SPP, bdpt, cornell_reference  # noqa: F401  (a fixture)
from test_vcm import RES, SMALL_RADIUS, path_stack, vcm


def test_a_wrong_weight_is_caught(cornell_reference, monkeypatch):
    """Power of the agreement test: the t = 1 weight multiplied by 1.03 fails it (max |z| past
    Z_BOUND: 8.36 at POWER_LAB_SPP against the POWER_REF_SPP reference; 12.5 at 64 against 1024)."""
    from mitsuba_lab.plugins.integrators.bdpt import integrator
    from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights

    scene, ref = cornell_reference
    assert_agrees(renders(scene, bdpt(), POWER_LAB_SPP, SEEDS_LAB), ref, "lab_bdpt on the Cornell box, 32 spp")

    class Perturbed(BdptWeights):
        def light_to_camera(self, *args, **kwargs):
            return 1.03 * super().light_to_camera(*args, **kwargs)

    monkeypatch.setattr(integrator, "BdptWeights", Perturbed)
    wrong = renders(scene, bdpt(), POWER_LAB_SPP, SEEDS_LAB)
    z = z_scores(wrong, ref).max_abs_z
    print(f"t = 1 weight x 1.03: max |z| {z:.2f}")
    assert z > Z_BOUND


def test_a_wrong_merging_normalisation_is_caught(monkeypatch):
    """Power: merges 10% too bright (bpm merging at every camera vertex, where merging carries most
    of the image; 64 iterations x 16 seeds: |z| 5.1 at 32 with the Epanechnikov kernel's 4/3
    the variance) fail. (3% at 16 iterations gave |z| 1.9: bpm's noise at r_1 = 0.02
    hides it; lab_bdpt's test catches 3% in the connection weights.)"""
    from mitsuba_lab.plugins.integrators.vcm import merging

    scene = load_scene(scene_path("cornell_box.xml"), res=RES)
    ref = path_stack("cornell_box.xml")
    original = merging.VertexGrid.__init__

    def brighter(self, *args, **kwargs):
        original(self, *args, **kwargs)
        self.normalisation = self.normalisation * 1.10

    monkeypatch.setattr(merging.VertexGrid, "__init__", brighter)
    wrong = renders(scene, vcm(mode="bpm", radius=SMALL_RADIUS, merge_first=True), 64, SEEDS_LAB)
    z = z_scores(wrong, ref).max_abs_z
    print(f"merges x 1.10: max |z| {z:.2f}")
    assert z > Z_BOUND
