"""Time budgets kept or flagged (issue 42, item 2): a budget point whose median render time is
off its budget by more than budget.BUDGET_TOLERANCE is recalibrated and rendered again (at most
BUDGET_RETRIES times), and one that still misses is marked wherever the report shows it.

Nothing reads a clock here: the worker runs on a fake ``render_at`` whose times are given, and
the report on a synthetic stored sweep (tests/synthetic_sweep.py) whose times are edited.
"""
import math
import os
from types import SimpleNamespace

import numpy as np
import pytest
import synthetic_sweep as synth

from mitsuba_lab.experiment.pipeline import budget
from mitsuba_lab.experiment.report.analysis import region_at_budgets
from mitsuba_lab.experiment.report.comparisons import group_points
from mitsuba_lab.experiment.pipeline.config import PluginSpec, SceneSpec
from mitsuba_lab.experiment.pipeline.plan import Point
from mitsuba_lab.experiment.pipeline.run import SweepRunner
from mitsuba_lab.experiment.pipeline.store import ResultStore
from mitsuba_lab.experiment.sweep import budget_message
from mitsuba_lab.experiment.execution.worker import PointResult, PointTask, execute_counted, execute_progressive

WARMUP = 99
REFERENCE = np.full((4, 6, 3), 0.5, np.float32)


def task(budget_s=1.0, seeds=(1, 2, 3), spp=None, stored_times=(), calibration=None, point_seeds=None):
    point = Point("s/p/i/t1s", "s", "p", "i", None, budget_s, tuple(point_seeds or seeds), WARMUP)
    return PointTask(point=point, scene=SceneSpec("s", "s.xml", None, {}, {}), sampler=PluginSpec("i", "independent", {}),
                     strategy=PluginSpec("p", "path", {}), seeds=tuple(seeds), spp=spp,
                     reference_image=REFERENCE, regions={}, metrics=(), variant="scalar_rgb",
                     stored_times=tuple(stored_times), calibration=calibration)


class FakeRenders:
    """``render_at(count, seed)`` whose wall time is ``seconds(count, seed)``; it records every call."""

    def __init__(self, seconds):
        self.seconds, self.calls = seconds, []

    def __call__(self, count, seed):
        self.calls.append((count, seed))
        stats = SimpleNamespace(wall_s=self.seconds(count, seed), kernel_s=0.0, compile_s=0.0, cache_misses=0,
                                rays={}, integrator={})
        return REFERENCE + 0.01 * seed, stats

    def timed(self):
        """The timed renders (not the warm-ups and pilots, which render the warm-up seed)."""
        return [c for c in self.calls if c[1] != WARMUP]


# -- the tolerance ---------------------------------------------------------------------------

def test_the_tolerance_is_25_percent_either_way():
    assert budget.BUDGET_TOLERANCE == 0.25
    assert budget.within_budget(1.25, 1.0) and budget.within_budget(0.75, 1.0)
    assert not budget.within_budget(1.26, 1.0) and not budget.within_budget(0.74, 1.0)
    assert budget.missed_budget(SimpleNamespace(budget_s=2.0, time_s=1.1))
    assert not budget.missed_budget(SimpleNamespace(budget_s=None, time_s=1.1))      # an spp point
    assert budget.budget_label(2.0, 1.93, 2.31) == "2 s (1.9-2.3 s measured)"
    assert budget.budget_label(0.5, 0.51, 0.52) == "0.5 s (0.51-0.52 s measured)"
    assert budget.rescaled_count(100, 2.0, 1.0) == 50
    assert budget.rescaled_count(100, 2.0, 1.0, fixed_s=0.2) == 44              # (1 - 0.2) / (2 - 0.2)


# -- the worker ------------------------------------------------------------------------------

