"""Progressive runs: pass schedules, accumulation, agreement with separate renders, the store."""
import json
import os

import numpy as np
import pytest

from mitsuba_lab.experiment.pipeline.config import ConfigError, PluginSpec, parse_config
from mitsuba_lab.experiment.pipeline.plan import build_plan, ladder_passes, separate_reason
from mitsuba_lab.experiment.execution.progressive import fit_pass_time, next_budget_pass, run_passes
from mitsuba_lab.experiment.pipeline.run import SweepRunner
from mitsuba_lab.experiment.pipeline.store import ResultStore
from mitsuba_lab.render import RenderStats

from agreement import Z_BOUND

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORNELL = os.path.join(ROOT, "scenes", "cornell_box.xml")


def test_ladder_passes_double_and_hit_every_ladder_value():
    assert ladder_passes([4, 16, 64]) == (4, 4, 8, 16, 32)          # 4, 8, 16, 32, 64 spp
    assert ladder_passes([64]) == (64,)
    assert ladder_passes([3, 10]) == (3, 3, 4)                       # 3, 6, 10
    assert ladder_passes([2, 3, 8]) == (2, 1, 3, 2)                  # 2, 3, 6, 8
    assert ladder_passes([4, 16, 64], "ladder") == (4, 12, 48)       # the ladder's values only


def test_which_strategies_accumulate():
    independent, sobol = PluginSpec("i", "independent"), PluginSpec("s", "lab_sobol")
    assert separate_reason(PluginSpec("m", "lab_mis"), independent) == ""
    assert separate_reason(PluginSpec("p", "path"), PluginSpec("l", "lab_independent")) == ""
    assert separate_reason(PluginSpec("b", "lab_bdpt"), independent) == ""
    assert "stratifies" in separate_reason(PluginSpec("m", "lab_mis"), sobol)
    assert "radius" in separate_reason(PluginSpec("ph", "lab_photon"), independent)
    assert "radius" in separate_reason(PluginSpec("v", "lab_vcm"), independent)            # mode vcm merges
    assert separate_reason(PluginSpec("v", "lab_vcm", {"mode": "bpt"}), independent) == ""


def test_plan_and_config_switch():
    """A scene runs progressively only when all of its strategies and samplers can accumulate."""
    glossy = os.path.join(ROOT, "scenes", "glossy_small_light.xml")
    data = {"experiment": {"spp": [4, 16], "time_budgets": [0.5]},
            "scenes": {"c": {"path": CORNELL}, "g": {"path": glossy}},
            "strategies": {"mis": {"type": "lab_mis"}, "ph": {"type": "lab_photon"}}}
    # lab_photon left out of g (by the assess stand-in): g is progressive, c keeps separate renders
    assess = lambda scene, strategies: ({"ph": "left out"} if scene.name == "g" else {}, {})
    plan = build_plan(parse_config(data, os.path.join(ROOT, "x.toml")), assess)
    assert [(p.id, p.progressive, p.passes) for p in plan.points] == [
        ("c/mis/independent/spp4", False, ()), ("c/mis/independent/spp16", False, ()),
        ("c/mis/independent/t0.5s", False, ()), ("c/ph/independent/spp4", False, ()),
        ("c/ph/independent/spp16", False, ()), ("c/ph/independent/t0.5s", False, ()),
        ("g/mis/independent/spp4-16", True, (4, 4, 8)), ("g/mis/independent/t0.5s", True, ())]
    assert [(s["scene"], s["strategy"]) for s in plan.separate] == [("c", "ph")]
    data["experiment"]["progressive"] = False
    plan = build_plan(parse_config(data, os.path.join(ROOT, "x.toml")), assess)
    assert not any(p.progressive for p in plan.points) and not plan.separate
    data["experiment"].update(progressive=True, checkpoints="ladder")
    plan = build_plan(parse_config(data, os.path.join(ROOT, "x.toml")), assess)
    assert plan.points[-2].passes == (4, 12)
    for key, value, message in (("progressive", "yes", "experiment.progressive: expected true"),
                                ("checkpoints", "all", 'experiment.checkpoints: expected "doubling"')):
        with pytest.raises(ConfigError, match=message):
            parse_config({**data, "experiment": {**data["experiment"], key: value}}, os.path.join(ROOT, "x.toml"))


