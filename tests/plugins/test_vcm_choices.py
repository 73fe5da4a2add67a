"""lab_vcm's choices of how much of its machinery runs: ``connections = one`` and ``pilot``.

* ``connections = one``: each camera vertex connects to one vertex of its light subpath, picked
  uniformly from the n it may use and counted n times, so the estimate stays unbiased; with
  mode ``bpt`` it agrees with Mitsuba's ``path`` by the z-test of test_vcm (|z| <= Z_BOUND = 5),
  and counting the picked connection once fails it (power). The weights' count is checked
  against the brute force in test_bdpt_weights.
* ``pilot``: the render is every technique's or path tracing's alone, with the pilot's path
  tracing averaged in when chosen; the pilot's own choice agrees with ``path``; it picks path
  tracing on Veach's plates and every technique on the caustic scene; light that path tracing's
  pilot misses counts as error. Its counted work is at most ``pilot_share`` (1/8) of the whole
  render's: no pilot where it would be more, or a pilot that stops after its first pair of renders
  once every technique's own counts show the rest would pass it; then the scene decides (every
  technique where a shape is specular, path tracing elsewhere).
"""
import numpy as np
import pytest

from agreement import renders, z_scores
from mitsuba_lab.plugins.integrators.vcm import selection
from mitsuba_lab.scene import load_scene, make_integrator
from test_vcm import MAX_DEPTH, RES, SEEDS_LAB, Z_BOUND, assert_agrees, path_stack, render, scene_path, vcm

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

#: experiments/vcm.toml's vcm_auto: one setting for every scene, the pilot choosing.
AUTO = {"radius": 0.022, "light_paths": 1, "light_paths_max": 16, "aim": 0.9, "pilot": True}
#: The tests of what the pilot chooses run it unbounded (pilot renders of max(4, spp / 128)
#: iterations, as before ``pilot_share``): at their sizes the default share (1/8 of the counted
#: work) affords no pilot, and lab_vcm would render every technique unpiloted.
UNBOUNDED = {"pilot_share": 1.0}


@pytest.mark.parametrize("name", ["cornell_box.xml", "caustic.xml"])
def test_one_connection_per_camera_vertex_agrees_with_mitsuba_path(name, monkeypatch):
    from mitsuba_lab.plugins.integrators.bdpt import camera_subpath

    scene = load_scene(scene_path(name), res=RES)
    ref = path_stack(name)
    assert_agrees(renders(scene, vcm(mode="bpt", connections="one"), 16, SEEDS_LAB), ref,
                  f"one connection per camera vertex on {name}")
    if name != "cornell_box.xml":      # (the caustic's light subpaths hold about one vertex: n is 1)
        return
    right = camera_subpath.pick_light_vertex
    monkeypatch.setattr(camera_subpath, "pick_light_vertex", lambda *a: (lambda r: (r[0], r[1] * 0 + 1))(right(*a)))
    z = z_scores(renders(scene, vcm(mode="bpt", connections="one"), 16, SEEDS_LAB), ref).max_abs_z
    print(f"the picked connection counted once on {name}: max |z| {z:.2f}")
    assert z > Z_BOUND


def check_the_pilots_own_choice_agrees_with_mitsuba_path():
    """Mode bpt on the Cornell box, each seed's pilot choosing for itself."""
    scene = load_scene(scene_path("cornell_box.xml"), res=RES)
    integrator = vcm(mode="bpt", light_paths=0.25, pilot=True, **UNBOUNDED)
    assert_agrees(renders(scene, integrator, 64, SEEDS_LAB), path_stack("cornell_box.xml"), "the pilot's own choice")
    assert integrator.bdpt_stats()["pilot_s"] > 0


