"""``mitsuba_lab.sweep``: the CLI's sweep from Python, its results table, its errors, its progress."""
import csv
import io
import os
import subprocess
import sys
import tomllib

import pytest

import mitsuba_lab
from mitsuba_lab import cli
from mitsuba_lab.errors import LabError
from mitsuba_lab.experiment.api import ResultRows
from mitsuba_lab.experiment.pipeline.config import ConfigError, load_config_dict
from mitsuba_lab.progress import ProgressBar

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENE = os.path.join(ROOT, "scenes", "cornell_box.xml")

TOML = """
[experiment]
name = "api"
spp = [2, 4]
repetitions = 2
max_depth = 4
metrics = []

[reference]
integrator = {{ type = "path" }}
spp = 16
chunks = 2
cache = "{cache}"

[scenes.cornell]
path = "{scene}"
resolution = 16
regions = {{ light = [6, 0, 10, 3] }}

[strategies]
nee = {{ type = "lab_nee" }}
mis = {{ type = "lab_mis", heuristic = "balance" }}
"""
POINTS = {(f"cornell/{s}/independent/spp{n}", seed) for s in ("nee", "mis") for n in (2, 4) for seed in (1, 2)}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The tiny sweep's TOML file, the same config as a dict, and its API run (a list of dicts)."""
    tmp = tmp_path_factory.mktemp("api")
    text = TOML.format(cache=tmp / "cache", scene=SCENE)
    path = tmp / "api.toml"
    path.write_text(text)
    data = tomllib.loads(text)
    table = mitsuba_lab.sweep(data, output=tmp / "api_out", progress=False, as_frame=False)
    return {"tmp": tmp, "toml": str(path), "dict": data, "table": table}


def read_csv(path):
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return reader.fieldnames, list(reader)


@pytest.mark.slow
def test_api_returns_the_rows_of_results_csv(tiny):
    table = tiny["table"]
    assert isinstance(table, ResultRows) and len(table) == 8          # 2 strategies x 2 spp x 2 seeds
    assert {(r["point"], r["seed"]) for r in table} == POINTS
    header, rows = read_csv(table.attrs["report"]["csv"])
    assert table.columns == header and all(list(r) == header for r in table)
    assert "region_light_rel_mse" in header and "rays_shadow" in header
    assert [r["point"] for r in table] == [r["point"] for r in rows]
    for row in table:                  # cells typed back: ints, floats, bools, None for empty
        assert isinstance(row["spp"], int) and row["mse"] > 0 and row["wall_s"] > 0
        assert row["finite"] is True and row["negative"] == 0 and row["flip"] is None
        assert row["rays_camera"] == 16 * 16 * row["spp"]
    assert os.path.isfile(table.attrs["report"]["html"]) and os.path.isfile(table.attrs["report"]["md"])


@pytest.mark.slow
def test_cli_on_the_same_config_gives_the_same_points(tiny, capsys):
    out = tiny["tmp"] / "cli_out"
    assert cli.main(["sweep", tiny["toml"], "-o", str(out)]) == 0, capsys.readouterr().err
    assert f"results in {out}/results.csv" in capsys.readouterr().out
    header, rows = read_csv(out / "results.csv")
    assert header == tiny["table"].columns
    cli_mse = {(r["point"], int(r["seed"])): float(r["mse"]) for r in rows}
    api_mse = {(r["point"], r["seed"]): r["mse"] for r in tiny["table"]}
    assert set(cli_mse) == POINTS
    # same renders (same seeds, same cached reference): the same errors
    assert cli_mse == pytest.approx(api_mse, rel=1e-6)


