"""lab_photon in the sweep runner: the shipped photon experiments plan, a sample count means
passes for lab_photon, time budgets are fitted in passes, and the report splits bias^2 from
variance against passes and compares strategies per region at each time budget."""
import io
import math
import os

import pytest

from mitsuba_lab.experiment.report.analysis import PointStats, bias_by_passes, region_at_budgets
from mitsuba_lab.experiment.pipeline.config import ConfigError, PluginSpec, parse_config, sample_count_plugin
from mitsuba_lab.experiment.pipeline.plan import Point
from mitsuba_lab.experiment.execution.worker import calibrate, settle

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORNELL = os.path.join(ROOT, "scenes", "cornell_box.xml")


@pytest.mark.parametrize("name", ["caustics.toml", "photon_bias.toml"])
def test_shipped_photon_experiments_plan_in_a_dry_run(name):
    from mitsuba_lab.commands.sweep import sweep_command

    out = io.StringIO()
    assert sweep_command(os.path.join(ROOT, "experiments", name), None, True, out) == 0
    text = out.getvalue()
    assert "photon_photons" in text and "photon_nee" in text and "estimated total" in text
    assert "passes" in text                      # lab_photon's levels are shown as passes


def test_sample_count_means_passes_for_lab_photon():
    photon = PluginSpec("p", "lab_photon", {"radius": 0.03})
    spec, spp = sample_count_plugin(photon, 12)
    assert spp == 1 and spec.params == {"radius": 0.03, "passes": 12} and photon.params == {"radius": 0.03}
    mis = PluginSpec("m", "lab_mis", {"heuristic": "balance"})
    assert sample_count_plugin(mis, 12) == (mis, 12)


def test_a_lab_photon_strategy_may_not_set_passes():
    data = {"experiment": {"spp": [4]}, "scenes": {"s": {"path": CORNELL}},
            "strategies": {"ph": {"type": "lab_photon", "passes": 8}}}
    with pytest.raises(ConfigError) as err:
        parse_config(data, os.path.join(ROOT, "x.toml"))
    message = str(err.value)
    assert "\n" not in message and "strategies.ph.passes" in message and "time budget" in message


def test_calibration_fits_the_count_to_the_budget():
    """A fake render whose time is 0.2 s fixed + 0.05 s per pass: a 1.2 s budget is 20 passes."""
    class Stats:
        def __init__(self, wall_s):
            self.wall_s = wall_s

    calls = []

    def render_at(count, seed):
        calls.append(count)
        return None, Stats(0.2 + 0.05 * count)

    point = Point("s/p/i/t1.2s", "s", "p", "i", None, 1.2, (1, 2), 0)
    count, row = calibrate(point, render_at)
    assert count == 20 and row["fixed_s"] == pytest.approx(0.2) and row["per_spp_s"] == pytest.approx(0.05)
    assert set(calls) == {2, 8}


def test_calibration_grows_the_pilots_until_the_per_sample_cost_is_measurable():
    """A fixed cost of 10 ms and 10 us per sample, with the 8-spp pilot timed faster than the
    2-spp one (noise): the pilots grow 4x until their times differ by 5% of the 1 s budget."""
    class Stats:
        def __init__(self, wall_s):
            self.wall_s = wall_s

    def render_at(count, seed):
        return None, Stats(0.0099 if count == 8 else 0.01 + 1e-5 * count)

    point = Point("s/p/i/t1s", "s", "p", "i", None, 1.0, (1, 2), 0)
    count, row = calibrate(point, render_at)
    assert row["pilots"] == [2048, 8192] and row["per_spp_s"] == pytest.approx(1e-5)
    assert count == pytest.approx(99_000, rel=1e-3)


class Timed:
    """What a render's statistics give the calibration: wall and compile seconds."""
    def __init__(self, wall_s, compile_s=0.0):
        self.wall_s, self.compile_s = wall_s, compile_s


