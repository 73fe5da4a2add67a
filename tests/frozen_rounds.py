"""The chain estimators' frozen lock-step rounds (``mlt/frozen.py``) against traced ones: one
check for lab_pssmlt and lab_mmlt."""
from __future__ import annotations

from dataclasses import dataclass

from agreement import scene_path
from mitsuba_lab.render import render
from mitsuba_lab.scene import load_scene, make_integrator


@dataclass
class FrozenAgainstTraced:
    diff: float              # frozen against traced: largest pixel difference over the largest pixel
    wrong_diff: float        # the same with the frozen rounds' step number off by one (the power)
    rays: dict               # {freeze: ray counts}
    recordings: dict         # {freeze: mlt_stats()["frozen_recordings"]}


def frozen_against_traced(monkeypatch, plugin: str, module, params: dict) -> FrozenAgainstTraced:
    """Render the Cornell box (16x16, 8 mutations per pixel: 4 full rounds of 512 chains, seed 5)
    with ``module.FREEZE_ROUNDS`` off and on, then with the frozen rounds' step number off by one
    (other random numbers, the same distribution)."""
    from mitsuba_lab.plugins.integrators.mlt import frozen

    scene = load_scene(scene_path("cornell_box.xml"), res=16)
    integrator = make_integrator(plugin, {"chains": 512, "bootstrap": 4096, **params})
    images, rays, recordings = {}, {}, {}
    for freeze in (False, True):
        monkeypatch.setattr(module, "FREEZE_ROUNDS", freeze)
        integrator.ray_counts(reset=True)
        images[freeze], _ = render(scene, integrator, spp=8, seed=5)
        rays[freeze] = integrator.ray_counts(reset=True)
        recordings[freeze] = integrator.mlt_stats()["frozen_recordings"]
    scale = images[False][..., :3].max()
    original = frozen.FrozenRounds.__call__

    def off_by_one(self):
        self.chains.step_index = lambda: module.mi.UInt32(self.chains.steps + 1)
        original(self)

    monkeypatch.setattr(frozen.FrozenRounds, "__call__", off_by_one)
    wrong, _ = render(scene, integrator, spp=8, seed=5)
    result = FrozenAgainstTraced(float(abs(images[True] - images[False])[..., :3].max() / scale),
                                 float(abs(wrong - images[False])[..., :3].max() / scale), rays, recordings)
    print(f"frozen against traced: largest difference {result.diff:.2g} of the largest pixel; "
          f"off by one {result.wrong_diff:.2g}")
    return result