@pytest.mark.slow
def test_resumed_sweep_returns_a_dataframe_and_shows_plain_progress(tiny, capsys):
    pd = pytest.importorskip("pandas")
    frame = mitsuba_lab.sweep(tiny["dict"], output=tiny["tmp"] / "api_out")       # everything is stored
    err = capsys.readouterr().err
    # one progressive point per strategy (spp2-4: one accumulating render per seed)
    assert "0 points to run (2 already done)" in err and "sweep 'api' done in" in err
    assert "\r" not in err                                  # a log gets plain lines
    assert isinstance(frame, pd.DataFrame) and list(frame.columns) == tiny["table"].columns
    assert frame.attrs["report"] == tiny["table"].attrs["report"]
    assert list(frame["mse"]) == [r["mse"] for r in tiny["table"]]
    assert frame["flip"].isna().all() and frame["finite"].all()


def base_dict():
    return {"experiment": {"spp": [2], "repetitions": 2, "max_depth": 4, "metrics": []},
            "reference": {"spp": 16, "chunks": 2},
            "scenes": {"cornell": {"path": SCENE, "resolution": 16}},
            "strategies": {"nee": {"type": "lab_nee"}, "mis": {"type": "lab_mis"}}}


def changed(path, value):
    data = base_dict()
    *tables, key = path
    target = data
    for name in tables:
        target = target.setdefault(name, {})
    target[key] = value
    return data


@pytest.mark.parametrize("config, expected", [
    (changed(["experiment", "spp"], [2, -8]),
     "config dict: experiment.spp: expected a list of positive integers, got [2, -8]"),
    (changed(["experiment", "bogus"], 1), "config dict: experiment.bogus: expected one of the keys"),
    (changed(["reference", "chunks"], 3), "config dict: reference.chunks: expected an integer >= 2 that divides"),
    (changed(["strategies", "mis"], {"type": "lab_miss"}),
     "config dict: strategies.mis.type: unknown integrator 'lab_miss' (did you mean 'lab_mis'?)"),
    (changed(["strategies", "mis", "heuristc"], "power"),
     "config dict: strategies.mis.heuristc: lab_mis: unknown parameter 'heuristc'"),
    (changed(["samplers", "s"], {"type": "lab_sobol", "sample_count": "x"}),
     "config dict: samplers.s.sample_count: lab_sobol: parameter 'sample_count' expects an integer"),
    (changed(["scenes", "cornell", "path"], "no/such.xml"), "config dict: scenes.cornell.path: expected an "
                                                           "existing scene file"),
    ("no/such/sweep.toml", "config file not found: no/such/sweep.toml"),
    (42, "a sweep config is the path of a TOML file or a dict of its tables, got int"),
])
def test_bad_configs_raise_one_lab_error_in_one_line(config, expected, tmp_path):
    with pytest.raises(LabError) as err:
        mitsuba_lab.sweep(config, output=tmp_path / "out", progress=False)
    assert str(err.value).startswith(expected) and "\n" not in str(err.value)
    assert not (tmp_path / "out").exists()                  # nothing ran


@pytest.mark.parametrize("strategy", ['{ type = "lab_miss" }', '{ type = "lab_mis", beta = -1 }'])
def test_cli_and_api_say_the_same(strategy, tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(TOML.format(cache=tmp_path / "cache", scene=SCENE).replace(
        'mis = { type = "lab_mis", heuristic = "balance" }', f"mis = {strategy}"))
    assert cli.main(["sweep", str(path)]) == 2
    printed = capsys.readouterr().err
    with pytest.raises(LabError) as err:
        mitsuba_lab.sweep(str(path), output=tmp_path / "out", progress=False)
    assert printed == f"mitsuba-lab: error: {err.value}\n" and "strategies.mis" in printed


def test_dict_paths_resolve_against_the_current_directory(tmp_path, monkeypatch):
    data = changed(["scenes", "cornell", "path"], os.path.join("scenes", "cornell_box.xml"))
    data["experiment"]["spp"] = (2, 4)                      # tuples are taken as lists
    monkeypatch.chdir(ROOT)
    config = load_config_dict(data)
    assert config.scenes[0].path == SCENE and config.spp == (2, 4)
    assert config.name == "sweep" and config.output == os.path.join("out", "sweep")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match=f"but {tmp_path}/scenes/cornell_box.xml does not exist"):
        load_config_dict(data)


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_is_plain_lines_in_a_log_and_a_tqdm_bar_on_a_terminal():
    log = io.StringIO()
    bar = ProgressBar(log)
    bar.begin(3, "3 points to run", unit="point")
    for name in ("a", "b", "c"):
        bar.step(name)
    bar.message("done")
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and lines[0] == "3 points to run" and lines[-1] == "done"
    assert [line.split("| ")[1].split(" ")[0] for line in lines[1:4]] == ["1/3", "2/3", "3/3"]
    assert lines[3].startswith("100%") and lines[3].endswith(", c]")

    screen = Terminal()
    bar = ProgressBar(screen)
    assert bar.live
    bar.begin(2, unit="point")
    bar.step("a")
    bar.message("between")                  # printed above the bar, which is redrawn
    bar.step("b")
    text = screen.getvalue()
    assert "\r" in text and "between\n" in text and "2/2" in text and text.endswith("\n")


