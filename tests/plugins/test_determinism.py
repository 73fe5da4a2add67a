"""A render depends on nothing but its inputs (issue 41): the scene, the settings, the seed and
the variant.

* Two renders of one integrator instance with the same seed are bit-identical, for every lab
  integrator (lab_vcm in each mode, and with its pilot choosing light subpaths): nothing one
  render learns (lab_bdpt's stored vertices per light subpath, which size its passes) carries
  into the next. The lab_bdpt and lab_vcm cases with ``max_vertices`` 1024 and ``max_depth`` 3
  split a render into passes by what its first passes learn, so a learnt value carried over
  changes the second render's passes (it did before issue 41: 4 passes, then 3).
* lab_vcm's pilot chooses from counted work (``pilot_costs = counted``): under fake clocks that
  tick 1 ms or 10 s per reading or jump at random, it makes the same choice with the same
  scores and renders the same image; with ``pilot_costs = measured`` the same clocks change its
  scores (the fake clocks do reach the pilot). No assertion depends on the real clock.

* lab_vcm with no parameter on the caustic, where its defaults do something: the pilot chooses
  every technique and the light aims 0.9 of its subpaths at the glass sphere.

The renders run on one Dr.Jit thread: with several, float atomics (light tracing's splats, the
film) add in the order the threads reach them, so the last bits of a pixel can differ from run
to run whatever the inputs; one thread fixes that order. Measured (2026-11-28, 32x32, 64 spp,
seed 7, max_depth 8; one thread against two): lab_vcm's defaults on the caustic and
light_in_glass and lab_bdpt on the caustic and the Cornell box differ by at most 5.0e-5 (2.7e-6
relative), and the pilot's scores by up to 4e-4 relative, its choice the same; path tracing alone
(lab_mis, and lab_vcm's pilot choosing it on the Cornell box) is bit-identical. No test asserts
identity across thread counts (experiments/results/2026-11-28-vcm-defaults-2.md).
"""
import time

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mitsuba_lab.plugins.params import VCM_MODES
from mitsuba_lab.scene import load_scene, make_integrator
from test_vcm import render, scene_path

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

#: Passes sized by what a render learns: a small vertex budget and short light subpaths.
LEARNT_PASSES = {"max_depth": 3, "max_vertices": 1024}
CASES = [
    ("lab_naive", {}),
    ("lab_nee", {}),
    ("lab_mis", {}),
    ("lab_photon", {"photons_per_pass": 2000, "passes": 2}),
    ("lab_bdpt", {"max_depth": 6}),
    ("lab_bdpt", LEARNT_PASSES),
    *[("lab_vcm", {"mode": mode, "radius": 0.05, **LEARNT_PASSES}) for mode in VCM_MODES],
    ("lab_vcm", {"pilot": True, "light_paths_max": 4, "radius": 0.05, "pilot_share": 1.0, **LEARNT_PASSES}),
    ("lab_pssmlt", {"chains": 256, "bootstrap": 4096}),
    ("lab_mmlt", {"max_depth": 4, "chains": 256, "bootstrap": 4096}),
]
#: The issue's case, smaller: light_in_glass with the pilot choosing up to 16 light subpaths.
#: (``pilot_share`` 1 here and below: at these sizes the default share, 1/8 of the counted work,
#: affords no pilot, and the pilot is what these tests check.)
PILOT = {"pilot": True, "light_paths_max": 16, "max_depth": 8, "pilot_share": 1.0}


@pytest.fixture
def one_thread():
    """Dr.Jit on one thread for the test (float atomics in one order), restored after it."""
    threads = dr.thread_count()
    dr.set_thread_count(1)
    yield
    dr.set_thread_count(threads)


def fake_clocks():
    """time.perf_counter stand-ins: 1 ms per reading, 10 s per reading, random jumps."""
    def ticking(step):
        state = {"now": 0.0}

        def clock():
            state["now"] += step
            return state["now"]
        return clock

    rng = np.random.default_rng(41)
    jumps = {"now": 0.0}

    def jittering():
        jumps["now"] += float(rng.exponential(0.05))
        return jumps["now"]
    return {"1 ms per reading": ticking(1e-3), "10 s per reading": ticking(10.0), "random jumps": jittering}


