"""A reference must render every feature of its scene (issue 42, item 1): on a scene with a
participating medium the default reference is volpathmis, a named `path` reference is refused,
a strategy that ignores the medium (Mitsuba's path and ptracer) is left out with its reason unless
experiment.allow_unsupported names it (then every table marks it), and a sweep with nothing to
run renders nothing and exits 2. The same rule for `mitsuba-lab reference` and `check`.

The scene: a 16x16 glass ball holding a homogeneous medium over a diffuse floor, under a
constant environment; renders of a few spp, fixed seeds (the sweep's)."""
import csv
import os

import pytest
from lab_cli import run

from mitsuba_lab.experiment.pipeline.config import ConfigError
from mitsuba_lab.experiment.sweep import prepare_sweep

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORNELL = os.path.join(ROOT, "scenes", "cornell_box.xml")

FOG_XML = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="16"/>
            <integer name="height" value="16"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <shape type="sphere">
        <float name="radius" value="0.7"/>
        <bsdf type="dielectric"/>
        <medium type="homogeneous" name="interior">
            <float name="albedo" value="0.8"/>
            <float name="sigma_t" value="3"/>
        </medium>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="3"/><translate value="0, 0, -1"/></transform>
        <bsdf type="diffuse"/>
    </shape>
    <emitter type="constant"/>
</scene>
"""

CONFIG = """
[experiment]
spp = [2]
repetitions = 2
progressive = false
max_depth = 4
metrics = []
{experiment}

[reference]
spp = 8
chunks = 2
cache = "{cache}"
{reference}

[scenes.fog]
path = "fog.xml"
{scene}

