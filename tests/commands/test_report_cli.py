"""`mitsuba-lab report`: what a wrong argument says, and the Veach-bound table's grouping
(on a synthetic stored sweep: rows and images made with numpy, nothing rendered); the shared
report helpers (mitsuba_lab.reporting) that the sweep report, invert and check write with."""
import json
import os

import numpy as np
import pytest

from mitsuba_lab.cli import main
from mitsuba_lab.experiment.report.build import Report, build_report
from mitsuba_lab.experiment.pipeline.store import ResultStore
from mitsuba_lab import images

SIZE = 8
SEEDS = (1, 2, 3)


def report_error(capsys, argument) -> str:
    assert main(["report", str(argument)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("mitsuba-lab: error: ")
    return err[len("mitsuba-lab: error: "):]


def test_report_given_a_toml_file(tmp_path, capsys):
    config = tmp_path / "quick.toml"
    config.write_text("[experiment]\n")
    assert report_error(capsys, config) == (f"report expects a sweep's output folder, got the file {config}; "
                                            f"to run the sweep: mitsuba-lab sweep {config}")


def test_report_given_another_file(tmp_path, capsys):
    other = tmp_path / "results.jsonl"
    other.write_text("")
    assert report_error(capsys, other) == f"report expects a sweep's output folder, got the file {other}"


def test_report_given_a_missing_folder_creates_nothing(tmp_path, capsys):
    missing = tmp_path / "out" / "nope"
    assert report_error(capsys, missing) == f"no such folder: {missing}"
    assert not (tmp_path / "out").exists()


def test_report_given_a_folder_without_results(tmp_path, capsys):
    assert report_error(capsys, tmp_path) == (f"{tmp_path} holds no sweep results (no results.jsonl): run "
                                              f"`mitsuba-lab sweep CONFIG -o {tmp_path}` first")
    assert os.listdir(tmp_path) == []


def test_report_given_a_sweep_without_runs(tmp_path, capsys):
    ResultStore(str(tmp_path)).append({"kind": "meta", "config": "experiments/quick.toml", "name": "quick"})
    message = report_error(capsys, tmp_path)
    assert "no finished renders" in message and f"mitsuba-lab sweep experiments/quick.toml -o {tmp_path}" in message
    assert not (tmp_path / "report").exists()


# -- Veach's bound, on a synthetic sweep -------------------------------------------------------------

#: strategy -> (lab_mis parameters as a run row would store them, noise sigma of its images)
STRATEGIES = {
    "mis_balance": ({"heuristic": "balance", "max_depth": 2}, 0.05),
    # every default spelled out (a fully resolved row): the same group as mis_balance
    "mis_power": ({"heuristic": "power", "beta": 2.0, "emitter_samples": 1, "max_depth": 2, "rr_depth": 5,
                   "hide_emitters": False, "count_rays": True}, 0.06),
    "mis_max": ({"heuristic": "max", "max_depth": 2}, 0.07),
    "mis_balance_2": ({"heuristic": "balance", "emitter_samples": 2, "max_depth": 2}, 0.04),
    "mis_average_2": ({"heuristic": "average", "emitter_samples": 2, "max_depth": 2}, 0.08),
    "mis_power_4": ({"heuristic": "power", "emitter_samples": 4, "max_depth": 2}, 0.03),   # no balance at 4
    "mis_max_depth3": ({"heuristic": "max", "max_depth": 3}, 0.05),      # another estimator: no balance
}
SAMPLERS = ("independent", "sobol")


def synthetic_sweep(folder) -> None:
    rng = np.random.default_rng(7)
    store = ResultStore(str(folder))
    store.append({"kind": "meta", "config": "synthetic.toml", "name": "synthetic", "machine": {}})
    reference = np.full((SIZE, SIZE, 3), 0.5, dtype=np.float32)
    reference[:2] = 4.0                                           # a bright band: "light"
    os.makedirs(folder / "references")
    images.write_exr(str(folder / "references" / "k.exr"), reference)
    images.write_exr(str(folder / "references" / "k.var.exr"), np.full_like(reference, 1e-6))
    store.append({"kind": "reference", "scene": "s", "key": "k", "regions": {"light": [0, 0, SIZE, 2]},
                  "spp": 1024, "chunks": 4, "integrator": "path", "params": {}})
    os.makedirs(folder / "images")
    runs = [(name, "lab_mis", params, sigma, sampler) for sampler in SAMPLERS
            for name, (params, sigma) in STRATEGIES.items()]
    runs.append(("nee", "lab_nee", {"max_depth": 2}, 0.05, "independent"))
    for name, integrator, params, sigma, sampler in runs:
        for spp in (4, 16):
            point = f"s/{name}/{sampler}/spp{spp}"
            for seed in SEEDS:
                image = reference + rng.normal(0, sigma / np.sqrt(spp), reference.shape).astype(np.float32)
                path = store.image_path(point, seed)
                images.write_exr(path, image)
                mse = float(np.mean((image - reference) ** 2))
                store.append({"kind": "run", "point": point, "scene": "s", "strategy": name, "sampler": sampler,
                              "spp": spp, "budget_s": None, "seed": seed, "wall_s": 0.01 * spp, "kernel_s": 0.01,
                              "compile_s": 0.0, "rays": {}, "integrator": integrator, "params": params,
                              "mse": mse, "rel_mse": float(np.mean((image - reference) ** 2 / (reference ** 2 + 0.01))),
                              "image": os.path.relpath(path, folder), "regions": {}, "finite": True,
                              "negative": 0})


def veach_section(markdown: str) -> list[str]:
    lines = markdown.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("### Veach's bound"))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith(("#", "!["))), len(lines))
    return lines[start:end]


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    folder = tmp_path_factory.mktemp("synthetic")
    synthetic_sweep(folder)
    return folder