@pytest.mark.slow
def test_import_stays_cheap_and_sweep_is_exported():
    code = ("import sys, mitsuba_lab; lazy = [m for m in ('mitsuba_lab.experiment.api', 'pandas') "
            "if m in sys.modules]; print(lazy, mitsuba_lab.sweep.__module__, 'sweep' in mitsuba_lab.__all__)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.stdout.strip() == "[] mitsuba_lab.experiment.api True", proc.stderr


def isolation_config(tmp_path, integrator="lab_mis"):
    """The tiny sweep at 1 spp, 3 seeds, one render per point, 32x32, one strategy."""
    config = tomllib.loads(TOML.format(cache=tmp_path / "cache", scene=SCENE))
    config["experiment"].update(spp=[1], repetitions=3, progressive=False)
    del config["experiment"]["name"], config["scenes"]["cornell"]["regions"]
    config["scenes"]["cornell"]["resolution"] = 32
    config["strategies"] = {"mis": {"type": integrator}}
    return config


@pytest.mark.slow
def test_the_sweep_renders_in_a_process_of_its_own(tmp_path):
    """Each render traces a virtual call for every Mitsuba object alive in its process, so the
    sweep renders in a process that holds only its own scene (measured once: 20 small scenes held by
    the caller made a 1-spp lab_mis render at 64x64 take 22 ms in the caller, 4.6 ms there).
    Asserted by the process each row names, not by timing (the suite must pass under load)."""
    import os

    from mitsuba_lab.experiment.pipeline.store import ResultStore

    for in_process in (False, True):
        output = tmp_path / f"out_{in_process}"
        mitsuba_lab.sweep(isolation_config(tmp_path), output=output, progress=False, as_frame=False,
                          in_process=in_process)
        pids = {r["pid"] for r in ResultStore(str(output)).stored_runs()}
        assert len(pids) == 1 and (pids == {os.getpid()}) == in_process, (in_process, pids)


@pytest.mark.slow
def test_a_plugin_registered_only_in_the_calling_process_is_named(tmp_path):
    """The render process imports mitsuba_lab's plugins, not the caller's registrations: such a
    plugin is refused with one line naming it and the way out, and in_process=True renders it."""
    import mitsuba as mi

    class Black(mi.SamplingIntegrator):
        def __init__(self, props):
            super().__init__(props)
            self.max_depth = props.get("max_depth", 1)

        def sample(self, scene, sampler, ray, medium=None, active=True):
            return mi.Spectrum(0.0), mi.Bool(True), []

    mi.register_integrator("test_api_here_only", lambda props: Black(props))
    config = isolation_config(tmp_path, "test_api_here_only")
    with pytest.raises(LabError, match="test_api_here_only.*in_process=True"):
        mitsuba_lab.sweep(config, output=tmp_path / "out", progress=False, as_frame=False)
    rows = mitsuba_lab.sweep(config, output=tmp_path / "out", progress=False, as_frame=False, in_process=True)
    assert len(rows) == 3 and all(r["mse"] > 0 for r in rows)


def test_the_render_process_sends_each_failure_back_as_one_line():
    """What the sweep's process raises for a point that failed in the render process (a unit
    test of render_process.portable: the subprocess itself runs in the slow tier)."""
    from types import SimpleNamespace

    from mitsuba_lab.errors import LabError
    from mitsuba_lab.experiment.execution.render_process import RenderProcessError, portable

    task = SimpleNamespace(point=SimpleNamespace(id="s/x/independent/spp4"))
    bad_input = portable(LabError("lab_mis: parameter 'rr_depth' must be an integer >= 1, got 0"), task)
    assert type(bad_input) is LabError and str(bad_input).startswith("lab_mis: parameter 'rr_depth'")
    try:
        raise RuntimeError("drjit.custom(<_RenderOp>): error") from ValueError("the kernel failed")
    except RuntimeError as err:
        crash = portable(err, task)
    assert isinstance(crash, RenderProcessError) and "\n" not in str(crash) and "Traceback" in crash.traceback


@pytest.mark.slow
def test_an_error_in_the_render_process_arrives_as_its_one_line(tmp_path):
    """A parameter the plugin can only check against the scene (aim_at naming a shape the scene
    lacks) fails in the render process; the sweep's process raises that error's one line."""
    from mitsuba_lab.experiment.execution.render_process import RenderProcessError

    config = isolation_config(tmp_path, "lab_bdpt")
    config["strategies"]["mis"].update(aim=0.5, aim_at="no_such_shape")
    with pytest.raises(RenderProcessError, match="aim_at.*no_such_shape") as caught:
        mitsuba_lab.sweep(config, output=tmp_path / "out", progress=False, as_frame=False)
    assert "Traceback" in caught.value.traceback and "\n" not in str(caught.value)


@pytest.mark.slow
def test_what_the_render_process_prints_reaches_this_process(tmp_path, capsys):
    """lab_sobol warns that 3 samples per pixel is not a power of two; that warning, printed in
    the render process, is passed on to this process's stderr (a notebook shows it)."""
    config = isolation_config(tmp_path)
    config["experiment"]["spp"] = [3]
    config["samplers"] = {"sobol": {"type": "lab_sobol"}}
    mitsuba_lab.sweep(config, output=tmp_path / "out", progress=False, as_frame=False)
    assert "lab_sobol: sample_count=3 is not a power of two" in capsys.readouterr().err


@pytest.mark.slow
def test_a_bidirectional_sweep_fills_the_rays_per_sample_column(tmp_path):
    """lab_vcm counts its rays by kind (count_rays): results.csv has a column for each kind it
    counted, and the report's rays/sample cell names the bidirectional ones after extension and
    shadow rays (empty before lab_bdpt and lab_vcm counted)."""
    config = isolation_config(tmp_path, "lab_vcm")
    config["strategies"]["mis"]["pilot"] = False      # (every technique: its pilot may choose path tracing)
    rows = mitsuba_lab.sweep(config, output=tmp_path / "out", progress=False, as_frame=False, in_process=True)
    pixels = 32 * 32
    for row in rows:
        assert row["rays_camera"] == pixels * row["spp"]
        assert row["rays_light"] > 0 and row["rays_sensor"] > 0 and row["rays_merge"] > 0
    summary = (tmp_path / "out" / "report" / "summary.md").read_text()
    # (the efficiency table's row of strategy "mis": ranked "1", or "not ranked" when it rendered
    # in under 50 ms, which depends on the machine)
    lines = summary.splitlines()
    table = lines[lines.index("### Efficiency (largest sample count), ranked"):]
    cell = next(line for line in table if line.startswith("| ") and line.split("|")[2].strip() == "mis").split("|")[-2]
    assert "; connection " in cell and " light " in cell and " merge " in cell, cell
