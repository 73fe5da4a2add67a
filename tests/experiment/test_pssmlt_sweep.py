"""lab_pssmlt (and lab_mmlt, which shares its driver) in the runner: a progressive run's later passes
continue the first pass's Markov chains (``Estimator.CONTINUES_PASSES``,
``progressive.run_passes(continues=True)``), so the checkpoint after N mutations per pixel is the
chains' normalised image after N mutations per pixel, the same image (to float32 rounding) as one
render of N; every seed is its own bootstrap and set of chains. Exact checks only (no statistics, no
clock); the sweep is 16 x 16 at max_depth 3 with a 1024-path bootstrap (a few seconds)."""
import json
import os

import numpy as np
import pytest

from mitsuba_lab.experiment.pipeline.config import parse_config
from mitsuba_lab.experiment.pipeline.plan import build_plan
from mitsuba_lab.experiment.pipeline.run import SweepRunner
from mitsuba_lab.experiment.pipeline.store import ResultStore
from mitsuba_lab.plugins.integrators.mlt import chain

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORNELL = os.path.join(ROOT, "scenes", "cornell_box.xml")
MLT = {"type": "lab_pssmlt", "chains": 128, "bootstrap": 1024}


def test_rounds_step_every_chain_in_turn():
    assert chain.rounds(0, 256, 128) == [(0, 128), (0, 128)]
    assert chain.rounds(0, 64, 128) == [(0, 64)]                 # a partial round
    assert chain.rounds(64, 256, 128) == [(64, 128), (0, 128), (0, 64)]
    assert chain.rounds(100, 10, 128) == [(100, 110)]
    assert chain.rounds(5, 0, 128) == []


def test_budget_passes_leave_the_bootstrap_out_of_their_fit():
    """A fake chain estimator whose first pass pays a 0.5 s bootstrap: the budget run fits the
    later passes alone (0.1 s per spp), so it doubles its passes and fills the budget, the first
    pass fresh and the rest continued; rescaling a run takes the bootstrap off the budget once."""
    from types import SimpleNamespace

    from mitsuba_lab.experiment.execution.progressive import run_passes
    from mitsuba_lab.experiment.pipeline.budget import once_cost, pass_times, rescaled_passes

    calls = []

    def render_at(size, seed, continues=False):
        calls.append((size, continues))
        wall = (0.0 if continues else 0.5) + 0.1 * size
        return np.ones((2, 2, 3), np.float32), SimpleNamespace(wall_s=wall, kernel_s=wall, compile_s=0.0,
                                                              cache_misses=0, rays={}, integrator={})

    checkpoints = run_passes(render_at, 7, None, 2.0, continues=True)
    assert calls[:4] == [(1, False), (1, True), (2, True), (4, True)] and all(c for _, c in calls[1:])
    assert 1.6 <= checkpoints[-1].wall_s <= 2.0
    row = {"checkpoints": [{"spp": 1, "wall_s": 0.6}, {"spp": 2, "wall_s": 0.7}, {"spp": 4, "wall_s": 0.9},
                           {"spp": 8, "wall_s": 1.3}]}
    times = pass_times([row], first=False)
    assert times == [(1, 0.1), (2, 0.2), (4, 0.4)] or np.allclose(times, [(1, 0.1), (2, 0.2), (4, 0.4)])
    assert abs(once_cost([row], times) - 0.5) < 1e-9
    assert rescaled_passes((1, 1, 2, 4), 1.3, 2.1, times, 0.5) == (2, 2, 4, 8)     # 1.6 s of passes: 16 spp


@pytest.mark.parametrize("plugin", ["lab_pssmlt", "lab_mmlt"])
def test_continued_passes_are_one_render_of_all_their_mutations(plugin):
    """Two passes of 2 mutations per pixel, the second continuing the first's chains, weighted by
    their spp as the runner's progressive runs weigh them, equal one render of 4 (same seed,
    the same chain steps: 16 x 16 x 2 mutations are whole rounds of 128 chains); and a pass of 1
    continued by one of 2 (partial rounds: mutation k a step of chain k mod 128) makes 3 x 256
    mutations, each chain 6 steps."""
    from mitsuba_lab.render import render
    from mitsuba_lab.scene import load_scene, make_integrator

    scene = load_scene(CORNELL, res=16)
    params = {k: v for k, v in MLT.items() if k != "type"} | {"max_depth": 3}
    whole, _ = render(scene, make_integrator(plugin, params), spp=4, seed=5)
    integrator = make_integrator(plugin, params)
    first, _ = render(scene, integrator, spp=2, seed=5)
    integrator.continue_chains = True
    second, _ = render(scene, integrator, spp=2, seed=77)           # (a continued pass ignores its seed)
    assert integrator.mlt_stats()["chain_mutations"] == 4 * 256
    mean = (2 * first.astype(np.float64) + 2 * second) / 4
    np.testing.assert_allclose(mean, whole, rtol=1e-5, atol=1e-7)

    integrator.continue_chains = False
    render(scene, integrator, spp=1, seed=5)                       # new chains: 2 rounds of 128, the second of 128
    integrator.continue_chains = True
    render(scene, integrator, spp=2, seed=5)
    stats = integrator.mlt_stats()
    assert stats["chain_mutations"] == 3 * 256 and stats["steps"] == 4 and stats["mutations_per_pixel"] == 2.0
    assert 0.0 < stats["acceptance"] < 1.0


