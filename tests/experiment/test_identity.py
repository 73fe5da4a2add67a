"""A run's identity: a resumed sweep redoes exactly the runs whose identity changed."""
import collections
import json
import os
import shutil

import pytest

from mitsuba_lab import cli
from mitsuba_lab.experiment.pipeline import identity
from mitsuba_lab.experiment.pipeline.identity import describe_changes
from mitsuba_lab.experiment.pipeline.store import ResultStore

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

CONFIG = """
[experiment]
name = "ident"
spp = [2]
repetitions = 2
progressive = false
seed = {seed}
max_depth = {max_depth}
metrics = []

[reference]
integrator = {{ type = "path" }}
spp = {ref_spp}
chunks = 2
cache = "{cache}"

[scenes.box]
path = "{scene}"
resolution = {res}

[strategies]
nee = {{ type = "lab_nee" }}
mis = {{ type = "lab_mis", heuristic = "{heuristic}" }}

[samplers]
ind = {{ type = "independent" }}
hal = {{ type = "lab_halton", randomization = "{randomization}" }}
"""
BASE = dict(seed=0, max_depth=4, ref_spp=16, res=8, heuristic="balance", randomization="owen")
ALL = {f"box/{s}/{p}/spp2" for s in ("nee", "mis") for p in ("ind", "hal")}


def sweep(tmp_path, capsys, **changes):
    settings = {**BASE, **changes}
    config = tmp_path / "ident.toml"
    config.write_text(CONFIG.format(cache=tmp_path / "cache", scene=tmp_path / "box.xml", **settings))
    out = tmp_path / "out"
    before = len(ResultStore(str(out)).rows) if out.exists() else 0
    code = cli.main(["sweep", str(config), "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 0, err
    rows = ResultStore(str(out)).rows[before:]
    redone = collections.Counter(r["point"] for r in rows if r["kind"] == "run")
    return redone, err


@pytest.mark.slow
def test_each_identity_field_redoes_exactly_its_runs(tmp_path, capsys, monkeypatch):
    shutil.copy(os.path.join(ROOT, "scenes", "cornell_box.xml"), tmp_path / "box.xml")
    redone, _ = sweep(tmp_path, capsys)
    assert redone == {p: 2 for p in ALL}                                   # 4 points x 2 seeds

    redone, err = sweep(tmp_path, capsys)                                  # nothing changed
    assert not redone and "0 points to run (4 already done)" in err

    redone, err = sweep(tmp_path, capsys, heuristic="power")               # one strategy
    assert set(redone) == {"box/mis/ind/spp2", "box/mis/hal/spp2"} and set(redone.values()) == {2}
    assert '4 stored runs no longer match: integrator heuristic "balance" -> "power"; rerunning them' in err

    redone, err = sweep(tmp_path, capsys, heuristic="power", randomization="permute_digits")   # one sampler
    assert set(redone) == {"box/nee/hal/spp2", "box/mis/hal/spp2"}
    assert 'sampler randomization "owen" -> "permute_digits"' in err

    # every other field touches every run of the scene
    cases = [
        (dict(res=10), "scene resolution 8 -> 10"),
        (dict(res=10, max_depth=3), "integrator max_depth 4 -> 3"),
        (dict(res=10, max_depth=3, ref_spp=32), "reference changed"),
        (dict(res=10, max_depth=3, ref_spp=32, seed=1), "not in this sweep's plan any more"),
    ]
    state = dict(heuristic="power", randomization="permute_digits")
    for change, message in cases:
        state.update(change)
        redone, err = sweep(tmp_path, capsys, **state)
        assert redone == {p: 2 for p in ALL}, change
        assert message in err, (change, err)

    box = tmp_path / "box.xml"                                             # the scene's content
    box.write_text(box.read_text().replace('value="0.570068, 0.0430135, 0.0443706"', 'value="0.5, 0.0430135, 0.0443706"', 1))
    redone, err = sweep(tmp_path, capsys, **state)
    assert redone == {p: 2 for p in ALL} and "scene file content changed" in err

    monkeypatch.setattr(identity, "plugin_code_version", lambda: "0123456789abcdef")   # lab code
    redone, err = sweep(tmp_path, capsys, **state)
    assert redone == {p: 2 for p in ALL} and "lab plugin code changed" in err

    # the store keeps every row, the superseded ones marked; the report reads the current ones
    out = tmp_path / "out"
    store = ResultStore(str(out))
    current = store.current_runs()
    assert len(current) == 8 and len(store.of_kind("run")) > 8
    assert len(store.of_kind("superseded")) == len(store.of_kind("run")) - 8
    with open(out / "results.csv") as f:
        assert sum(1 for _ in f) == 1 + 8
    assert {r["identity"]["integrator"]["params"]["max_depth"] for r in current} == {3}


def test_describe_changes_names_fields():
    old = {"integrator": {"type": "lab_mis", "params": {"max_depth": 8, "emitter_samples": 2}},
           "sampler": {"type": "lab_zsobol", "params": {}}, "reference": "a", "spp": 4}
    new = {"integrator": {"type": "lab_mis", "params": {"max_depth": 5, "emitter_samples": 4}},
           "sampler": {"type": "lab_zsobol", "params": {"width": 64}}, "reference": "b", "spp": 4}
    assert describe_changes(old, new) == ("integrator emitter_samples 2 -> 4; integrator max_depth 8 -> 5; "
                                          "sampler width (unset) -> 64")
    assert describe_changes(None, new).startswith("stored without a run identity")
    assert describe_changes(old, old) == "identity changed"
