"""lab_vcm's choices of how much of its machinery runs: ``connections = one`` and ``pilot``.

* ``connections = one``: each camera vertex connects to one vertex of its light subpath, picked
  uniformly from the n it may use and counted n times, so the estimate stays unbiased; with
  mode ``bpt`` it agrees with Mitsuba's ``path`` by the z-test of test_vcm (|z| <= Z_BOUND = 5),
  and counting the picked connection once fails it (power). The weights' count is checked
  against the brute force in test_bdpt_weights.
* ``pilot``: the render is every technique's or path tracing's alone, with the pilot's path
  tracing averaged in when chosen; the pilot's own choice agrees with ``path``; it picks path
  tracing on Veach's plates and every technique on the caustic scene; light that path tracing's
  pilot misses counts as error.
"""
import numpy as np
import pytest

from agreement import renders, z_scores
from mitsuba_lab.plugins.integrators.vcm import selection
from mitsuba_lab.scene import load_scene, make_integrator
from test_vcm import MAX_DEPTH, RES, SEEDS_LAB, Z_BOUND, assert_agrees, path_stack, render, scene_path, vcm


@pytest.mark.parametrize("name", ["cornell_box.xml", "caustic.xml"])
def test_one_connection_per_camera_vertex_agrees_with_mitsuba_path(name, monkeypatch):
    from mitsuba_lab.plugins.integrators.bdpt import camera_subpath

    scene = load_scene(scene_path(name), res=RES)
    ref = path_stack(scene)
    assert_agrees(renders(scene, vcm(mode="bpt", connections="one"), 16, SEEDS_LAB), ref,
                  f"one connection per camera vertex on {name}")
    if name != "cornell_box.xml":      # (the caustic's light subpaths hold about one vertex: n is 1)
        return
    right = camera_subpath.pick_light_vertex
    monkeypatch.setattr(camera_subpath, "pick_light_vertex", lambda *a: (lambda r: (r[0], r[1] * 0 + 1))(right(*a)))
    z = z_scores(renders(scene, vcm(mode="bpt", connections="one"), 16, SEEDS_LAB), ref).max_abs_z
    print(f"the picked connection counted once on {name}: max |z| {z:.2f}")
    assert z > Z_BOUND


def test_the_pilots_own_choice_agrees_with_mitsuba_path():
    """Mode bpt on the Cornell box, each seed's pilot choosing for itself."""
    scene = load_scene(scene_path("cornell_box.xml"), res=RES)
    integrator = vcm(mode="bpt", light_paths=0.25, pilot=True)
    assert_agrees(renders(scene, integrator, 64, SEEDS_LAB), path_stack(scene), "the pilot's own choice")
    assert integrator.bdpt_stats()["pilot_s"] > 0


def test_path_tracing_chosen_is_lab_mis_with_the_pilots_iterations(monkeypatch):
    """A pilot that chooses path tracing: the render is lab_mis's image (the same seed) averaged
    with the pilot's path tracing by iterations, and traces no light subpath."""
    from mitsuba_lab.plugins.integrators.vcm.integrator import LabVCMIntegrator

    scene = load_scene(scene_path("cornell_box.xml"), res=RES)
    pilot_image = np.full((RES, RES, 3), 0.5)
    monkeypatch.setattr(LabVCMIntegrator, "_pilot", lambda self, *a: (True, pilot_image, 12))
    integrator = vcm(pilot=True)
    image = render(scene, integrator, spp=4)
    mis = render(scene, make_integrator("lab_mis", {"max_depth": MAX_DEPTH}), spp=4)
    np.testing.assert_allclose(image[..., :3], (4 * mis[..., :3] + 12 * 0.5) / 16, rtol=1e-6, atol=1e-7)
    stats = integrator.bdpt_stats()
    assert stats["chose_path_tracing"] and stats["light_subpaths"] == 0


@pytest.mark.parametrize("name, light_paths, path_tracing", [("veach_mis.xml", 0.0625, True),
                                                             ("caustic.xml", 4, False)])
def test_the_pilot_chooses_path_tracing_where_it_is_more_efficient(name, light_paths, path_tracing):
    """At 32x32 and 1024 iterations (pilots of 8), on 3 seeds: path tracing on Veach's plates
    (no technique but emitter hits and NEE lowers its variance there), every technique on the
    caustic scene (light tracing carries its caustic)."""
    scene = load_scene(scene_path(name), res=32)
    integrator = vcm(radius=0.03, light_paths=light_paths, pilot=True)
    for seed in range(3):
        render(scene, integrator, spp=1024, seed=seed)
        assert integrator.bdpt_stats()["chose_path_tracing"] == path_tracing, (name, seed)


def test_light_a_pilot_misses_counts_as_error():
    """Where path tracing's pilot never found the light every technique's did (a caustic), its
    renders agree with each other exactly, yet it loses even at a tenth of the time; the same
    light found by a path tracer 10x cheaper with twice the variance wins."""
    rng = np.random.default_rng(1)
    every = 1.0 + 0.1 * rng.standard_normal((4, 5, 5, 3))
    var_every, var_camera = selection.relative_variances(every, np.zeros((4, 5, 5, 3)), 8)
    assert np.all(var_camera > 10 * var_every)
    assert not selection.path_tracing_wins(var_every, var_camera, 1.0, 0.1)
    camera = 1.0 + 0.14 * rng.standard_normal((4, 5, 5, 3))
    var_every, var_camera = selection.relative_variances(every, camera, 8)
    assert selection.path_tracing_wins(var_every, var_camera, 1.0, 0.1)
    assert selection.pilot_iterations(10) == 4 and selection.pilot_iterations(6400) == 50


def test_pilot_and_connections_refusals_are_one_line():
    for params, match in (({"mode": "ppm", "pilot": True}, "pilot .* not mode 'ppm'"),
                          ({"connections": "two"}, "parameter 'connections' must be one of all, one"),
                          ({"mode": "bpm", "connections": "one"}, "mode 'bpm' makes no connections")):
        with pytest.raises(Exception, match=match):
            make_integrator("lab_vcm", params)