def test_path_tracing_chosen_is_lab_mis_with_the_pilots_iterations(monkeypatch):
    """A pilot that chooses path tracing: the render is lab_mis's image (the same seed) averaged
    with the pilot's path tracing by iterations, and traces no light subpath."""
    from mitsuba_lab.plugins.integrators.vcm.pilot import Pilot

    scene = load_scene(scene_path("cornell_box.xml"), res=RES)
    pilot_image = np.full((RES, RES, 3), 0.5)
    monkeypatch.setattr(Pilot, "run", lambda self, *a: (None, pilot_image, 12, {None: 0.0}))
    integrator = vcm(pilot=True)
    image = render(scene, integrator, spp=4)
    mis = render(scene, make_integrator("lab_mis", {"max_depth": MAX_DEPTH}), spp=4)
    np.testing.assert_allclose(image[..., :3], (4 * mis[..., :3] + 12 * 0.5) / 16, rtol=1e-6, atol=1e-7)
    stats = integrator.bdpt_stats()
    assert stats["chose_path_tracing"] and stats["light_subpaths"] == 0


def pilot_choice(scene, integrator, seed, spp):
    """(choice, scores) of the pilot that ``integrator.render(scene, seed=seed, spp=spp)`` runs
    first, without the render of ``spp`` iterations that follows it: with ``pilot_costs = counted``
    (the default) the choice depends on the pilot's renders only, so it is the render's, and the
    render's statistics are the choice's (test_path_tracing_chosen_is_lab_mis_..., test_the_chosen_
    light_subpaths_render_lab_vcm_at_them)."""
    assert integrator.values["pilot_costs"] == "counted"
    integrator.first_radius = integrator.values["radius"]      # (what render() sets before its pilot)
    pilot = integrator.pilot
    choice, _, _, scores = pilot.run(scene, scene.sensors()[0], seed, spp, pilot.companion(), pilot.path_tracer())
    return choice, scores


@pytest.mark.parametrize("name, spp, path_tracing", [("veach_mis.xml", 2048, True), ("caustic.xml", 512, False)])
def test_the_pilot_chooses_path_tracing_where_it_is_more_efficient(name, spp, path_tracing):
    """experiments/vcm.toml's `vcm_auto` at 64x64 (at 32x32 an iteration takes about as long as
    the timer's noise), on 3 seeds: path tracing on Veach's plates at 2048 iterations (no
    technique but emitter hits and NEE lowers its variance there), every technique on the caustic
    scene at 512 (light tracing and merging carry its caustic). The pilot's choice only
    (``pilot_choice``): the 2048 or 512 iterations a render then makes are not needed to know it."""
    scene = load_scene(scene_path(name), res=64)
    integrator = vcm(**AUTO, **UNBOUNDED)
    for seed in range(3):
        choice, scores = pilot_choice(scene, integrator, seed, spp)
        assert (choice is None) == path_tracing, (name, seed, scores)


def test_auto_is_the_experiments_vcm_auto():
    import os
    import tomllib

    with open(os.path.join(os.path.dirname(scene_path("x")), "..", "experiments", "vcm.toml"), "rb") as f:
        strategy = tomllib.load(f)["strategies"]["vcm_auto"]
    assert {k: v for k, v in strategy.items() if k not in ("type", "mode", "merge_first")} == AUTO
    assert strategy["mode"] == "vcm" and not strategy["merge_first"]


def test_light_a_pilot_misses_counts_as_error():
    """Where path tracing's pilot never found the light every technique's did (a caustic), its
    renders agree with each other exactly, yet it loses even at a tenth of the time; the same
    light found by a path tracer 10x cheaper with about the same variance wins."""
    rng = np.random.default_rng(1)
    every = 1.0 + 0.1 * rng.standard_normal((4, 5, 5, 3))
    costs = selection.PilotCosts(camera=1.0, light=0.0, per_pass=0.0, pass_iterations=1.0, path_tracing=0.1)
    missed = selection.pilot_variances(every, None, np.zeros((4, 5, 5, 3)), 8)
    assert missed.path_tracing > 10 * missed.every
    assert selection.choose(missed, costs, [1.0])[0] == 1.0
    found = selection.pilot_variances(every, None, 1.0 + 0.1 * rng.standard_normal((4, 5, 5, 3)), 8)
    assert selection.choose(found, costs, [1.0])[0] is None
    # a score below every technique's, but not by PATH_TRACING_MARGIN, keeps every technique
    close = selection.PilotVariances(every=1.0, camera_side=1.0,
                                     path_tracing=(1 + selection.PATH_TRACING_MARGIN) / 2 / 0.1)
    assert selection.choose(close, costs, [1.0])[0] == 1.0
    assert selection.pilot_iterations(10) == 4 and selection.pilot_iterations(6400) == 50