def test_a_count_whose_cost_changes_is_settled_at_the_budget():
    """A render that gets 5x cheaper per sample from 500 samples on (as lab_vcm's pilot choosing
    path tracing alone at large counts): the pilots fit 990 samples for 1 s (10 ms fixed), the
    compile render there takes 0.208 s (compilation left out), so the count is scaled by
    0.99 / 0.198 to 4950 (1.0 s) and kept;
    a render linear in its count is not rendered again."""
    calls = []

    def render_at(count, seed):                 # (the first render at a count compiles for 0.5 s)
        compile_s = 0.0 if count in calls else 0.5
        calls.append(count)
        return None, Timed(0.01 + (1e-3 if count < 500 else 2e-4) * count + compile_s, compile_s)

    point = Point("s/p/i/t1s", "s", "p", "i", None, 1.0, (1, 2), 0)
    count, row = calibrate(point, render_at)
    assert count == 990
    _, first = render_at(count, 0)
    settled = settle(point, render_at, count, first, row)
    assert settled == 4950 and row["spp"] == 4950 and calls[-1] == 4950
    assert [r["spp"] for r in row["rescaled"]] == [4950]

    calls.clear()
    linear = {"spp": 990}
    assert settle(point, render_at, 990, Timed(0.99), linear) == 990 and calls == [] and "rescaled" not in linear


def stats(spp, bias2, bias2_se, variance=1e-3, budget=None, strategy="ph", regions=None, time_s=1.0, times=None):
    """A point whose relative (relMSE-unit) bias^2 and variance are the given ones (two seeds, each
    of ``time_s`` unless ``times`` says)."""
    return PointStats(point=f"s/{strategy}/i/{spp}", scene="s", strategy=strategy, sampler="i", spp=spp,
                      budget_s=budget, seeds=8, time_s=time_s, kernel_s=time_s, mse=0.0, mse_std=0.0,
                      rel_mse=bias2 + variance, rel_mse_std=0.0, mse_corrected=0.0, rel_mse_corrected=0.0,
                      variance=0.0, bias2=0.0, bias2_se=0.0, efficiency=math.nan, near_floor=False,
                      rel_variance=variance, rel_bias2=bias2, rel_bias2_se=bias2_se, regions=regions or {},
                      times=times or [time_s, time_s])


def seeds(mean, se):
    """Two seeds' values with this mean and standard error (their half difference)."""
    return [mean - se, mean + se]


def test_bias_by_passes_sorts_flags_and_fits_the_resolved_bias():
    # bias^2 = 0.01 / passes where resolved; the 64-pass point is within noise of zero
    points = [stats(64, 1e-5, 1e-4), stats(4, 2.5e-3, 1e-4), stats(1, 1e-2, 1e-4), stats(16, 6.25e-4, 1e-4)]
    result = bias_by_passes(points, lambda p: p.spp)
    assert [r["passes"] for r in result["rows"]] == [1, 4, 16, 64]
    assert [r["resolved"] for r in result["rows"]] == [True, True, True, False]
    assert result["slope"] == pytest.approx(-1.0)
    assert result["rows"][0]["rel_mse"] == pytest.approx(1e-2 + 1e-3)
    assert math.isnan(bias_by_passes(points[:1], lambda p: p.spp)["slope"])


def test_region_at_budgets_gives_the_equal_time_ratio_to_the_best():
    region = lambda rel: {"caustic": {"rel_mse": rel, "mse": 0.0, "rel_mse_seeds": [rel, rel]}}
    points = [stats(100, 0, 0, budget=2.0, strategy="mis", regions=region(0.051), time_s=2.0),
              stats(10, 0, 0, budget=2.0, strategy="ph", regions=region(0.006), time_s=2.5),
              stats(4, 0, 0, strategy="ph", regions=region(0.5))]                  # no budget: not listed
    table = region_at_budgets(points, lambda p: p.strategy, "caustic", rel_floor=0.001)
    assert list(table) == [2.0]
    cells = table[2.0]
    assert cells["ph"]["x_best"] == pytest.approx(1.0) and cells["ph"]["rel_mse_corrected"] == pytest.approx(0.005)
    assert cells["mis"]["x_best"] == pytest.approx(0.05 * 2.0 / (0.005 * 2.5))



def test_region_at_budgets_gives_the_ratio_one_standard_error_either_way():
    """Relative standard errors 10% (mis) and 20% (ph, the best) combine on the ratio's log:
    sqrt(0.1^2 + 0.2^2) = 0.224, so the ratio 8 reads 8 exp(-0.224) = 6.40 to 10.0; a single
    seed (no standard error) gives no range."""
    def region(rel, se):
        return {"caustic": {"rel_mse": rel, "mse": 0.0, "rel_mse_se": se, "rel_mse_seeds": seeds(rel, se)}}
    points = [stats(100, 0, 0, budget=2.0, strategy="mis", regions=region(0.041, 0.004), time_s=2.0),
              stats(10, 0, 0, budget=2.0, strategy="ph", regions=region(0.006, 0.001), time_s=2.0)]
    cells = region_at_budgets(points, lambda p: p.strategy, "caustic", rel_floor=0.001)[2.0]
    assert cells["mis"]["x_best"] == pytest.approx(8.0)
    low, high = cells["mis"]["x_best_range"]
    spread = math.exp(math.hypot(0.1, 0.2))
    assert (low, high) == pytest.approx((8.0 / spread, 8.0 * spread))
    assert cells["ph"]["x_best_range"] == (1.0, 1.0)
    points[0].regions["caustic"]["rel_mse_seeds"] = [0.041]
    points[0].times = [2.0]
    cells = region_at_budgets(points, lambda p: p.strategy, "caustic", rel_floor=0.001)[2.0]
    assert all(math.isnan(v) for v in cells["mis"]["x_best_range"])


