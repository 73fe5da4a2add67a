"""The sweep runner: config validation, plan, reference cache, store, resume after kill -9, report."""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from mitsuba_lab.experiment.report import browser
from mitsuba_lab.experiment.pipeline.config import ConfigError, PluginSpec, load_config, parse_config
from mitsuba_lab.experiment.pipeline.plan import build_plan
from mitsuba_lab.experiment.pipeline.reference import get_reference, reference_key
from mitsuba_lab.experiment.pipeline.store import ResultStore

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

TINY = """
[experiment]
name = "tiny"
spp = [2, 8]
repetitions = 2
progressive = false        # one render per spp (progressive runs: test_progressive.py)
max_depth = 4
metrics = ["flip", "ciede2000"]

[reference]
integrator = {{ type = "path" }}
spp = 64
chunks = 4
cache = "{cache}"

[scenes.cornell]
path = "{root}/scenes/cornell_box.xml"
resolution = 16
regions = {{ light = [6, 0, 10, 3], left = [0.0, 0.25, 0.25, 0.75] }}

[strategies]
nee = {{ type = "lab_nee" }}
mis = {{ type = "lab_mis", heuristic = "balance" }}
"""


@pytest.fixture
def tiny_config(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY.format(cache=tmp_path / "cache", root=ROOT))
    return str(path)