def test_the_pilot_tells_the_camera_share_of_the_variance():
    """A render sharing the camera seed of another but not its light seed: the camera seed's share
    of the variance (what more light subpaths cannot lower) is the mean product of their
    differences from two independent renders. On 200 x 200 pixels with light, camera and own
    standard deviations 0.2, 0.1, 0.1 (relative variance of one iteration at 4 iterations: 0.24,
    camera side 0.04): both within 5 standard errors of the sample (0.0048 and 0.0032 here,
    from the products' spread); the light seed shared
    instead gives the light's share (power); a longer path-tracing render counts by its
    iterations, less the variance of every technique's mean, over PATH_TRACING_SIZE, if that is
    higher than the other renders' estimate."""
    rng = np.random.default_rng(3)
    shape = (200, 200, 1)
    cameras = 0.1 * rng.standard_normal((4,) + shape)
    every = 1.0 + 0.2 * rng.standard_normal((4,) + shape) + cameras + 0.1 * rng.standard_normal((4,) + shape)
    shared = 1.0 + 0.2 * rng.standard_normal((1,) + shape) + cameras[:1] + 0.1 * rng.standard_normal((1,) + shape)
    path = np.ones((4,) + shape)
    v = selection.pilot_variances(every, shared, path, 4)
    scale = 4 / 1.01           # iterations / (mean^2 + 0.01)
    print(f"every {v.every:.4f} (expected {0.06 * scale:.4f}), camera side {v.camera_side:.4f} "
          f"(expected {0.01 * scale:.4f})")
    assert abs(v.every - 0.06 * scale) < 5 * 0.0048
    assert abs(v.camera_side - 0.01 * scale) < 5 * 0.0032
    lights = every[:1] - cameras[:1] + 0.1 * rng.standard_normal((1,) + shape)   # the light seed shared
    assert selection.pilot_variances(every, lights, path, 4).camera_side > 0.04 * scale
    assert abs(v.every_at(4.0) - (v.camera_side + (v.every - v.camera_side) / 4)) < 1e-12
    longer = 1.0 + 0.5 * rng.standard_normal(shape)          # variance 0.25 of a 16-iteration mean
    with_longer = selection.pilot_variances(every, shared, path, 4, longer, 16)
    # (1 / mean^2 over a mean of variance 0.06 / 4 is 1 + 3 x 0.015 on average)
    quarter = 16 * 0.25 / 1.01 * (1 + 3 * 0.015) / selection.PATH_TRACING_SIZE
    print(f"path tracing with the longer render {with_longer.path_tracing:.3f} (expected {quarter:.3f}; "
          f"standard error 0.7%)")
    assert abs(with_longer.path_tracing - quarter) < 5 * 0.007 * quarter
    short = selection.pilot_variances(every, shared, path + 0.2, 4).path_tracing     # the shared seeds' alone
    assert selection.pilot_variances(every, shared, path + 0.2, 4, path[0], 16).path_tracing == short > 0.1