def test_region_at_budgets_charges_each_seed_its_own_time():
    """A strategy that chose per seed (lab_vcm's pilot): seed 1 took 1 s for a corrected relMSE of
    0.04, seed 2 took 4 s for 0.01, so each seed's relMSE x time is 0.04: the cost is 0.04, as
    for a strategy that took 2 s for 0.02 on both. Mean relMSE x median time would say
    0.025 x 2.5 = 0.0625 (1.56x worse); the cell says how far apart the times are."""
    def region(rels):
        return {"caustic": {"rel_mse": sum(rels) / 2, "mse": 0.0, "rel_mse_se": 0.0, "rel_mse_seeds": rels}}
    points = [stats(100, 0, 0, budget=2.0, strategy="auto", regions=region([0.041, 0.011]), time_s=2.5,
                    times=[1.0, 4.0]),
              stats(100, 0, 0, budget=2.0, strategy="fixed", regions=region([0.021, 0.021]), time_s=2.0)]
    cells = region_at_budgets(points, lambda p: p.strategy, "caustic", rel_floor=0.001)[2.0]
    assert cells["auto"]["cost"] == pytest.approx(0.04) and cells["fixed"]["cost"] == pytest.approx(0.04)
    assert cells["auto"]["x_best"] == pytest.approx(1.0) and cells["auto"]["time_spread"] == pytest.approx(4.0)
    from mitsuba_lab.experiment.report.tables import budget_cell
    assert "times 4x apart" in budget_cell(cells["auto"]) and "apart" not in budget_cell(cells["fixed"])



def test_a_strategy_at_the_floor_does_not_hide_the_best():
    """A strategy whose relMSE is at the region's floor has no cost (NaN); listed first, it must
    not become the best that the others are divided by."""
    region = lambda rel: {"caustic": {"rel_mse": rel, "mse": 0.0, "rel_mse_se": rel / 10,
                                      "rel_mse_seeds": seeds(rel, rel / 10)}}
    points = [stats(100, 0, 0, budget=2.0, strategy="floor", regions=region(0.001), time_s=2.0),
              stats(100, 0, 0, budget=2.0, strategy="mis", regions=region(0.041), time_s=2.0),
              stats(10, 0, 0, budget=2.0, strategy="ph", regions=region(0.006), time_s=2.0)]
    cells = region_at_budgets(points, lambda p: p.strategy, "caustic", rel_floor=0.001)[2.0]
    assert math.isnan(cells["floor"]["x_best"])
    assert cells["ph"]["x_best"] == pytest.approx(1.0) and cells["mis"]["x_best"] == pytest.approx(8.0)


def test_region_bias_variance_sees_a_blurred_region_and_not_the_rest(tmp_path):
    """Synthetic renders: unbiased noise everywhere, and a 4 x 4 region scaled by 1.1 (a bias of
    10%): the region's bias^2 is resolved and near 0.1^2; another region's is within noise; one
    seed gives NaN."""
    import numpy as np

    from mitsuba_lab import images
    from mitsuba_lab.experiment.report.analysis import region_bias_variance
    from mitsuba_lab.experiment.pipeline.reference import Reference

    rng = np.random.default_rng(5)
    image = np.full((16, 16, 3), 2.0)
    ref = Reference("k", image, np.zeros_like(image), {})
    paths = []
    for k in range(16):
        render = image * (1.0 + rng.normal(0.0, 0.05, image.shape))
        render[4:8, 4:8] *= 1.1
        paths.append(f"r{k}.exr")
        images.write_exr(str(tmp_path / paths[-1]), render)
    point = stats(16, 0, 0, budget=1.0)
    point.images = paths
    variance, bias2, se = region_bias_variance(point, str(tmp_path), ref, (4, 4, 8, 8))
    weight = 2.0 ** 2 / (2.0 ** 2 + 1e-2)                # relMSE's units: 1 / (ref^2 + 0.01)
    assert bias2 > 5 * se and bias2 == pytest.approx(0.1 ** 2 * weight, rel=0.2)
    assert variance == pytest.approx(0.05 ** 2 * 1.1 ** 2 * weight, rel=0.2)
    _, other, se = region_bias_variance(point, str(tmp_path), ref, (10, 10, 14, 14))
    assert abs(other) < 3 * se
    point.images = paths[:1]
    assert all(math.isnan(v) for v in region_bias_variance(point, str(tmp_path), ref, (4, 4, 8, 8)))