@pytest.mark.slow
def test_veach_table_compares_weightings_within_one_sampler_and_emitter_count(synthetic):
    paths = build_report(str(synthetic))
    section = veach_section(open(paths["md"]).read())
    table = [line for line in section if line.startswith("|")]
    header = [c.strip() for c in table[0].strip("|").split("|")]
    assert header[:6] == ["sampler", "emitter_samples", "balance", "other", "weighting", "spp"]
    rows = [dict(zip(header, (c.strip() for c in line.strip("|").split("|")))) for line in table[2:]]
    compared = {(r["sampler"], r["emitter_samples"], r["balance"], r["other"], r["weighting"]) for r in rows}
    expected = set()
    for sampler in SAMPLERS:
        expected |= {(sampler, "1", "mis_balance", "mis_power", "power (beta 2)"),
                     (sampler, "1", "mis_balance", "mis_max", "max"),
                     (sampler, "2", "mis_balance_2", "mis_average_2", "average")}
    assert compared == expected                   # never across samplers or emitter_samples
    # one row per spp and region (light, image-wide regions are not added when regions exist)
    assert len(rows) == len(expected) * 2 and {r["region"] for r in rows} == {"light"}
    assert {r["spp"] for r in rows} == {"4", "16"}
    # grouped: rows of one (sampler, emitter_samples) are contiguous, in sorted order
    keys = [(r["sampler"], int(r["emitter_samples"])) for r in rows]
    assert keys == sorted(keys)
    assert all(r["verdict"] in ("holds", "within noise", "violated") for r in rows)
    notes = [line for line in section if line.startswith("Not compared")]
    assert len(notes) == 4
    for sampler in SAMPLERS:
        for name, n_l in (("mis_power_4", 4), ("mis_max_depth3", 1)):
            assert any(f"{name} (sampler {sampler}, emitter_samples {n_l}): no balance weighting" in n
                       for n in notes)
    print("\n".join(section))


def test_veach_table_is_absent_without_a_balance_weighting(synthetic):
    report = Report(str(synthetic))
    groups = {}
    for p in report.stats["s"]:
        if p.strategy != "mis_balance" and p.strategy != "mis_balance_2":
            groups.setdefault((p.strategy, p.sampler), []).append(p)
    assert report.veach_table("s", groups) == []


def test_veach_section_is_absent_with_one_lab_mis_weighting(synthetic):
    """A balance weighting alone (the other strategy not lab_mis): nothing to compare, so no
    section at all (issue 42: sections with nothing to say are left out, not printed empty)."""
    report = Report(str(synthetic))
    groups = {}
    for p in report.stats["s"]:
        if p.strategy in ("mis_balance", "nee") and p.sampler == "independent":
            groups.setdefault((p.strategy, p.sampler), []).append(p)
    assert report.veach_table("s", groups) == []


def test_veach_bound_without_a_standard_error_is_not_resolved():
    from mitsuba_lab.experiment.report.analysis import veach_bound

    nan = float("nan")
    balance = {"variance": 2.0, "variance_se": nan, "ref_mean_square": 0.0}
    other = {"variance": 1.0, "variance_se": nan, "ref_mean_square": 0.0}
    assert veach_bound(balance, other, 1, 4)["verdict"] == "not resolved with 2 seeds (needs at least 3)"


# -- mitsuba_lab.reporting ---------------------------------------------------------------------

def test_number_formatting():
    from mitsuba_lab.reporting import fmt

    assert [fmt(v) for v in (0.123456, 1234567.0, float("nan"), float("inf"), float("-inf"), None, 7, "x")] == \
        ["0.123", "1.23e+06", "n/a", "inf", "-inf", "n/a", "7", "x"]
    assert fmt(0.123456, 2) == "0.12" and fmt(None, missing="-") == "-" and fmt("", missing="-") == "-"


def test_markdown_table_and_its_html(tmp_path):
    from mitsuba_lab.reporting import markdown_table, md_to_html

    lines = markdown_table(["a", "b"], [[1, "x <y>"], [2.5, ""]])
    assert lines == ["| a | b |", "|---|---|", "| 1 | x <y> |", "| 2.5 |  |"]
    page = md_to_html("# Title\n\n" + "\n".join(lines) + "\n\n**Best:** `lab_mis`.")
    assert page.splitlines() == [
        "<h1>Title</h1>",
        "<table><tr><th>a</th><th>b</th></tr><tr><td>1</td><td>x &lt;y&gt;</td></tr>"
        "<tr><td>2.5</td><td></td></tr></table>",
        "<p><strong>Best:</strong> <code>lab_mis</code>.</p>"]


@pytest.mark.slow
def test_a_page_embeds_its_images_and_honours_the_umask(tmp_path):
    from mitsuba_lab.reporting import write_markdown_page

    images.write_png(str(tmp_path / "plot.png"), np.full((2, 2, 3), 0.5, dtype=np.float32))
    old = os.umask(0o027)
    try:
        paths = write_markdown_page(str(tmp_path), "T & U", "# T & U\n\n![a plot](plot.png)")
    finally:
        os.umask(old)
    html = open(paths["html"]).read()
    assert "<title>T &amp; U</title>" in html and '<img alt="a plot" src="data:image/png;base64,' in html
    assert open(paths["md"]).read() == "# T & U\n\n![a plot](plot.png)\n"
    assert all(os.stat(p).st_mode & 0o777 == 0o640 for p in paths.values())
    assert sorted(os.listdir(tmp_path)) == ["index.html", "plot.png", "summary.md"]      # no temporary left