class FakeClock:
    """render_at stand-in: a pass of n spp takes fixed + per x n seconds and returns an image
    whose every pixel is n (so the accumulated image shows the weights)."""

    def __init__(self, fixed=0.01, per=0.001):
        self.fixed, self.per, self.calls = fixed, per, []

    def __call__(self, n, seed):
        self.calls.append((n, seed))
        stats = RenderStats(wall_s=self.fixed + self.per * n, compile_s=0.0, kernel_s=self.per * n, kernels=1,
                            cache_misses=0, spp=n, seed=seed, width=2, height=2, rays={"camera": 4 * n})
        return np.full((2, 2, 3), float(n), np.float32), stats


def test_run_passes_accumulates_by_spp_and_sums_time():
    clock = FakeClock()
    cps = run_passes(clock, 5, (4, 4, 8))
    assert [c.spp for c in cps] == [4, 8, 16] and clock.calls[0] == (4, 5)        # pass 0 keeps the seed
    assert len({seed for _, seed in clock.calls}) == 3
    # spp-weighted mean of the pass images (4, 4, 8): (16 + 16 + 64) / 16 = 6
    assert cps[-1].image[0, 0, 0] == pytest.approx(6.0) and cps[1].image[0, 0, 0] == pytest.approx(4.0)
    assert cps[-1].wall_s == pytest.approx(3 * 0.01 + 16 * 0.001) and cps[-1].rays == {"camera": 64}


def test_budget_passes_stop_at_the_last_that_fits():
    assert fit_pass_time([(1, 0.011), (2, 0.012), (4, 0.014)]) == pytest.approx((0.01, 0.001))
    assert fit_pass_time([(4, 0.02), (4, 0.03)]) == (0.0, pytest.approx(0.0075))     # one size: upper bound
    assert next_budget_pass(0, [], 1.0) == (1, False)
    clock = FakeClock(fixed=0.01, per=0.001)
    cps = run_passes(clock, 1, budget_s=0.2005)
    totals = [0] + [c.spp for c in cps]
    sizes = [b - a for a, b in zip(totals, totals[1:])]
    # doubling to 64 spp takes 0.134 s; 64 more would not fit (0.074 s), 56 do: 0.01 + 0.056
    assert sizes == [1, 1, 2, 4, 8, 16, 32, 56] and cps[-1].wall_s == pytest.approx(0.2)

    class Overrun(FakeClock):                 # the last pass takes longer than predicted: dropped
        def __call__(self, n, seed):
            image, stats = super().__call__(n, seed)
            stats.wall_s *= 3 if n == 56 else 1
            return image, stats
    cps = run_passes(Overrun(), 1, budget_s=0.2005)
    assert cps[-1].spp == 64 and cps[-1].wall_s == pytest.approx(0.134)