def test_the_pilot_chooses_light_subpaths_by_variance_times_time():
    """Light-side variance falls as 1 / ratio, the light pass grows as ratio and the camera pass
    as its square root: with the light side carrying the variance and the light pass cheap, more
    light subpaths win; with the camera side carrying it, light_paths stays; a pass's fixed cost
    counts as it is shared by fewer iterations."""
    costs = selection.PilotCosts(camera=1.0, light=0.1, per_pass=0.0, pass_iterations=64.0, path_tracing=1.0)
    ratios = selection.light_path_ratios(1.0, 16.0)
    assert ratios == [1.0, 2.0, 4.0, 8.0, 16.0]
    light_heavy = selection.PilotVariances(every=10.0, camera_side=0.5, path_tracing=100.0)
    choice, scores = selection.choose(light_heavy, costs, ratios)
    assert choice == min((r for r in ratios), key=lambda r: (0.5 + 9.5 / r) * (r ** 0.5 + 0.1 * r)) and choice > 1
    assert scores[None] == 100.0
    camera_heavy = selection.PilotVariances(every=10.0, camera_side=9.5, path_tracing=100.0)
    assert selection.choose(camera_heavy, costs, ratios)[0] == 1.0
    passes = selection.PilotCosts(camera=1.0, light=0.1, per_pass=1000.0, pass_iterations=64.0, path_tracing=1.0)
    assert passes.every_at(16.0) == 4.0 + 1.6 + 1000.0 / 4
    assert selection.choose(selection.PilotVariances(10.0, 0.5, 1e6), passes, ratios)[0] == 1.0
    assert selection.light_path_ratios(0.25, 0.0) == [1.0] and selection.light_path_ratios(1.0, 3.0) == [1.0, 2.0]
    assert selection.light_path_ratios(16.0, 64.0) == [1.0, 2.0, 4.0]
    sizes = selection.PilotCosts.from_sizes((0.03, 0.05), (0.06, 0.11), 4, 80.0, (0.004, 0.016), 4, 16)
    assert np.allclose([sizes.light, sizes.camera, sizes.per_pass, sizes.path_tracing], [0.01, 0.02, 0.05, 0.001])
    hiccup = selection.PilotCosts.from_sizes((1.0, 0.2), (0.06, 0.11), 4, 80.0, (0.004, 0.016), 4, 16)
    assert np.allclose([hiccup.light, hiccup.camera, hiccup.per_pass, hiccup.path_tracing], [0.015, 0.0275, 0, 0.001])


def test_the_chosen_light_subpaths_render_lab_vcm_at_them(monkeypatch):
    """A pilot that chooses 4x light_paths: the render is lab_vcm's at 4 light subpaths per camera
    subpath (the same seed, the same image), its statistics say so."""
    from mitsuba_lab.plugins.integrators.vcm.pilot import Pilot

    scene = load_scene(scene_path("caustic.xml"), res=RES)
    monkeypatch.setattr(Pilot, "run", lambda self, *a: (4.0, None, 0, {4.0: 1.0, None: 2.0}))
    integrator = vcm(radius=0.03, pilot=True, light_paths_max=16)
    image = render(scene, integrator, spp=4, seed=7)
    direct = render(scene, vcm(radius=0.03, light_paths=4), spp=4, seed=7)
    np.testing.assert_allclose(image, direct, rtol=1e-5, atol=1e-7)      # (float atomics in the splats: ~3e-6 measured)
    stats = integrator.bdpt_stats()
    assert stats["light_paths_chosen"] == 4.0 and not stats["chose_path_tracing"]
    assert stats["light_subpaths"] == 4 * 4 * RES * RES


def test_the_pilot_finds_where_more_light_subpaths_lower_the_variance():
    """`vcm_auto`'s pilot at 64x64 on 3 seeds: on light_in_glass (its room lit only through the
    glass, so light tracing and merging carry it) the camera subpaths' share of the variance is
    below a fifth (measured 0.02 to 0.07): more light subpaths lower the rest; on the caustic
    scene above a half (0.86 to 0.97). The count it then picks also depends on the ``cost_*``
    parameters (with ``pilot_costs = measured``, on the pass times of the process it runs in: a
    pass's own cost, ~15 ms in a fresh process, measured 107 ms late in the test suite), so it is
    not asserted here (``choose`` is, above); on the Cornell box, rendering 512 iterations, it
    chooses path tracing alone."""
    for name, low in (("stiff/light_in_glass.xml", True), ("caustic.xml", False)):
        scene = load_scene(scene_path(name), res=64)
        integrator = vcm(**AUTO, **UNBOUNDED)
        integrator.first_radius = AUTO["radius"]      # (what render() sets before its pilot)
        pilot = integrator.pilot
        for seed in range(3):
            pilot.run(scene, scene.sensors()[0], seed, 512, pilot.companion(), pilot.path_tracer())
            v = pilot.variances
            share = v.camera_side / v.every
            assert (share < 0.2) if low else (share > 0.5), (name, seed, v)
    scene = load_scene(scene_path("cornell_box.xml"), res=64)
    for seed in range(3):
        choice, scores = pilot_choice(scene, integrator, seed, 512)
        assert choice is None, ("cornell_box", seed, scores)