[strategies]
{strategies}
"""
MEDIUM_REASON = "path ignores participating media (the scene has a medium): use volpath or volpathmis"


def write_config(tmp_path, name="fog.toml", experiment="", reference="", scene="",
                 strategies='volpath = { type = "volpath" }\npath = { type = "path" }\nmis = { type = "lab_mis" }\n'
                            'tracer = { type = "ptracer" }'):
    (tmp_path / "fog.xml").write_text(FOG_XML)
    path = tmp_path / name
    path.write_text(CONFIG.format(cache=tmp_path / "cache", experiment=experiment, reference=reference,
                                  scene=scene, strategies=strategies))
    return str(path)


def cached_references(tmp_path) -> list[str]:
    cache = tmp_path / "cache"
    return sorted(os.listdir(cache)) if cache.exists() else []


def test_the_default_reference_renders_the_medium(tmp_path):
    path = write_config(tmp_path, scene="", strategies='volpath = { type = "volpath" }')
    with open(path, "a") as f:
        f.write(f'\n[scenes.cornell]\npath = "{CORNELL}"\nresolution = 16\n')
    config, _ = prepare_sweep(path)
    chosen = {scene.name: config.reference_for(scene).integrator.type for scene in config.scenes}
    assert chosen == {"fog": "volpathmis", "cornell": "path"}
    assert config.reference_for(config.scenes[0]).spp == 8         # the rest of [reference] is kept


@pytest.mark.parametrize("where, key", [("reference", "reference.integrator"),
                                        ("scene", "scenes.fog.reference.integrator")])
def test_a_named_reference_that_ignores_the_medium_is_refused(tmp_path, where, key):
    table = {"reference": 'integrator = { type = "path" }',
             "scene": 'reference = { integrator = { type = "path" } }'}[where]
    path = write_config(tmp_path, **{where: table})
    with pytest.raises(ConfigError) as err:
        prepare_sweep(path)
    assert str(err.value) == f"{path}: {key}: scene 'fog': the reference must render every feature of the scene, " \
                             f"but {MEDIUM_REASON}"
    code, out, err = run(["sweep", path, "-o", str(tmp_path / "out")])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "scene 'fog'" in err and MEDIUM_REASON in err
    assert "Traceback" not in err and not (tmp_path / "out").exists() and cached_references(tmp_path) == []


def test_a_strategy_that_ignores_the_medium_is_left_out_with_its_reason(tmp_path):
    _, plan = prepare_sweep(write_config(tmp_path))
    left = {item["strategy"]: item["reason"] for item in plan.left_out}
    assert left["path"] == MEDIUM_REASON and "participating media" in left["tracer"] and "mis" not in left
    assert [p.strategy for p in plan.points] == ["volpath", "mis"] and plan.unsupported == []


@pytest.mark.slow
def test_dry_run_lists_what_it_leaves_out(tmp_path):
    code, out, err = run(["sweep", write_config(tmp_path), "--dry-run"])
    assert code == 0, err
    assert "fog: 2 points" in out and "reference volpathmis" in out
    assert f"left out: fog / path: {MEDIUM_REASON}" in out
    assert "left out: fog / tracer: ptracer ignores participating media" in out
    assert "left out: fog / mis" not in out
    assert cached_references(tmp_path) == []


def test_nothing_to_run_renders_nothing_and_exits_2(tmp_path):
    path = write_config(tmp_path, strategies='path = { type = "path" }\ntracer = { type = "ptracer" }')
    code, out, err = run(["sweep", path, "-o", str(tmp_path / "out")])
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "nothing to run: every strategy is left out on every scene" in err and MEDIUM_REASON in err
    assert "experiment.allow_unsupported" in err
    assert not (tmp_path / "out").exists() and cached_references(tmp_path) == []    # not even the reference

    code, out, err = run(["sweep", path, "--dry-run"])           # the plan, then the same refusal
    assert code == 2 and len(err.strip().splitlines()) == 1 and "nothing to run" in err
    assert f"left out: fog / path: {MEDIUM_REASON}" in out and "fog: 0 points" in out
    assert cached_references(tmp_path) == []


@pytest.mark.slow
def test_allowed_strategies_run_and_every_table_marks_them(tmp_path):
    # (strategy names unlike any plugin name, so that a table cell names the strategy)
    path = write_config(tmp_path, experiment='allow_unsupported = ["pt", "lab"]',
                        strategies='volpath = { type = "volpath" }\npt = { type = "path" }\nlab = { type = "ptracer" }')
    _, plan = prepare_sweep(path)
    assert plan.left_out == []
    assert {(u["strategy"], u["mark"]) for u in plan.unsupported} == {("pt", "ignores media"),
                                                                      ("lab", "ignores media")}
    code, out, err = run(["sweep", path, "-o", str(tmp_path / "out")])
    assert code == 0, err
    summary = (tmp_path / "out" / "report" / "summary.md").read_text()
    assert "## Strategies run on scenes they cannot render correctly" in summary
    assert f"| fog | pt | ignores media | {MEDIUM_REASON} |" in summary
    assert "Reference: volpathmis" in summary
    rows = [line for line in summary.splitlines() if line.startswith("|") and "| ignores media |" not in line]
    cells = [cell.strip() for line in rows for cell in line.split("|")]
    for name in ("pt", "lab"):
        assert f"{name} (ignores media)" in cells
        assert name not in cells and not any(c.startswith(f"fog/{name}/") and "ignores media" not in c for c in cells)
    assert "volpath" in cells                                      # the one that renders the medium: unmarked


def test_allow_unsupported_names_strategies(tmp_path):
    with pytest.raises(ConfigError) as err:
        prepare_sweep(write_config(tmp_path, experiment='allow_unsupported = ["nope"]'))
    assert "experiment.allow_unsupported: expected a list of [strategies] names (volpath, path, mis, tracer), " \
           "got ['nope']" in str(err.value)


@pytest.mark.slow
def test_the_reference_command_follows_the_same_rule(tmp_path, monkeypatch):
    monkeypatch.setenv("MITSUBA_LAB_CACHE", str(tmp_path / "cache"))
    (tmp_path / "fog.xml").write_text(FOG_XML)
    scene = str(tmp_path / "fog.xml")
    code, out, err = run(["reference", scene, "--integrator", "path", "--spp", "4", "--chunks", "2"])
    assert code == 2 and err.strip().splitlines() == [
        f"mitsuba-lab: error: scene {scene}: the reference must render every feature of the scene, but {MEDIUM_REASON}"]
    assert cached_references(tmp_path) == []
    code, out, err = run(["reference", scene, "--spp", "4", "--chunks", "2"])
    assert code == 0, err
    assert "(volpathmis, 16x16) rendered" in out


@pytest.mark.slow
def test_check_measures_against_a_reference_that_renders_the_medium(tmp_path, monkeypatch):
    monkeypatch.setenv("MITSUBA_LAB_CACHE", str(tmp_path / "cache"))
    (tmp_path / "fog.xml").write_text(FOG_XML)
    code, out, err = run(["check", str(tmp_path / "fog.xml"), "--res", "16", "--spp", "4", "--ref-spp", "4",
                          "--splits", "2", "-o", str(tmp_path / "check")])
    assert code == 0, err
    with open(tmp_path / "check.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows[0]["strategy"] == "volpathmis (reference)"
    status = {row["strategy"]: row["status"] for row in rows[1:]}
    for name in ("lab_naive", "lab_nee", "lab_mis_power", "lab_mis_balance", "lab_bdpt", "lab_vcm",
                 "lab_photon"):                                      # (they render media)
        assert status[name] == "ok", name
    assert status["lab_mmlt"] == "skipped"                           # it leaves them out