@pytest.fixture(scope="module")
def cornell():
    from mitsuba_lab.render import render
    from mitsuba_lab.scene import make_integrator
    from mitsuba_lab.scene_xml import load_scene_variant

    scene = load_scene_variant(CORNELL, 64, {"type": "independent"}, {})
    reference = render(scene, make_integrator("path", {"max_depth": 4}), spp=1024, seed=99)[0]
    return scene, reference.astype(np.float64)


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["lab_mis", "path"])
def test_progressive_mse_agrees_with_separate_renders(cornell, integrator):
    """Cornell box 64x64, max_depth 4, 16 seeds each: the mean MSE and relMSE (against a 1024-spp
    reference) of the progressive run's 4- and 16-spp checkpoints (passes 2, 2, 4, 8) equal those
    of separate 4- and 16-spp renders of other seeds within |z| < Z_BOUND; every pass after the
    warm-up runs without compiling. Power: weighting the passes equally instead of by spp (1.37x
    the variance at 16 spp) is caught at |z| > Z_BOUND in relMSE (MSE itself, dominated by the
    light's edge pixels, varies 23% from seed to seed: too much to see it with 16 seeds)."""
    from mitsuba_lab.render import render
    from mitsuba_lab.scene import make_integrator

    scene, reference = cornell
    method = make_integrator(integrator, {"max_depth": 4})
    render_at = lambda n, seed: render(scene, method, spp=n, seed=seed)
    for n in (2, 4):                                           # the warm-up of execute_progressive
        render_at(n, 0)
    errors = {"mse": lambda image: float(np.mean((image - reference) ** 2)),
              "rel_mse": lambda image: float(np.mean((image - reference) ** 2 / (reference ** 2 + 0.01)))}
    values = {(name, kind): [] for name in errors for kind in ("p4", "p16", "s4", "s16", "equal")}
    for seed in range(1, 17):
        cps = run_passes(render_at, seed, (2, 2, 4, 8))
        assert sum(c.cache_misses for c in cps) == 0
        totals = [0] + [c.spp for c in cps]
        sums = [0.0] + [c.image.astype(np.float64) * c.spp for c in cps]
        passes = [(sums[k + 1] - sums[k]) / (totals[k + 1] - totals[k]) for k in range(len(cps))]
        images = {"p4": cps[1].image, "p16": cps[3].image, "equal": np.mean(passes, axis=0),
                  "s4": render_at(4, 1000 + seed)[0], "s16": render_at(16, 1000 + seed)[0]}
        for name, error in errors.items():
            for kind, image in images.items():
                values[(name, kind)].append(error(image.astype(np.float64)))

    def z(a, b):
        a, b = values[a], values[b]
        return (np.mean(a) - np.mean(b)) / np.sqrt(np.var(a, ddof=1) / len(a) + np.var(b, ddof=1) / len(b))

    print(f"\n{integrator}: progressive against separate, z of " + ", ".join(
        f"{name} at {n} spp {z((name, f'p{n}'), (name, f's{n}')):+.2f}" for name in errors for n in (4, 16)) +
        f"; equal pass weights, relMSE at 16 spp {z(('rel_mse', 'equal'), ('rel_mse', 's16')):+.2f}")
    for name in errors:
        for n in (4, 16):
            assert abs(z((name, f"p{n}"), (name, f"s{n}"))) < Z_BOUND, (name, n)
    assert z(("rel_mse", "equal"), ("rel_mse", "s16")) > Z_BOUND


TINY = {"experiment": {"spp": [2, 8], "repetitions": 2, "max_depth": 3, "metrics": ["ciede2000"]},
        "reference": {"spp": 64, "chunks": 4},
        "scenes": {"c": {"path": CORNELL, "resolution": 16}},
        "strategies": {"mis": {"type": "lab_mis"}, "path": {"type": "path"}}}


def sweep(folder, cache, strategies=None, **experiment):
    data = json.loads(json.dumps(TINY))
    data["experiment"].update(experiment)
    data["strategies"] = strategies or data["strategies"]
    data["reference"]["cache"] = str(cache)
    config = parse_config(data, os.path.join(ROOT, "x.toml"))
    events = []
    store = ResultStore(str(folder))
    SweepRunner(config, build_plan(config), store, lambda event, **info: events.append((event, info))).run()
    return ResultStore(str(folder)), events