def test_the_pilot_is_at_most_its_share_of_the_render():
    """``pilot_share`` (1/8 by default) bounds the pilot's counted work (its renders' counts x the
    ``cost_*`` parameters: no clock) by that share of the whole render's. The Cornell box at 16x16
    with `vcm_auto`'s settings: at 64 spp even the fewest pilot iterations would pass the share, so
    there is no pilot (no pilot render at all) and the choice is the scene's fallback, path tracing
    (no specular shape): the image is lab_mis's with the same seed (a render of every technique
    instead fails the comparison); at 8192 spp a pilot of 6 iterations per render fits (path
    tracing costs 0.61 ms per iteration there, every technique 6.5 ms and a pass 71 ms), chooses
    path tracing, as the unbounded one does at 512 spp on 64x64, and costs at most 1/8 of the whole."""
    scene = load_scene(scene_path("cornell_box.xml"), res=16)
    integrator = vcm(**AUTO, count_rays=True)
    image = render(scene, integrator, spp=64, seed=5)
    stats = integrator.bdpt_stats()
    assert stats["pilot_iterations"] == 0 and stats["pilot_counted_s"] == 0.0 and stats["pilot_scores"] == {}
    assert stats["light_paths_chosen"] == 0.0 and stats["chose_path_tracing"] and stats["light_subpaths"] == 0
    np.testing.assert_array_equal(image, render(scene, integrator.pilot.path_tracer(), spp=64, seed=5))
    render(scene, integrator, spp=8192, seed=5)
    stats = integrator.bdpt_stats()
    print(f"8192 spp: {stats['pilot_iterations']} iterations per pilot render, pilot {stats['pilot_counted_s']:.3f} "
          f"counted s, render {stats['render_counted_s']:.3f}, share {stats['pilot_share']:.3f}")
    assert stats["pilot_iterations"] >= selection.PILOT_MIN_ITERATIONS and stats["chose_path_tracing"]
    assert 0.0 < stats["pilot_share"] <= 1 / 8
    assert stats["pilot_share"] == stats["pilot_counted_s"] / (stats["pilot_counted_s"] + stats["render_counted_s"])


def test_without_a_pilot_a_scene_with_a_specular_shape_renders_every_technique():
    """The caustic scene (a glass sphere) at 16x16 and 64 spp: no pilot fits, and the fallback is
    every technique at light_paths, the image of lab_vcm without a pilot."""
    scene = load_scene(scene_path("caustic.xml"), res=16)
    integrator = vcm(**AUTO, count_rays=True)
    image = render(scene, integrator, spp=64, seed=5)
    stats = integrator.bdpt_stats()
    assert stats["pilot_iterations"] == 0 and stats["pilot_scores"] == {} and stats["pilot_share"] == 0.0
    assert stats["light_paths_chosen"] == 1.0 and not stats["chose_path_tracing"]
    unpiloted = render(scene, vcm(**{k: v for k, v in AUTO.items() if k not in ("pilot", "light_paths_max")}),
                       spp=64, seed=5)
    np.testing.assert_allclose(image, unpiloted, rtol=1e-5, atol=1e-7)      # (float atomics in the splats: ~3e-6 measured)