def test_a_point_whose_renders_take_twice_its_budget_is_recalibrated_and_rendered_once():
    """The calibration's pilots (warm-up seed) see 10 ms per sample: 100 spp for 1 s; the timed
    renders then run at half that speed (another load), 2.0 s each. The point is rescaled by the
    measured 2.0 s to 50 spp and every seed rendered again, once: 1.0 s, within the budget."""
    renders = FakeRenders(lambda count, seed: 0.01 * count * (1 if seed == WARMUP else 2))
    result = execute_counted(task(), renders)
    assert result.spp == 50 and [row["spp"] for row, _ in result.runs] == [50, 50, 50]
    assert [row["wall_s"] for row, _ in result.runs] == [1.0, 1.0, 1.0]
    assert renders.timed() == [(100, 1), (100, 2), (100, 3), (50, 1), (50, 2), (50, 3)]
    assert (50, WARMUP) in renders.calls[renders.calls.index((100, 3)):]         # compiled before timing
    tries = result.calibration["budget_tries"]
    assert [(t["spp"], t["measured_s"]) for t in tries] == [(100, 2.0), (50, 1.0)]
    assert result.calibration["spp"] == 50 and result.calibration["within_budget"] is True


def test_a_point_within_tolerance_is_not_rendered_again():
    """Timed renders 1.2x the budget (inside +-25%): one render per seed, as before."""
    renders = FakeRenders(lambda count, seed: 0.01 * count * (1 if seed == WARMUP else 1.2))
    result = execute_counted(task(), renders)
    assert result.spp == 100 and renders.timed() == [(100, 1), (100, 2), (100, 3)]
    assert len(result.calibration["budget_tries"]) == 1 and result.calibration["within_budget"] is True


def test_a_point_that_misses_every_try_stops_after_the_retries_and_says_so():
    """A cost the calibration never sees (3 s per timed render whatever the count): the first
    renders and BUDGET_RETRIES more, then the point is kept, its calibration saying it missed."""
    renders = FakeRenders(lambda count, seed: 0.01 * count if seed == WARMUP else 3.0)
    result = execute_counted(task(), renders)
    tries = result.calibration["budget_tries"]
    assert len(tries) == 1 + budget.BUDGET_RETRIES == 3
    assert all(t["measured_s"] == 3.0 for t in tries) and result.calibration["within_budget"] is False
    assert len(renders.timed()) == 3 * len(tries) and len(result.runs) == 3       # only the last renders
    assert [row["spp"] for row, _ in result.runs] == [tries[-1]["spp"]] * 3

    events = []
    SweepRunner(None, None, None, lambda event, **info: events.append((event, info))).report_budget_tries(result)
    assert [e for e, _ in events] == ["budget_retry", "budget_retry", "budget_missed"]
    lines = [budget_message(e, info) for e, info in events]
    assert lines[0].startswith("s/p/i/t1s: median render time 3.000 s at 100 spp is outside +-25% of its 1 s budget")
    assert "(retry 1 of 2)" in lines[0] and "(retry 2 of 2)" in lines[1]
    assert "after 2 retries" in lines[2] and "the report marks it as off budget" in lines[2]


def test_a_resumed_point_counts_its_stored_seeds_and_renders_all_of_them_again():
    """Seeds 1 and 2 stored at 100 spp (2.0 s each, from a run under load), seed 3 missing: its
    render (2.0 s) makes the median 2.0 s, so every seed of the point is rendered again at 50 spp
    (one point, one count), rescaled with the stored calibration's fixed cost (0 here)."""
    renders = FakeRenders(lambda count, seed: 0.02 * count)
    stored = {"kind": "calibration", "point": "s/p/i/t1s", "spp": 100, "fixed_s": 0.0, "per_spp_s": 0.01}
    result = execute_counted(task(seeds=(3,), point_seeds=(1, 2, 3), spp=100, stored_times=(2.0, 2.0),
                                  calibration=stored), renders)
    assert renders.timed() == [(100, 3), (50, 1), (50, 2), (50, 3)]
    assert [row["seed"] for row, _ in result.runs] == [1, 2, 3] and result.spp == 50
    assert result.calibration["spp"] == 50 and result.calibration["per_spp_s"] == 0.01     # (the stored fit kept)
    # within its budget, a resumed point adds no calibration row
    renders = FakeRenders(lambda count, seed: 0.01 * count)
    result = execute_counted(task(seeds=(3,), point_seeds=(1, 2, 3), spp=100, stored_times=(1.0, 1.0),
                                  calibration=stored), renders)
    assert renders.timed() == [(100, 3)] and result.calibration is None