@pytest.mark.parametrize("plugin, params", CASES, ids=[f"{p}-{'-'.join(f'{k}={v}' for k, v in q.items())}"
                                                       for p, q in CASES])
def test_two_renders_of_one_instance_are_identical(plugin, params, one_thread):
    scene = load_scene(scene_path("cornell_box.xml"), res=16)
    integrator = make_integrator(plugin, params)
    first = render(scene, integrator, spp=8, seed=7)
    passes = integrator.bdpt_stats()["passes"] if hasattr(integrator, "bdpt_stats") else None
    second = render(scene, integrator, spp=8, seed=7)
    if passes is not None:
        assert integrator.bdpt_stats()["passes"] == passes
    assert np.array_equal(first, second), f"{plugin} {params}: max difference {np.abs(first - second).max()}"


def pilot_runs(monkeypatch, costs: str | None = None):
    """{clock: (choice stats, image)} of one lab_vcm instance with a pilot (``pilot_costs``:
    ``costs``, None: the default) rendering the same seed under each fake clock."""
    scene = load_scene(scene_path("stiff/light_in_glass.xml"), res=32)
    integrator = make_integrator("lab_vcm", {**PILOT, **({} if costs is None else {"pilot_costs": costs})})
    runs = {}
    for name, clock in fake_clocks().items():
        monkeypatch.setattr(time, "perf_counter", clock)
        image = render(scene, integrator, spp=32, seed=7)
        stats = integrator.bdpt_stats()
        runs[name] = ((stats["chose_path_tracing"], stats["light_paths_chosen"], stats["pilot_scores"]), image)
    monkeypatch.undo()
    return runs


def test_the_pilots_choice_does_not_depend_on_the_clock(monkeypatch, one_thread):
    """The default pilot (``pilot_costs = counted``)."""
    runs = pilot_runs(monkeypatch)
    (choice, image), *others = runs.values()
    print(f"counted: chose {choice[1]:g} light subpaths (path tracing: {choice[0]}), scores {choice[2]}")
    for name, (other, other_image) in runs.items():
        assert other == choice, (name, other, choice)
        assert np.array_equal(other_image, image), name


def test_measured_costs_follow_the_clock(monkeypatch, one_thread):
    """The power of the test above: the fake clocks reach a pilot that reads them."""
    runs = pilot_runs(monkeypatch, "measured")
    scores = {name: choice[2] for name, (choice, _) in runs.items()}
    print(f"measured: {scores}")
    assert len({tuple(sorted((str(k), v) for k, v in s.items())) for s in scores.values()}) > 1


def test_the_defaults_where_they_aim_render_the_same_image_twice(one_thread):
    """lab_vcm with no parameter on the caustic: the pilot (counted costs) and aim 0.9 at the glass
    sphere; the same instance, the same seed, the same choice, scores and image."""
    from mitsuba_lab.plugins.integrators.common.aim import AimedEmission

    scene = load_scene(scene_path("caustic.xml"), res=32)      # (at 16x16 the pilot chooses path tracing)
    integrator = make_integrator("lab_vcm", {"max_depth": 6, "pilot_share": 1.0})
    assert integrator.settings()["aim"] == 0.9 and AimedEmission(scene, 0.9).enabled
    runs = []
    for _ in range(2):
        image = render(scene, integrator, spp=8, seed=7)
        stats = integrator.bdpt_stats()
        runs.append(((stats["chose_path_tracing"], stats["light_paths_chosen"], stats["pilot_scores"]), image))
    (choice, first), (other, second) = runs
    print(f"chose {choice[1]:g} light subpaths (path tracing: {choice[0]}), scores {choice[2]}")
    assert not choice[0] and other == choice
    assert np.array_equal(first, second), f"max difference {np.abs(first - second).max()}"
