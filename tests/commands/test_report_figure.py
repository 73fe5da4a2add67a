"""`mitsuba-lab report OUTDIR --figure`: the publication figure (PDF and PNG) of a stored
sweep, on a synthetic sweep (tests/synthetic_sweep.py, nothing rendered), and what bad input
says."""
import re

import pytest
import synthetic_sweep as synth

from mitsuba_lab.cli import main
from mitsuba_lab.experiment.report.comparisons import comparison_sets, group_points
from mitsuba_lab.experiment.report.figure import build_figure, pick_set
from mitsuba_lab.experiment.report.build import Report


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    folder = tmp_path_factory.mktemp("figure_sweep")
    synth.write_sweep(folder)
    return folder


def one_error_line(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("mitsuba-lab: error: ")
    return err


@pytest.mark.slow
def test_figure_files_are_written(sweep, tmp_path, capsys):
    out = tmp_path / "fig"
    assert main(["report", str(sweep), "--figure-dir", str(out)]) == 0
    printed = capsys.readouterr().out
    pdf, png = out / "s_equal_time.pdf", out / "s_equal_time.png"
    assert str(pdf) in printed and str(png) in printed
    assert pdf.read_bytes()[:5] == b"%PDF-" and pdf.stat().st_size > 10_000
    import matplotlib.image

    pixels = matplotlib.image.imread(str(png))
    assert pixels.shape[0] > 300 and pixels.shape[1] > 1000       # a grid and a plot side by side
    assert pixels[..., :3].std() > 0.05                             # not a blank page
    # --figure alone: beside the report
    assert main(["report", str(sweep), "--figure"]) == 0
    assert (sweep / "report" / "figures" / "s_equal_time.pdf").exists()


def test_the_figure_shows_each_image_and_crop_with_its_relmse(sweep):
    report = Report(str(sweep))
    fig = build_figure(report, "s", budget=0.1)
    texts = [t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text"))]
    assert any("equal time 0.1 s (0.1 s measured)" in t for t in texts)
    assert sum("spp, " in t and "\nrelMSE " in t for t in texts) == 2      # under "good" and "noisy"
    crop_labels = [t for t in texts if t.startswith("floor ") or re.fullmatch(r"[0-9.]+(e[+-][0-9]+)?", t)]
    assert len(crop_labels) == 3 * len(synth.REGIONS)                  # every image, every region
    assert "light\n-2.5 EV" in texts                                    # crops brought into range, said so
    plot = fig.axes[-1]
    assert plot.get_xscale() == plot.get_yscale() == "log" and len(plot.get_legend().get_texts()) == 2
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_budget_picks_the_nearest_equal_time_comparison(sweep):
    groups, label = group_points(Report(str(sweep)).stats["s"])
    sets = comparison_sets(groups, label)
    assert pick_set(sets, 0.12).name == "equal time 0.1 s (0.1 s measured)"
    assert pick_set(sets, 0.5).name == "equal time 0.2 s (0.2 s measured)"
    assert pick_set(sets, None).name == "equal time 0.2 s (0.2 s measured)"              # the middle one of two


@pytest.mark.parametrize("value", ["-1", "0", "abc", "inf"])
def test_bad_budget_is_one_line(sweep, capsys, value):
    with pytest.raises(SystemExit) as stop:           # argparse's usage error, before anything is read
        main(["report", str(sweep), "--figure", f"--budget={value}"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("mitsuba-lab report: error: argument --budget: expected a")


def test_no_figure_without_two_seeds(tmp_path, capsys):
    synth.write_sweep(tmp_path, seeds=(1,))
    err = one_error_line(capsys, ["report", str(tmp_path), "--figure"])
    assert "no points with two or more seeds" in err


def test_no_results_is_one_line(tmp_path, capsys):
    err = one_error_line(capsys, ["report", str(tmp_path), "--figure"])
    assert "holds no sweep results" in err