def config_error(text, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(str(path))
    message = str(err.value)
    assert "\n" not in message and "bad.toml" in message
    return message


@pytest.mark.parametrize("mutation, expected", [
    (lambda t: t.replace("spp = [2, 8]", "spp = [2, -8]"), "experiment.spp: expected a list of positive integers"),
    (lambda t: t.replace("repetitions = 2", "repetitions = 1"), "experiment.repetitions: expected an integer >= 2"),
    (lambda t: t.replace("chunks = 4", "chunks = 5"), "reference.chunks: expected an integer >= 2 that divides"),
    (lambda t: t.replace("cornell_box.xml", "nope.xml"), "scenes.cornell.path: expected an existing scene file"),
    (lambda t: t.replace('nee = { type = "lab_nee" }', 'nee = { heuristic = "x" }'),
     "strategies.nee.type: expected the integrator plugin name"),
    (lambda t: t.replace("[6, 0, 10, 3]", "[6, 0, 3, 3]"), "scenes.cornell.regions.light: expected [x0, y0, x1, y1]"),
    (lambda t: t.replace('metrics = ["flip", "ciede2000"]', 'metrics = ["psnr"]'), "experiment.metrics"),
    (lambda t: t.replace("[experiment]", "[experiment]\nbogus = 1"), "experiment.bogus: expected one of the keys"),
    (lambda t: t.replace("spp = [2, 8]", ""), "experiment.spp: expected an spp ladder"),
    (lambda t: t + "\n[[oops", "not valid TOML"),
    (lambda t: t.replace("resolution = 16", "resolution = 16\nreference = { spp = 96, chunks = 5 }"),
     "scenes.cornell.reference.chunks: expected an integer >= 2 that divides scenes.cornell.reference.spp = 96"),
    (lambda t: t.replace("resolution = 16", 'resolution = 16\nreference = { cache = "x" }'),
     "scenes.cornell.reference.cache: expected one of the keys chunks, integrator, spp (unknown key)"),
    (lambda t: t.replace("resolution = 16", "resolution = 16\nreference = { integrator = { max_depth = 3 } }"),
     "scenes.cornell.reference.integrator.type: expected the integrator plugin name"),
])
def test_config_errors_name_the_key(mutation, expected, tmp_path):
    text = mutation(TINY.format(cache=tmp_path / "cache", root=ROOT))
    assert expected in config_error(text, tmp_path)


def test_config_defaults_and_plan_ids(tiny_config):
    config = load_config(tiny_config)
    assert config.samplers[0].type == "independent" and config.spp == (2, 8)
    assert config.scenes[0].regions["left"] == (0.0, 0.25, 0.25, 0.75)
    plan = build_plan(config)
    ids = [p.id for p in plan.points]
    assert ids == ["cornell/nee/independent/spp2", "cornell/nee/independent/spp8",
                   "cornell/mis/independent/spp2", "cornell/mis/independent/spp8"]
    assert build_plan(config).points == plan.points          # stable
    assert all(p.seeds == (1, 2) and p.warmup_seed == 0 for p in plan.points)


@pytest.mark.slow
def test_a_scene_may_have_its_own_reference(tmp_path):
    """[scenes.X.reference] replaces what it names of [reference] for that scene (a hard region
    whose floor needs a better estimator or more samples); the cache stays the experiment's,
    and a sweep renders and reports that scene against it."""
    text = TINY.format(cache=tmp_path / "cache", root=ROOT).replace(
        "resolution = 16", 'resolution = 16\nreference = { integrator = { type = "lab_bdpt" }, spp = 32 }').replace(
        "spp = [2, 8]", "spp = [2]")
    (tmp_path / "own.toml").write_text(text)
    config = load_config(str(tmp_path / "own.toml"))
    own = config.reference_for(config.scenes[0])
    assert (own.integrator.type, own.spp, own.chunks, own.cache) == ("lab_bdpt", 32, 4, config.reference.cache)
    assert (config.reference.integrator.type, config.reference.spp) == ("path", 64)
    proc = run_cli("sweep", str(tmp_path / "own.toml"), "-o", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    assert "Reference: lab_bdpt" in (tmp_path / "out" / "report" / "summary.md").read_text()
    (tmp_path / "bad.toml").write_text(text.replace('type = "lab_bdpt"', 'type = "lab_nope"'))
    bad = run_cli("sweep", str(tmp_path / "bad.toml"), "-o", str(tmp_path / "bad"))
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert "scenes.cornell.reference.integrator" in bad.stderr and "lab_nope" in bad.stderr, bad.stderr


def test_plan_leaves_out_and_aliases():
    config = parse_config({"experiment": {"spp": [4]},
                           "scenes": {"s": {"path": os.path.join(ROOT, "scenes", "cornell_box.xml")}},
                           "strategies": {"a": {"type": "lab_naive"}, "b": {"type": "lab_nee"},
                                          "c": {"type": "lab_mis"}}}, os.path.join(ROOT, "x.toml"))
    plan = build_plan(config, lambda scene, strategies: ({"a": "cannot reach delta lights"},
                                                         {"c": ("b", "delta lights only")}))
    assert [p.strategy for p in plan.points] == ["b"]
    assert plan.left_out == [{"scene": "s", "strategy": "a", "reason": "cannot reach delta lights"}]
    assert plan.aliases[0]["same_as"] == "b"


def test_reference_cache_hit_miss_and_key(tmp_path):
    scene = os.path.join(ROOT, "scenes", "cornell_box.xml")
    spec = PluginSpec("ref", "path", {"max_depth": 3})
    key = reference_key(scene, 8, {}, spec, 16, 4)
    assert key == reference_key(scene, 8, {}, spec, 16, 4)                   # stable
    assert key != reference_key(scene, 8, {}, spec, 32, 4)                   # spp is part of it
    assert key != reference_key(scene, 16, {}, spec, 16, 4)                  # so is the resolution
    assert key != reference_key(scene, 8, {}, PluginSpec("ref", "path", {"max_depth": 4}), 16, 4)
    copy = tmp_path / "scene.xml"
    copy.write_text(open(scene).read().replace("0.885809, 0.698859, 0.666422", "0.7, 0.7, 0.7"))
    assert key != reference_key(str(copy), 8, {}, spec, 16, 4)              # content, not name
    ref, cached = get_reference(scene, 8, {}, spec, 16, 4, str(tmp_path / "cache"))
    assert not cached and ref.image.shape == (8, 8, 3) and ref.mse_floor > 0
    again, cached = get_reference(scene, 8, {}, spec, 16, 4, str(tmp_path / "cache"))
    assert cached and np.array_equal(again.image, ref.image) and again.mse_floor == pytest.approx(ref.mse_floor)


def test_store_cuts_a_torn_last_line(tmp_path):
    store = ResultStore(str(tmp_path))
    store.append({"kind": "run", "point": "p", "seed": 1})
    with open(store.path, "ab") as f:
        f.write(b'{"kind": "run", "point": "p", "se')            # killed mid-write
    again = ResultStore(str(tmp_path))
    assert again.done_runs() == {("p", 1): None}          # (no identity recorded in this row)
    again.append({"kind": "run", "point": "p", "seed": 2})
    assert [json.loads(line)["seed"] for line in open(store.path)] == [1, 2]


def test_store_current_runs_skip_superseded_rows(tmp_path):
    store = ResultStore(str(tmp_path))
    store.append({"kind": "run", "point": "p", "seed": 1, "identity_hash": "old"})
    store.append({"kind": "run", "point": "q", "seed": 1, "identity_hash": "old"})
    store.append({"kind": "superseded", "point": "p", "seed": 1, "identity_hash": "old", "changes": "x"})
    assert store.done_runs() == {("q", 1): "old"}
    store.append({"kind": "run", "point": "p", "seed": 1, "identity_hash": "new"})   # rerun
    store.append({"kind": "superseded", "point": "q", "seed": 1, "identity_hash": "other", "changes": "x"})
    assert ResultStore(str(tmp_path)).done_runs() == {("p", 1): "new", ("q", 1): "old"}


def run_cli(*args, **kwargs):
    # (python -m mitsuba_lab_command is the mitsuba-lab script: it chooses a variant only after
    # reading --variant; importing the package, as python -m mitsuba_lab does, activates first)
    return subprocess.run([sys.executable, "-m", "mitsuba_lab_command", *args], capture_output=True, text=True,
                          timeout=600, cwd=ROOT, **kwargs)


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    """One tiny sweep through the real command, shared by the tests that read its output."""
    tmp = tmp_path_factory.mktemp("sweep")
    config = tmp / "tiny.toml"
    config.write_text(TINY.format(cache=tmp / "cache", root=ROOT))
    out = tmp / "out"
    proc = run_cli("sweep", str(config), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "report:" in proc.stdout and "index.html" in proc.stdout
    return out


@pytest.mark.slow
def test_sweep_end_to_end_and_report_rebuild(tiny_sweep):
    out = tiny_sweep
    rows = [json.loads(line) for line in open(out / "results.jsonl")]
    runs = [r for r in rows if r["kind"] == "run"]
    assert len(runs) == 4 * 2
    for r in runs:
        assert r["finite"] and r["negative"] == 0 and r["mse"] > 0 and r["wall_s"] > 0
        assert set(r["regions"]) == {"light", "left"} and 0 <= r["flip"] <= 1 and r["ciede2000"] >= 0
        assert r["rays"]["camera"] == 16 * 16 * r["spp"]
    # more samples, less error (4x the samples: relMSE falls; a loose, safe check)
    by_spp = {spp: np.mean([r["rel_mse"] for r in runs if r["spp"] == spp]) for spp in (2, 8)}
    assert by_spp[8] < by_spp[2]
    html = (out / "report" / "index.html").read_text()
    assert "data:image/png;base64," in html and "Efficiency" in html
    # one lab_mis weighting (balance) alone: Veach's bound has nothing to compare, so no section
    assert "Veach's bound" not in html
    assert (out / "report" / "summary.md").exists() and (out / "results.csv").exists()
    # the report is rebuilt from stored results alone
    os.remove(out / "report" / "index.html")
    proc = run_cli("report", str(out), env={**os.environ, "MITSUBA_LAB_VARIANT": "nope_not_needed"})
    assert proc.returncode == 0, proc.stderr
    assert (out / "report" / "index.html").exists()


@pytest.mark.slow
@pytest.mark.skipif(browser.chromium() is None, reason="Debian's chromium is not installed")
def test_report_loads_in_headless_chromium(tiny_sweep, tmp_path):
    shot = tmp_path / "report.png"
    page = browser.check_page(str(tiny_sweep / "report" / "index.html"), str(shot))
    assert page.images >= 2 and page.broken == 0 and page.errors == 0
    assert shot.stat().st_size > 10_000                      # a real screenshot, not a blank page


@pytest.mark.slow
def test_sweep_resumes_after_kill_9(tmp_path):
    config = tmp_path / "longer.toml"      # 8 points x 2 seeds, so the kill lands mid-sweep
    config.write_text(TINY.format(cache=tmp_path / "cache", root=ROOT).replace("spp = [2, 8]", "spp = [2, 4, 8, 16]"))
    tiny_config = str(config)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "mitsuba_lab_command", "sweep", tiny_config, "-o", str(out)],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    results = out / "results.jsonl"
    deadline = time.time() + 300
    while time.time() < deadline:
        if results.exists() and sum('"kind": "run"' in line for line in open(results)) >= 3:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = [line for line in open(results) if '"kind": "run"' in line]
    assert 3 <= len(before) < 16, "the sweep finished before it could be killed"
    done = run_cli("sweep", tiny_config, "-o", str(out))
    assert done.returncode == 0, done.stderr
    after = [json.loads(line) for line in open(results) if '"kind": "run"' in line]
    keys = [(r["point"], r["seed"]) for r in after]
    assert len(keys) == len(set(keys)) == 16                         # nothing lost, nothing twice
    assert [json.loads(line) for line in before] == after[:len(before)]   # finished rows untouched
    assert not [f for f in os.listdir(out / "images") if f.startswith(".")]   # no temp files left


@pytest.mark.slow
def test_dry_run_prints_plan_and_estimate(tiny_config):
    proc = run_cli("sweep", tiny_config, "--dry-run")
    assert proc.returncode == 0, proc.stderr
    assert "cornell/mis/independent/spp8" in proc.stdout and "estimated total" in proc.stdout


@pytest.mark.slow
def test_bad_config_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[experiment]\nspp = 'many'\n")
    proc = run_cli("sweep", str(bad))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "experiment.spp" in proc.stderr


def test_veach_bound_verdicts():
    from mitsuba_lab.experiment.report.analysis import veach_bound

    balance = {"variance": 1.0, "variance_se": 0.1, "ref_mean_square": 4.0}
    # slack for n_L = 1 at 1 spp: (1/1 - 1/2) * 4 = 2
    assert veach_bound(balance, {"variance": 0.0, "variance_se": 0.0}, 1, 1)["verdict"] == "holds"
    near = veach_bound({**balance, "variance": 3.1}, {"variance": 1.0, "variance_se": 0.1}, 1, 1)
    assert near["rhs"] == pytest.approx(3.0) and near["verdict"] == "within noise"
    far = veach_bound({**balance, "variance": 5.0}, {"variance": 1.0, "variance_se": 0.1}, 1, 1)
    assert far["verdict"] == "violated"
    # spp divides the slack; n_L = 3: (1 - 1/4) * 4 / 4 = 0.75
    assert veach_bound(balance, {"variance": 0.0, "variance_se": 0.0}, 3, 4)["slack"] == pytest.approx(0.75)


@pytest.mark.slow
def test_sweep_on_a_dask_cluster_survives_a_killed_worker(tmp_path):
    """Two worker processes; one is killed with SIGKILL after the first point comes back."""
    distributed = pytest.importorskip("distributed")
    from mitsuba_lab.experiment.execution.executors import DaskExecutor
    from mitsuba_lab.experiment.pipeline.run import SweepRunner

    path = tmp_path / "c.toml"
    path.write_text(TINY.format(cache=tmp_path / "cache", root=ROOT).replace("spp = [2, 8]", "spp = [2, 4, 8, 16]"))
    config = load_config(str(path))
    store = ResultStore(str(tmp_path / "out"))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=50) as cluster, distributed.Client(cluster) as client:
        killed = []

        def progress(event, **info):
            if event == "point_done" and not killed:
                pids = client.run(os.getpid)
                victim = sorted(pids.values())[0]
                os.kill(victim, signal.SIGKILL)
                killed.append(victim)

        SweepRunner(config, build_plan(config), store, progress, DaskExecutor(client)).run()
    runs = store.of_kind("run")
    keys = [(r["point"], r["seed"]) for r in runs]
    assert killed and len(keys) == len(set(keys)) == 16            # every render once, none lost
    assert all(r["finite"] and r["mse"] > 0 for r in runs)
    assert {r["host"] for r in runs} and all("pid" in r for r in runs)


def test_plan_uses_scene_traits():
    from mitsuba_lab.experiment.sweep import assess_scene

    scenes = {name: {"path": os.path.join(ROOT, "scenes", "stiff", f"{name}.xml"), "resolution": 16}
              for name in ("delta_lights_only", "all_specular")}
    config = parse_config({"experiment": {"spp": [4]}, "scenes": scenes,
                           "strategies": {"naive": {"type": "lab_naive"}, "nee": {"type": "lab_nee"},
                                          "mis": {"type": "lab_mis"}}}, os.path.join(ROOT, "x.toml"))
    plan = build_plan(config, assess_scene)
    assert [(x["scene"], x["strategy"]) for x in plan.left_out] == [("delta_lights_only", "naive")]
    assert "delta lights" in plan.left_out[0]["reason"]
    aliases = {(a["scene"], a["strategy"]): a["same_as"] for a in plan.aliases}
    assert aliases == {("delta_lights_only", "mis"): "nee", ("all_specular", "nee"): "naive",
                       ("all_specular", "mis"): "naive"}
    assert sorted(p.id for p in plan.points) == ["all_specular/naive/independent/spp4-4",   # progressive
                                                 "delta_lights_only/nee/independent/spp4-4"]