@pytest.mark.slow
def test_progressive_sweep_rows_resume_and_switch_off(tmp_path):
    from mitsuba_lab.experiment.report.build import build_report

    out, cache = tmp_path / "out", tmp_path / "cache"
    store, _ = sweep(out, cache)
    prog = store.stored_runs()
    assert sorted((r["point"], r["seed"]) for r in prog) == [(f"c/{s}/independent/spp2-8", seed)
                                                              for s in ("mis", "path") for seed in (1, 2)]
    for row in prog:
        assert row["progressive"] and row["pass_spp"] == [2, 2, 4] and row["cache_misses"] == 0
        assert [c["spp"] for c in row["checkpoints"]] == [2, 4, 8]
        assert [("ciede2000" in c) for c in row["checkpoints"]] == [True, False, True]   # ladder values only
        assert all(os.path.isfile(out / c["image"]) for c in row["checkpoints"])
        times = [c["wall_s"] for c in row["checkpoints"]]
        assert times == sorted(times) and row["wall_s"] == times[-1]
    current = store.current_runs()                           # what the report reads: one row per checkpoint
    assert sorted((r["point"], r["seed"], r["spp"]) for r in current if r["strategy"] == "mis") == \
        [(f"c/mis/independent/spp{n}", s, n) for n in (2, 4, 8) for s in (1, 2)]
    assert all(r["rays"]["camera"] == 16 * 16 * r["spp"] for r in current if r["strategy"] == "mis")
    report = build_report(str(out))
    assert "Progressive runs: one render per seed" in open(report["md"]).read()

    # killed after a run's checkpoint images, before its row: that run alone is rendered again
    lines = open(out / "results.jsonl").read().splitlines(keepends=True)
    last = max(i for i, line in enumerate(lines) if '"kind": "run"' in line)
    dropped = json.loads(lines[last])
    open(out / "results.jsonl", "w").writelines(lines[:last] + lines[last + 1:])
    store, events = sweep(out, cache)
    assert dict(events)["start"] == {"total": 1, "skipped": 1}
    again = store.stored_runs()
    assert sorted((r["point"], r["seed"]) for r in again) == sorted((r["point"], r["seed"]) for r in prog)
    redone = next(r for r in again if (r["point"], r["seed"]) == (dropped["point"], dropped["seed"]))
    assert [c["mse"] for c in redone["checkpoints"]] == pytest.approx([c["mse"] for c in dropped["checkpoints"]],
                                                                      rel=1e-3)     # the same seeds, passes

    # progressive off: the progressive runs are retired, the ladder renders one point per spp
    store, events = sweep(out, cache, progressive=False)
    stale = [info for event, info in events if event == "stale"]
    assert stale == [{"count": 4, "changes": "not in this sweep's plan any more", "planned": False}]
    assert {r["point"] for r in store.current_runs()} == {f"c/{s}/independent/spp{n}" for s in ("mis", "path")
                                                          for n in (2, 8)}

    # a strategy that cannot accumulate keeps the whole scene on separate renders
    store, _ = sweep(tmp_path / "mixed", cache, {"mis": {"type": "lab_mis"},
                                                "ph": {"type": "lab_photon", "photons_per_pass": 500}})
    assert not any(r.get("progressive") for r in store.stored_runs())
    assert [(s["strategy"], s["sampler"]) for s in store.of_kind("meta")[-1]["separate"]] == [("ph", "independent")]


@pytest.mark.slow
def test_budget_run_fixes_its_passes_on_the_first_seed(tmp_path):
    store, _ = sweep(tmp_path / "out", tmp_path / "cache", {"mis": {"type": "lab_mis"}}, spp=[],
                     time_budgets=[0.05])
    runs = [r for r in store.stored_runs() if r.get("progressive")]
    calibration = [c for c in store.of_kind("calibration") if c.get("passes")]
    assert len(runs) == 2 and len(calibration) == 1
    assert all(r["pass_spp"] == calibration[0]["passes"] for r in runs)
    tries = calibration[0]["budget_tries"]                 # (more than one: rescaled to the budget)
    assert tries[0]["passes"] == runs[0]["pass_spp"] or len(tries) > 1
    if len(tries) == 1:
        first = next(r for r in runs if r["seed"] == calibration[0]["fitted_on_seed"])
        assert first["wall_s"] <= 0.05 or len(first["pass_spp"]) == 1      # the last pass that fits
    points = {r["point"]: r["spp"] for r in store.current_runs() if r["strategy"] == "mis"}
    assert points == {"c/mis/independent/t0.05s": calibration[0]["spp"]}