TINY = {"experiment": {"spp": [2, 8], "repetitions": 2, "max_depth": 3},
        "reference": {"spp": 16, "chunks": 2},
        "scenes": {"c": {"path": CORNELL, "resolution": 16}},
        "strategies": {"mlt": MLT}}


def test_progressive_sweep_checkpoints_continue_the_chains(tmp_path):
    """Each seed's run: passes 2, 2, 4 (checkpoints at 2, 4 and 8 mutations per pixel); the
    last checkpoint's image is one render of 8 mutations per pixel with that seed; the row keeps
    the last pass's mlt_stats() (b of the first pass's bootstrap, the chains' mutations in all);
    the seeds' bootstraps differ."""
    import mitsuba as mi

    from mitsuba_lab.render import render
    from mitsuba_lab.scene import load_scene, make_integrator

    data = json.loads(json.dumps(TINY))
    data["reference"]["cache"] = str(tmp_path / "cache")
    config = parse_config(data, os.path.join(ROOT, "x.toml"))
    SweepRunner(config, build_plan(config), ResultStore(str(tmp_path / "out")), lambda event, **info: None).run()
    rows = ResultStore(str(tmp_path / "out")).stored_runs()
    assert sorted((r["point"], r["seed"]) for r in rows) == [("c/mlt/independent/spp2-8", s) for s in (1, 2)]
    scene = load_scene(CORNELL, res=16)
    bs = set()
    for row in rows:
        assert row["progressive"] and row["pass_spp"] == [2, 2, 4] and row["cache_misses"] == 0
        assert [c["spp"] for c in row["checkpoints"]] == [2, 4, 8]
        last = np.array(mi.Bitmap(str(tmp_path / "out" / row["checkpoints"][-1]["image"])), dtype=np.float64)
        params = {k: v for k, v in MLT.items() if k != "type"} | {"max_depth": 3}
        integrator = make_integrator("lab_pssmlt", params)
        whole, _ = render(scene, integrator, spp=8, seed=row["seed"])
        np.testing.assert_allclose(last[..., :3], whole[..., :3], rtol=1e-4, atol=1e-6)
        bs.add(integrator.mlt_stats()["b"])
        assert row["integrator_stats"]["b"] == pytest.approx(integrator.mlt_stats()["b"], rel=1e-6)
        assert row["integrator_stats"]["chain_mutations"] == 16 * 16 * 8
    assert len(bs) == 2


@pytest.mark.parametrize("name", ["lab_pssmlt", "lab_mmlt"])
def test_check_judges_chain_estimators_by_the_z_test(name):
    """``mitsuba-lab check`` renders lab_pssmlt and lab_mmlt among its strategies, as unbiased
    estimators (the z-test with the heavy-tail escalation), not by bias^2 shrinking."""
    from mitsuba_lab import check
    from mitsuba_lab.check.render import is_consistent

    kind, params = check.STRATEGIES[name]
    assert kind == name and not is_consistent(kind, params)


def test_a_single_continued_pass_is_rescaled_from_the_tries():
    """A budget run of one pass (its second overran) has no pass times apart from the bootstrap:
    the second retry fits seconds = once + per spp over the tries (0.2 s + 0.03 s per spp:
    a 1 s budget is 27 spp); the first, with one try, scales all of the time."""
    from mitsuba_lab.experiment.execution.worker import rescaled_single_pass

    assert rescaled_single_pass((1,), [{"spp": 1, "measured_s": 0.23}], 1.0) == (4,)
    tries = [{"spp": 1, "measured_s": 0.23}, {"spp": 5, "measured_s": 0.35}]
    assert rescaled_single_pass((5,), tries, 1.0) == (27,)