def test_a_progressive_budget_point_scales_its_passes_to_the_budget():
    """Passes of 10, 10, 20 and 40 spp fitted earlier; the runs now take 25 ms per spp: 2.0 s
    for a 1 s budget. Every pass is halved (5, 5, 10, 20: 1.0 s) and each seed run again, once."""
    renders = FakeRenders(lambda count, seed: 0.025 * count)
    point = Point("s/p/i/t1s", "s", "p", "i", None, 1.0, (1, 2), WARMUP, progressive=True)
    progressive = PointTask(point=point, scene=SceneSpec("s", "s.xml", None, {}, {}),
                            sampler=PluginSpec("i", "independent", {}), strategy=PluginSpec("p", "path", {}),
                            seeds=(1, 2), spp=None, reference_image=REFERENCE, regions={}, metrics=(),
                            variant="scalar_rgb", passes=(10, 10, 20, 40))
    result = execute_progressive(progressive, renders)
    assert [row["pass_spp"] for row, _ in result.runs] == [[5, 5, 10, 20]] * 2
    assert [row["wall_s"] for row, _ in result.runs] == pytest.approx([1.0, 1.0])
    tries = result.calibration["budget_tries"]
    assert [(t["passes"], t["measured_s"]) for t in tries] == [([10, 10, 20, 40], pytest.approx(2.0)),
                                                               ([5, 5, 10, 20], pytest.approx(1.0))]
    assert result.calibration["passes"] == [5, 5, 10, 20] and result.calibration["spp"] == 40


# -- the store: a point rendered again replaces its images cleanly ---------------------------------

def test_a_point_rendered_again_replaces_its_rows_and_images(tmp_path):
    store = ResultStore(str(tmp_path))
    runner = SweepRunner(None, None, store)
    point_task = task(seeds=(1,), point_seeds=(1,))
    row = lambda spp, wall: {"kind": "run", "point": point_task.point.id, "scene": "s", "strategy": "p",  # noqa: E731
                             "sampler": "i", "spp": spp, "budget_s": 1.0, "seed": 1, "wall_s": wall,
                             "identity_hash": "abcdef0123"}
    runner.record(PointResult(point_task, 100, None, [(row(100, 2.0), REFERENCE)]))
    first = store.stored_runs()[0]["image"]
    assert os.path.exists(tmp_path / first)
    runner.record(PointResult(point_task, 50, None, [(row(50, 1.0), REFERENCE + 1)]))
    (kept,) = store.stored_runs()
    assert kept["spp"] == 50 and kept["image"] != first and "__try2" in kept["image"]
    assert os.path.exists(tmp_path / kept["image"]) and not os.path.exists(tmp_path / first)
    reopened = ResultStore(str(tmp_path))                    # what a resume and the report read
    assert [(r["spp"], r["image"]) for r in reopened.current_runs()] == [(50, kept["image"])]


# -- the report ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def off_budget_sweep(tmp_path_factory):
    """The synthetic sweep with "noisy"'s 0.2 s point rendered in 0.13 s (0.65x: off budget)."""
    folder = tmp_path_factory.mktemp("off_budget")
    synth.write_sweep(folder)

    def slow_down(row):
        if row["point"] == "s/noisy/independent/t0.2s":
            row["wall_s"] = 0.13 + 0.001 * row["seed"]
    synth.edit_runs(folder, slow_down)
    from mitsuba_lab.experiment.report.build import Report

    return Report(str(folder))


def test_the_equal_time_table_labels_budgets_by_measured_time_and_marks_the_point_off_budget(off_budget_sweep):
    groups, label = group_points(off_budget_sweep.stats["s"])
    md = "\n".join(off_budget_sweep.equal_time_table(groups, label))
    assert "| strategy | 0.1 s (0.1 s measured) | 0.2 s (0.13-0.2 s measured) |" in md
    noisy = next(line for line in md.splitlines() if line.startswith("| noisy"))
    assert noisy.count("off budget") == 1 and "(0.13 s, **off budget**)" in noisy
    good = next(line for line in md.splitlines() if line.startswith("| good"))
    assert "off budget" not in good
    assert "+-25%" in md                                   # the rule is stated where it is used