TINY = """
[experiment]
spp = [1, 4]
time_budgets = [0.4]
repetitions = 2
max_depth = 4
metrics = []

[reference]
spp = 64
chunks = 4
cache = "{cache}"

[scenes.cornell]
path = "{scene}"
resolution = 16
regions = {{ light = [6, 0, 10, 3] }}

[strategies]
photon = {{ type = "lab_photon", direct = "photons", photons_per_pass = 2000 }}
mis = {{ type = "lab_mis" }}
"""


@pytest.mark.slow
def test_tiny_photon_sweep_runs_passes_and_reports_bias_against_passes(tmp_path):
    from mitsuba_lab.experiment.pipeline.config import load_config
    from mitsuba_lab.experiment.pipeline.plan import build_plan
    from mitsuba_lab.experiment.report.build import build_report
    from mitsuba_lab.experiment.pipeline.run import SweepRunner
    from mitsuba_lab.experiment.pipeline.store import ResultStore

    path = tmp_path / "tiny.toml"
    path.write_text(TINY.format(cache=tmp_path / "cache", scene=CORNELL))
    config = load_config(str(path))
    store = ResultStore(str(tmp_path / "out"))
    SweepRunner(config, build_plan(config), store).run()
    runs = [r for r in store.of_kind("run") if r["strategy"] == "photon"]
    assert len(runs) == 3 * 2 and all(r["finite"] and r["negative"] == 0 for r in runs)
    for r in runs:                               # N camera samples per pixel = N passes of 1 spp
        assert r["params"]["passes"] == r["spp"] and r["rays"]["camera"] == 16 * 16 * r["spp"]
        # lab_photon's own statistics of that render (photon_stats()), stored with the row
        assert r["integrator_stats"]["passes"] == r["spp"] and r["integrator_stats"]["photons_traced"] > 0
    mis = [r for r in store.of_kind("run") if r["strategy"] == "mis"]
    assert mis and all(r.get("integrator_stats") == {} for r in mis)       # Mitsuba-side plugin: none
    fitted = {c["point"]: c["spp"] for c in store.of_kind("calibration")}
    assert {r["spp"] for r in runs if r["budget_s"]} == {fitted["cornell/photon/independent/t0.4s"]}
    summary = open(build_report(str(tmp_path / "out"))["md"]).read()
    assert "photon: bias^2 and variance against passes" in summary and "mis: bias^2" not in summary
    assert "Region `light` at each time budget" in summary and "Reference noise floor per region" in summary
    assert "Region `light`: relative variance / bias^2" in summary
    assert os.path.exists(tmp_path / "out" / "report" / "cornell_passes.png")


def test_relative_bias_is_zero_for_unbiased_renders_and_sees_a_scaled_one():
    """Synthetic: renders = ref + noise (unbiased) and 1.2 x ref + noise; relative units make
    the bright pixel count like the dim ones."""
    import numpy as np

    from mitsuba_lab.experiment.report.analysis import relative_bias_variance
    from mitsuba_lab.experiment.pipeline.reference import Reference

    rng = np.random.default_rng(3)
    image = np.full((16, 16, 3), 0.5)
    image[0, 0] = 1000.0                                     # a light pixel
    ref = Reference("k", image, np.zeros_like(image), {})
    noise = rng.normal(0.0, 0.05, (32, 16, 16, 3)) * np.sqrt(image ** 2 + 1e-2)
    variance, bias2, se = relative_bias_variance(image + noise, ref)
    assert abs(bias2) < 3 * se and variance == pytest.approx(0.05 ** 2, rel=0.1)
    _, scaled, se = relative_bias_variance(1.2 * image + noise, ref)
    assert scaled > 10 * se and scaled == pytest.approx(0.2 ** 2 * 0.25 / 0.26, rel=0.1)