def test_a_pilot_that_would_pass_its_share_stops_after_its_first_pair():
    """The Cornell box at 16x16 and 2048 spp: priced at EVERY_OVER_PATH_PLAN x path tracing the
    whole pilot does not fit in 1/8, its first pair of renders does (a pass, 71 ms counted, is 117
    iterations of path tracing there); counted, every technique's 10.7x path tracing still leaves
    the whole pilot over its share (it needs about 5900 spp), so it stops: no scores, the scene's
    fallback (path tracing: no specular shape) with what the pilot rendered of it (its counted
    iteration and first render of 4: 5 iterations) to average in, and what it did cost (one
    every-technique render too) within the share of spp iterations of path tracing."""
    scene = load_scene(scene_path("cornell_box.xml"), res=16)
    integrator = vcm(**AUTO)
    integrator.first_radius = AUTO["radius"]      # (what render() sets before its pilot)
    pilot = integrator.pilot
    every, camera = pilot.companion(), pilot.path_tracer()
    choice, image, camera_spp, scores = pilot.run(scene, scene.sensors()[0], 5, 2048, every, camera)
    assert choice is None and camera_spp == 1 + selection.PILOT_MIN_ITERATIONS and scores == {}
    assert image.shape == (16, 16, 3) and np.all(np.isfinite(image)) and image.mean() > 0
    assert pilot.iterations == 0 and pilot.every_all["passes"] == 1
    path_iteration = selection.seconds(pilot.path_all, "path_tracing", integrator.values) / (1 + 4)
    print(f"stopped: {pilot.counted_s:.4f} counted s, budget {selection.share_budget(1 / 8, 2048 * path_iteration):.4f}")
    assert 0 < pilot.counted_s <= selection.share_budget(1 / 8, 2048 * path_iteration)


def test_the_pilots_size_follows_its_share():
    """``PilotPlan``: the counted seconds of a pilot of k iterations per render (every technique's
    renders, their passes, path tracing's paired renders and its longer one), the most k within a
    budget, and that budget: share / (1 - share) of the render's cost."""
    plan = selection.PilotPlan(every=5, path=4)
    # 5 renders x (a pass + 4 x 2 s) + (4 + PATH_TRACING_SIZE) x 4 x 0.5 s
    assert plan.seconds(4, 2.0, 0.5, 1.0, 64) == 5 * 1.0 + 20 * 2.0 + (4 + selection.PATH_TRACING_SIZE) * 4 * 0.5
    assert plan.seconds(4, 2.0, 0.5, 1.0, 2) == 10 * 1.0 + 20 * 2.0 + 32 * 0.5      # (two passes a render)
    assert selection.PilotPlan(every=4, path=4, extra_every=2).seconds(4, 2.0, 0.0, 1.0, 64) == 6 + 18 * 2.0
    assert selection.share_budget(0.125, 7.0) == 1.0 and selection.share_budget(1.0, 7.0) == float("inf")
    assert plan.iterations(1 << 20, float("inf"), 2.0, 0.5, 1.0, 64) == selection.pilot_iterations(1 << 20) == 8192
    assert plan.iterations(512, plan.seconds(4, 2.0, 0.5, 1.0, 64), 2.0, 0.5, 1.0, 64) == 4
    assert plan.iterations(512, plan.seconds(4, 2.0, 0.5, 1.0, 64) - 1e-9, 2.0, 0.5, 1.0, 64) == 0
    assert plan.iterations(4096, plan.seconds(7, 2.0, 0.5, 1.0, 64), 2.0, 0.5, 1.0, 64) == 7
    assert plan.iterations(256, 1e9, 2.0, 0.5, 1.0, 64) == 4         # (at most max(4, spp / 128))


def test_pilot_and_connections_refusals_are_one_line():
    for params, match in (({"mode": "ppm", "pilot": True}, "pilot .* not mode 'ppm'"),
                          ({"connections": "two"}, "parameter 'connections' must be one of all, one"),
                          ({"mode": "bpm", "connections": "one"}, "mode 'bpm' makes no connections"),
                          ({"pilot": False, "light_paths_max": 4}, "light_paths_max .* needs pilot = true"),
                          ({"pilot": True, "light_paths": 4, "light_paths_max": 2}, "below light_paths = 4"),
                          ({"pilot": True, "light_paths_max": 100}, "light_paths_max"),
                          ({"pilot_share": 0.0}, "pilot_share")):
        with pytest.raises(Exception, match=match):
            make_integrator("lab_vcm", params)
