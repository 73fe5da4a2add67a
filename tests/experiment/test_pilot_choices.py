"""What lab_vcm's pilot chose, seed by seed, in a sweep: each run row keeps the integrator's own
statistics of that render (``integrator_stats``), and the report lists each pilot's choice beside
the seed's render time, so a point whose seeds took different times says why."""
import json
import math
import os

import pytest

from mitsuba_lab.experiment.report.analysis import PointStats, pilot_choice
from mitsuba_lab.experiment.report.tables import SectionTables

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORNELL = os.path.join(ROOT, "scenes", "cornell_box.xml")


def test_pilot_choice_reads_lab_vcms_statistics():
    assert pilot_choice({}) is None                                             # Mitsuba's integrators
    assert pilot_choice({"pilot_s": 0.0, "light_paths_chosen": 0.0}) is None    # lab_vcm without a pilot
    assert pilot_choice({"pilot_s": 0.21, "chose_path_tracing": True, "light_paths_chosen": 0.0}) == \
        ("path tracing", 0.21)
    assert pilot_choice({"pilot_s": 0.2, "chose_path_tracing": False, "light_paths_chosen": 16.0}) == ("16", 0.2)


def point(strategy, pilots, times, budget=4.0):
    return PointStats(point=f"s/{strategy}/i/t{budget:g}s", scene="s", strategy=strategy, sampler="i", spp=185,
                      budget_s=budget, seeds=len(times), time_s=sorted(times)[len(times) // 2], kernel_s=1.0,
                      mse=0.0, mse_std=0.0, rel_mse=0.0, rel_mse_std=0.0, mse_corrected=0.0, rel_mse_corrected=0.0,
                      variance=0.0, bias2=0.0, bias2_se=0.0, efficiency=math.nan, near_floor=False,
                      times=times, pilots=pilots)


def test_the_pilot_table_lists_each_seeds_choice_beside_its_time():
    auto = point("auto", [("16", 0.2), ("2", 0.25), ("path tracing", 0.21)], [4.0, 1.3, 4.1])
    bdpt = point("bdpt", [None, None, None], [4.0, 4.0, 3.9])
    md = SectionTables().pilot_table({("auto", "i"): [auto], ("bdpt", "i"): [bdpt]}, lambda key: key[0])
    assert "### What the pilots chose" in md
    rows = [line for line in md if line.startswith("| ") and "strategy" not in line]
    assert len(rows) == 1 and rows[0].startswith("| auto | 4 s | 185 |")
    assert "16, 2, path tracing" in rows[0] and "4, 1.3, 4.1" in rows[0] and "| 0.21 |" in rows[0]
    assert SectionTables().pilot_table({("bdpt", "i"): [bdpt]}, lambda key: key[0]) == []


def tiny_config(cache) -> dict:
    """Two seeds of the 16x16 Cornell box at 16 spp: lab_vcm with a pilot choosing one or two light
    subpaths (or path tracing), unbounded (``pilot_share`` 1: at 16 spp the default share affords
    no pilot), and lab_bdpt."""
    return {"experiment": {"spp": [16], "repetitions": 2, "max_depth": 4, "metrics": []},
            "reference": {"spp": 64, "chunks": 4, "cache": str(cache)},
            "scenes": {"cornell": {"path": CORNELL, "resolution": 16}},
            "strategies": {"auto": {"type": "lab_vcm", "light_paths": 1, "light_paths_max": 2, "pilot": True,
                                    "pilot_share": 1.0},
                           "bdpt": {"type": "lab_bdpt"}}}


@pytest.mark.slow
def test_a_sweep_keeps_each_renders_statistics_and_reports_the_pilots_choices(tmp_path):
    """Through ``mitsuba_lab.sweep`` (its render process builds the rows): lab_vcm's rows keep its
    pilot's statistics, lab_bdpt's its own, and the report's table lists each seed's choice."""
    import mitsuba_lab

    out = tmp_path / "out"
    table_rows = mitsuba_lab.sweep(tiny_config(tmp_path / "cache"), output=str(out), progress=False, as_frame=False)
    runs = {"auto": [], "bdpt": []}
    for line in open(out / "results.jsonl"):
        row = json.loads(line)
        if row.get("kind") == "run":
            runs[row["strategy"]].append(row)
    assert len(runs["auto"]) == 2 and len(runs["bdpt"]) == 2
    for r in runs["auto"]:
        stats = r["integrator_stats"]
        assert stats["pilot_s"] > 0 and set(stats["pilot_scores"]) == {"1.0", "2.0", "path tracing"}
        assert pilot_choice(stats) is not None
    assert all("pilot_s" not in r["integrator_stats"] and r["integrator_stats"]["passes"] >= 1 for r in runs["bdpt"])
    table = open(out / "report" / "summary.md").read().split("### What the pilots chose")[1]
    line = next(line for line in table.splitlines() if line.startswith("| auto"))
    chosen = [c.strip() for c in line.split("|")[4].split(",")]
    assert chosen == [pilot_choice(r["integrator_stats"])[0] for r in runs["auto"]]
    # results.csv (the rows mitsuba_lab.sweep returns): the count chosen, 0 for path tracing alone,
    # empty without a pilot
    expected = [0.0 if c == "path tracing" else float(c) for c in chosen]
    assert [r["pilot_light_paths"] for r in table_rows if r["strategy"] == "auto"] == expected
    assert [r["pilot_light_paths"] for r in table_rows if r["strategy"] == "bdpt"] == [None, None]
    assert "| bdpt" not in table.split("\n## ")[0]
