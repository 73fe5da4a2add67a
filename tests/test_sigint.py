"""Ctrl-C with real signals. Each command runs as a subprocess in a process group of its own
(``benchmarks/sigint_cli.py``: the command line, which also reports on stderr when a render
begins and when a multi-pass integrator passes a pass boundary). When a chosen moment comes,
SIGINT goes to the group, as a terminal's Ctrl-C sends it. The command must then end with
status 130 and one line, "mitsuba-lab: interrupted". It must leave no temporary file and no
output for the interrupted work, and no process of its group may remain. An interrupted sweep,
resumed, must render exactly what is missing. The timings are measured by
``benchmarks/sigint_timings.py``; here only a generous bound is checked."""
import importlib.util
import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow      # real Ctrl-C to subprocesses: the full suite's tier (pytest -m "not slow" leaves it out)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _load_timings():
    spec = importlib.util.spec_from_file_location("sigint_timings", os.path.join(ROOT, "benchmarks",
                                                                                  "sigint_timings.py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module            # (its dataclass looks its module up)
    spec.loader.exec_module(module)
    return module


timings = _load_timings()
RENDER, PASS = timings.RENDER, timings.PASS
#: From SIGINT to exit, at most (measured: 0.1-0.3 s; the uninterrupted multi-pass renders of
#: test_render take minutes).
BOUND_S = 20.0


def _tail(outcome) -> str:
    """The end of stderr without progress lines (a failure shows what the command said)."""
    return "\n".join(line for line in outcome.stderr.splitlines() if "it/s" not in line)[-3000:]


def assert_interrupted(outcome):
    assert outcome.signalled, f"the moment never came:\n{_tail(outcome)}"
    # (Mitsuba's own "Received interrupt signal, winding down.." goes to stdout; skipped if not)
    lines = [line for line in outcome.stderr.splitlines()
             if not line.startswith("sigint-cli:") and "Received interrupt signal" not in line]
    assert outcome.returncode == timings.EXIT_INTERRUPTED, f"exit {outcome.returncode}:\n{_tail(outcome)}"
    assert lines[-1:] == ["mitsuba-lab: interrupted"] and "Traceback" not in outcome.stderr, _tail(outcome)
    assert outcome.seconds < BOUND_S


@pytest.mark.parametrize("family", ["path", "lab_mis", "lab_photon", "lab_bdpt", "lab_vcm"])
def test_render_stops_and_writes_nothing(tmp_path, family):
    """A multi-pass render stops at a pass boundary (uninterrupted, these take minutes); a
    render that is one kernel (signalled while it runs) once the kernel is done. Either way no
    EXR or PNG is written."""
    _, moment = timings.render_moment(family)
    outcome = timings.interrupt(timings.render_args(family, str(tmp_path / "out.exr")), moment)
    assert_interrupted(outcome)
    assert os.listdir(tmp_path) == []


def test_reference_stops_and_caches_nothing(tmp_path):
    cache = tmp_path / "cache"
    args = ["reference", timings.CORNELL, "--res", "16", "--spp", "4096", "--chunks", "8", "--cache", str(cache)]
    assert_interrupted(timings.interrupt(args, (RENDER, RENDER)))       # in chunk 2 of 8
    assert not cache.exists() or os.listdir(cache) == []


def runs_by_point(folder) -> dict[str, list[int]]:
    runs, orphans = timings.stored(str(folder))
    assert orphans == [] and timings.leftovers(str(folder)) == []
    assert len(runs) == len(set(runs)), "a run stored twice"
    points = {}
    for point, seed in runs:
        points.setdefault(point.split("/")[1], []).append(seed)
    return points


def test_sweep_interrupted_at_each_moment_resumes_exactly_what_is_missing(tmp_path):
    """One sweep folder, one point per family (path, lab_mis, lab_photon, lab_bdpt, lab_vcm;
    2 seeds each), interrupted in the reference, in the first point, between points and in the
    middle of a pass of each multi-pass integrator. Each run resumes the folder: it redoes the
    point interrupted before and is interrupted in the next one."""
    config = timings.sweep_config(str(tmp_path))
    out = tmp_path / "out"
    args = ["sweep", config, "-o", str(out)]
    families = list(timings.FAMILIES)
    for family, moment, wait in timings.sweep_moments():
        assert_interrupted(timings.interrupt(args, wait))
        # stored: every point before the interrupted one ("-": the reference), each with both seeds
        stored = runs_by_point(out)
        assert sorted(stored) == sorted(families[:families.index(family)] if family in families else []), moment
        assert all(len(set(seeds)) == 2 for seeds in stored.values())
        if family == "-":                            # the reference: none cached
            assert not (tmp_path / "cache").exists() or os.listdir(tmp_path / "cache") == []
    assert os.listdir(tmp_path / "cache")            # the reference, cached by the second run
    with open(out / "results.jsonl") as f:
        before = [json.loads(line) for line in f if '"kind": "run"' in line]
    done = subprocess.run([sys.executable, timings.LAUNCHER, *args], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert sorted(runs_by_point(out)) == sorted(families)
    with open(out / "results.jsonl") as f:
        after = [json.loads(line) for line in f if '"kind": "run"' in line]
    assert after[:len(before)] == before and len(after) == 2 * len(families)   # only vcm's point added


def test_sweep_api_raises_keyboard_interrupt_and_ends_its_render_process(tmp_path):
    """``mitsuba_lab.sweep()`` renders its points in a render process of its own (which
    ignores SIGINT: its caller handles it). Ctrl-C in the first point: the caller raises a
    plain KeyboardInterrupt within the bound, and the render process is gone."""
    config = timings.sweep_config(str(tmp_path), ("lab_bdpt",), spp=256)
    out = tmp_path / "out"
    outcome = timings.interrupt(["api-sweep", config, str(out)], ("points to run",), timeout=60)
    assert outcome.signalled and outcome.returncode == timings.EXIT_INTERRUPTED, outcome.stderr[-3000:]
    assert "sigint-cli: KeyboardInterrupt" in outcome.stderr and "Traceback" not in outcome.stderr
    assert outcome.seconds < BOUND_S
    assert runs_by_point(out) == {}


def test_check_stops_in_its_first_strategy(tmp_path):
    # renders 1-2: the path reference's chunks; 3: the first lab strategy's first split
    assert_interrupted(timings.interrupt(timings.check_args(str(tmp_path)), (RENDER,) * 3))
    assert not [n for n in os.listdir(tmp_path) if n.startswith("check")]
    assert timings.leftovers(str(tmp_path)) == []


def test_invert_stops_between_iterations(tmp_path):
    out = tmp_path / "out"
    assert_interrupted(timings.interrupt(["invert", timings.invert_config(str(tmp_path)), "-o", str(out)],
                                         ("| 2/",)))
    assert [f for _, _, names in os.walk(out) for f in names] == []