def test_the_figure_does_not_call_an_off_budget_set_equal_time(off_budget_sweep):
    import matplotlib.pyplot as plt

    from mitsuba_lab.experiment.report.figure import build_figure

    fig = build_figure(off_budget_sweep, "s", budget=0.2)
    title = fig._suptitle.get_text()
    assert "equal time 0.2 s" not in title
    assert "budget 0.2 s, not equal time (0.13-0.2 s measured; off budget: noisy 0.13 s)" in title
    texts = [t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text"))]
    assert sum("off its 0.2 s budget" in t for t in texts) == 1                # under noisy's image only
    plt.close(fig)
    fig = build_figure(off_budget_sweep, "s", budget=0.1)
    assert "equal time 0.1 s (0.1 s measured)" in fig._suptitle.get_text()
    plt.close(fig)


def test_a_point_off_budget_is_left_out_of_the_ranking_at_its_budget(off_budget_sweep):
    stats = off_budget_sweep.stats["s"]
    table = region_at_budgets(stats, lambda p: p.strategy, "light", rel_floor=0.0)
    noisy, good = table[0.2]["noisy"], table[0.2]["good"]
    assert noisy["off_budget"] and math.isnan(noisy["x_best"]) and good["x_best"] == 1.0
    assert not table[0.1]["noisy"]["off_budget"] and table[0.1]["noisy"]["x_best"] > 1.0
    from mitsuba_lab.experiment.report.tables import budget_cell
    assert "**off the 0.2 s budget**: not compared" in budget_cell(noisy)
    # the efficiency table ranks by measured time and says which point is off its budget
    groups, label = group_points(stats)
    md = "\n".join(off_budget_sweep.efficiency_table(groups, label))
    assert "off its 0.2 s budget: 0.13 s" in md and "**Off budget:** noisy" in md


def test_the_bias_tables_mark_the_point_off_budget(off_budget_sweep):
    """Issue 42 follow-up, item 2: the walkthrough under load marked its off-budget 1 s points in the
    equal-time, region and viewer tables but not in "Bias and variance per point" nor in the regions'
    variance / bias^2 tables. Every row or cell of the off-budget point says so, no other does."""
    report = off_budget_sweep
    stats = sorted(report.stats["s"], key=lambda p: p.point)
    md = "\n".join(report.bias_table(stats))
    rows = {line.split("|")[1].strip(): line for line in md.splitlines() if line.startswith("| s/")}
    off = [point for point, line in rows.items() if "off its" in line]
    print("\n".join(line for line in md.splitlines() if "t0.2s" in line))
    assert off == ["s/noisy/independent/t0.2s (**off its 0.2 s budget: 0.13 s**)"]
    ref = report.references["s"]
    rect = report._regions("s", ref.image.shape[1], ref.image.shape[0])["light"]
    region = report._region_bias_table("light", rect, ref, stats, lambda key: key[0])
    print("\n".join(region))
    row_02 = next(line for line in region if line.startswith("| 0.2 s"))
    good, noisy = (cell.strip() for cell in row_02.strip("|").split("|")[1:])
    assert noisy.endswith("(**off its 0.2 s budget: 0.13 s**)") and "off its" not in good
    assert not any("off its" in line for line in region if line.startswith("| 0.1 s"))


def test_the_viewer_labels_the_point_off_budget(off_budget_sweep):
    from mitsuba_lab.experiment.report.viewer import scene_data

    report = off_budget_sweep
    ref = report.references["s"]
    data = scene_data(report.folder, "s", report.stats["s"], ref, {})
    by_name = {s["name"]: s for s in data["sets"]}
    off_set = by_name["budget 0.2 s, not equal time (0.13-0.2 s measured; off budget: noisy 0.13 s)"]
    assert [e["label"] for e in off_set["entries"]] == ["reference", "good", "noisy (off budget)"]
    assert [e["key"] for e in off_set["entries"]] == ["reference", "good", "noisy"]     # the viewer keeps it shown
    assert "off its 0.2 s budget: 0.13 s" in off_set["entries"][2]["detail"]
    on_set = by_name["equal time 0.1 s (0.1 s measured)"]
    assert [e["label"] for e in on_set["entries"]] == ["reference", "good", "noisy"]


# -- the image strip: one budget for all ------------------------------------------------------

@pytest.mark.slow
def test_the_image_strip_shows_every_strategy_at_one_budget(tmp_path):
    """Issue 42 follow-up, item 1: the strip ("each strategy at about equal time") took each
    strategy's point nearest the middle of the common time range, so one strategy showed at 2 s
    beside another at 0.99 s. With budgets it shows every strategy at the largest budget all have,
    and says so; the synthetic sweep has budgets 0.1 and 0.2 s and spp points (4, 16 spp) whose
    times differ per strategy (the old rule picked good at 16 spp, 0.064 s, and noisy at 0.032 s)."""
    from mitsuba_lab.experiment.report.build import build_report

    synth.write_sweep(tmp_path)
    paths = build_report(str(tmp_path))
    summary = open(os.path.join(tmp_path, "report", "summary.md")).read()
    line = next(x for x in summary.splitlines() if x.startswith("![reference, each strategy"))
    print(line)
    assert line.startswith("![reference, each strategy at the 0.2 s budget (0.2 s measured), error maps]")
    from mitsuba_lab.experiment.report.build import Report
    from mitsuba_lab.experiment.report.strip import strip_points

    groups, label = group_points(Report(str(tmp_path)).stats["s"])
    picks, _ = strip_points(groups, label)
    assert {label(k): p.budget_s for k, p in picks.items()} == {"good": 0.2, "noisy": 0.2}


def test_the_image_strip_takes_the_largest_budget_all_strategies_have_and_marks_off_budget(tmp_path,
                                                                                            off_budget_sweep):
    from mitsuba_lab.experiment.report.build import Report
    from mitsuba_lab.experiment.report.strip import strip_points

    groups, label = group_points(off_budget_sweep.stats["s"])
    picks, title = strip_points(groups, label)
    print(title)
    assert {label(k): p.budget_s for k, p in picks.items()} == {"good": 0.2, "noisy": 0.2}
    assert title == "reference, each strategy at the 0.2 s budget (0.13-0.2 s measured; off budget: noisy 0.13 s), error maps"
    synth.write_sweep(tmp_path)                      # noisy without its 0.2 s point: both at 0.1 s
    synth.edit_runs(tmp_path, lambda row: [] if row["point"] == "s/noisy/independent/t0.2s" else None)
    groups, label = group_points(Report(str(tmp_path)).stats["s"])
    picks, title = strip_points(groups, label)
    assert {label(k): p.budget_s for k, p in picks.items()} == {"good": 0.1, "noisy": 0.1}
    assert title.startswith("reference, each strategy at the 0.1 s budget")


def test_without_budgets_the_image_strip_title_names_each_images_time(tmp_path):
    from mitsuba_lab.experiment.report.build import Report
    from mitsuba_lab.experiment.report.strip import strip_points

    synth.write_sweep(tmp_path, budgets=())
    groups, label = group_points(Report(str(tmp_path)).stats["s"])
    picks, title = strip_points(groups, label)
    print(title)
    times = {label(k): f"{p.time_s:.2g} s" for k, p in picks.items()}
    assert title == f"reference, each strategy at about equal time (good {times['good']}, noisy {times['noisy']}), error maps"


# -- progressive retries under a fixed cost per pass ---------------------------------------------

def test_progressive_retries_reach_a_budget_that_the_pass_count_alone_exceeds():
    """Issue 42 follow-up, item 3: under load path's 1 s point went 47 -> 34 spp but 1.424 ->
    1.391 s: each of its 8 passes cost about 0.16 s whatever its size, and the retry kept the 8
    passes and scaled only their sizes. Here every timed pass takes 0.16 s + 2.5 ms per spp (8
    passes of 47 spp: 1.40 s for a 1 s budget). The retry fits that model to the passes'
    measured times and drops passes until their fixed part is at most a tenth of the budget
    (``budget.FIXED_SHARE``; 0.16 s is more: one pass), the rest filled with samples: one retry,
    within the budget."""
    renders = FakeRenders(lambda count, seed: 0.16 + 0.0025 * count)
    point = Point("s/p/i/t1s", "s", "p", "i", None, 1.0, (1, 2, 3), WARMUP, progressive=True)
    progressive = PointTask(point=point, scene=SceneSpec("s", "s.xml", None, {}, {}),
                            sampler=PluginSpec("i", "independent", {}), strategy=PluginSpec("p", "path", {}),
                            seeds=(1, 2, 3), spp=None, reference_image=REFERENCE, regions={}, metrics=(),
                            variant="scalar_rgb", passes=(1, 1, 1, 2, 4, 8, 16, 14))
    result = execute_progressive(progressive, renders)
    tries = result.calibration["budget_tries"]
    print([(t["passes"], round(t["measured_s"], 4)) for t in tries])
    assert tries[0]["measured_s"] == pytest.approx(8 * 0.16 + 47 * 0.0025)
    assert len(tries) == 2 and result.calibration["within_budget"] is True
    assert tries[1]["passes"] == [336] and tries[1]["measured_s"] == pytest.approx(1.0)
    assert [row["pass_spp"] for row, _ in result.runs] == [[336]] * 3
    # the fit alone, from injected pass times: deterministic, and with no fixed part the passes stay
    times = [(n, 0.16 + 0.0025 * n) for n in (1, 1, 1, 2, 4, 8, 16, 14)]
    assert budget.rescaled_passes((1, 1, 1, 2, 4, 8, 16, 14), 1.3975, 1.0, times) == (336,)
    light = [(n, 0.019 + 0.0025 * n) for n in (1, 1, 1, 2, 4, 8, 16, 14)]    # 5 passes keep 0.095 s of fixed part
    assert budget.rescaled_passes((1, 1, 1, 2, 4, 8, 16, 14), 0.2695, 1.0, light) == (40, 40, 40, 80, 162)
    assert budget.rescaled_passes((1, 1, 1, 2, 4, 8, 16, 14), 2 * 1.3975, 1.0, times) == (136,)   # twice as slow: one pass
    assert budget.rescaled_passes((10, 10, 20, 40), 2.0, 1.0, [(n, 0.025 * n) for n in (10, 10, 20, 40)]) == \
        (5, 5, 10, 20)
    assert budget.pass_times([{"checkpoints": [{"spp": 1, "wall_s": 0.2}, {"spp": 3, "wall_s": 0.5}]}]) == \
        [(1, 0.2), (2, pytest.approx(0.3))]


def test_a_budget_run_whose_passes_cost_more_than_its_samples_is_fitted_again_with_fewer():
    """A render's fixed part of 0.125 s (tracing a long kernel) and 5 ms per spp, a 1 s budget:
    the budget's doubling passes from 1 spp (1, 1, 2, 4, 8, 16: 0.91 s) spend 0.75 s on their
    fixed parts and render 32 spp. The first run's passes are refitted (``FIXED_SHARE``: their
    fixed part at most 0.1 s, so one pass of 175 spp) and that seed rendered again; every seed
    renders one pass, within the budget, at 5.5x the samples."""
    renders = FakeRenders(lambda count, seed: 0.125 + 0.005 * count)
    point = Point("s/p/i/t1s", "s", "p", "i", None, 1.0, (1, 2, 3), WARMUP, progressive=True)
    fitted = PointTask(point=point, scene=SceneSpec("s", "s.xml", None, {}, {}),
                       sampler=PluginSpec("i", "independent", {}), strategy=PluginSpec("p", "path", {}),
                       seeds=(1, 2, 3), spp=None, reference_image=REFERENCE, regions={}, metrics=(),
                       variant="scalar_rgb", passes=())
    result = execute_progressive(fitted, renders)
    timed = [count for count, _ in renders.timed()]
    assert timed == [1, 1, 2, 4, 8, 16, 175, 175, 175], timed     # the doubling run, seed 1 again, seeds 2 and 3
    assert result.calibration["passes"] == [175] and result.calibration["within_budget"] is True
    assert [row["pass_spp"] for row, _ in result.runs] == [[175]] * 3
