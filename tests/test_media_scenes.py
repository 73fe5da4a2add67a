"""The participating-media scenes of issue 44 (scenes/fog_shafts.xml, smoke.xml, chromatic.xml): each
loads with a medium, its regions file parses with the sweep's own loader to whole pixels inside the
image, each scene has the feature it is meant to test (read from the loaded scene), the regions show
what their comments claim (ray casts through pixel centres, no render), and the smoke grid's
generator rewrites scenes/smoke.vol byte for byte (and fog.vol's, of fog_lantern.xml). A few seconds in all."""
import importlib.util
import os

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mitsuba_lab.experiment.pipeline.config import load_config_dict
from mitsuba_lab.experiment.pipeline.run import pixel_regions
from mitsuba_lab.scene import SceneTraits, load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "scenes")
RES = 64
REGIONS = {"fog_shafts": {"shafts", "floor_light"}, "smoke": {"plume"}, "chromatic": {"medium"}}


def _path(name, ext=".xml"):
    return os.path.join(SCENES, name + ext)


@pytest.fixture(scope="module")
def scenes():
    return {name: load_scene(_path(name), res=RES) for name in REGIONS}


def _make_smoke(name="make_smoke"):
    spec = importlib.util.spec_from_file_location(name, os.path.join(SCENES, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def regions_at(name, res):
    config = load_config_dict({"experiment": {"spp": [4]},
                               "scenes": {name: {"path": _path(name), "resolution": res,
                                                 "regions_file": _path(name, ".regions.toml")}},
                               "strategies": {"mis": {"type": "lab_mis"}}})
    return config.scenes[0], pixel_regions(config.scenes[0], res, res)


def _params(scene):
    return mi.traverse(scene)


def _value(params, key):
    return np.array(params[key]).ravel()


def _pixel_rays(scene, rect):
    """Camera rays through the centres of the pixels of ``rect`` at res RES."""
    x0, y0, x1, y1 = rect
    xs, ys = np.meshgrid(np.arange(x0, x1) + 0.5, np.arange(y0, y1) + 0.5)
    pos = mi.Point2f(mi.Float(xs.ravel() / RES), mi.Float(ys.ravel() / RES))
    ray, _ = scene.sensors()[0].sample_ray(0.0, 0.5, pos, mi.Point2f(0.5))
    return ray


# -- every scene --------------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(REGIONS))
def test_scene_loads_with_a_medium(scenes, name):
    traits = SceneTraits.from_scene(scenes[name])
    assert traits.media and traits.emits_light
    assert scenes[name].bbox().valid()         # (shapes Mitsuba merges into one mesh have no box)
    assert not traits.far_clip_problems


@pytest.mark.parametrize("name", sorted(REGIONS))
def test_regions_parse_to_whole_pixels_inside_the_image(name):
    spec, rects = regions_at(name, RES)
    assert set(rects) == REGIONS[name]
    for region, (x0, y0, x1, y1) in rects.items():
        assert 0 <= x0 < x1 <= RES and 0 <= y0 < y1 <= RES, region
        frac = np.array(spec.regions[region]) * RES          # fractions give whole pixels at res 64
        assert np.allclose(frac, np.round(frac)) and tuple(np.round(frac).astype(int)) == rects[region]
    _, doubled = regions_at(name, 2 * RES)                    # and the same area at res 128
    assert doubled == {k: tuple(2 * v for v in r) for k, r in rects.items()}


# -- fog_shafts ---------------------------------------------------------------------------------

ROOM = (np.array([-2.0, 0.0, -2.0]), np.array([2.0, 3.0, 2.0]))     # as in fog_shafts.xml
HOUSING_X = -1.0                     # the partition: the lamp housing (clear air) behind it, the fog before it


def test_fog_shafts_camera_is_in_thin_fog_and_the_light_in_a_clear_housing(scenes):
    scene = scenes["fog_shafts"]
    params = _params(scene)
    light = _value(params, "light.position")
    assert len(scene.emitters()) == 1 and "PointLight" in str(scene.emitters()[0])
    assert np.all(light > ROOM[0]) and np.all(light < ROOM[1]) and light[0] < HOUSING_X
    assert scene.sensors()[0].get_medium() is not None                # the camera is in the fog
    sigma_t = _value(params, "fog.sigma_t.value.value") * _value(params, "fog.scale")
    albedo = _value(params, "fog.albedo.value.value")
    width = ROOM[1][0] - HOUSING_X
    assert 0.3 <= float(sigma_t.max()) * width <= 1.0                # 0.3 to 1 mean free paths across
    assert np.allclose(albedo, 0.8)
    # the fog is on the room's side of every surface that has it; the housing's lining has none
    assert all(shape.interior_medium() is None for shape in scene.shapes())
    fogged = [shape.exterior_medium() is not None for shape in scene.shapes()]
    assert any(fogged) and not all(fogged)
    # from the light: through a gap of the louvre into the fog, and to the housing's back in clear air
    o = mi.Point3f(*(float(v) for v in light))
    for target, fog in (([HOUSING_X, 1.73, -0.3], True), ([-1.5, 1.5, -2.0], False)):
        d = dr.normalize(mi.Vector3f(*target) - o)
        si = scene.ray_intersect(mi.Ray3f(o, d))
        assert (si.target_medium(d)[0] is not None) == fog, target
        assert float(si.p.x[0]) < HOUSING_X + 1e-3


def _lit(scene, points, light):
    """Points with an unblocked segment to the point light (null surfaces, where the fog ends in
    the window, let it through)."""
    d = light - points
    dist = dr.norm(d)
    d /= dist
    start, blocked = mi.Float(0.0), mi.Bool(False)
    for _ in range(4):                                   # (the window is the one null surface)
        ray = mi.Ray3f(points + start * d, d)
        ray.maxt = dist * (1 - 1e-4) - start
        si = scene.ray_intersect(ray)
        null = si.is_valid() & mi.has_flag(si.bsdf().flags(), mi.BSDFFlags.Null)
        blocked |= si.is_valid() & ~null
        start = dr.select(null, start + si.t + 1e-4, mi.Float(dist))
    return ~blocked


def test_fog_shafts_regions_show_lit_air_and_a_lit_floor(scenes):
    scene = scenes["fog_shafts"]
    light = mi.Point3f(*(float(v) for v in _value(_params(scene), "light.position")))
    _, rects = regions_at("fog_shafts", RES)

    ray = _pixel_rays(scene, rects["shafts"])
    si = scene.ray_intersect(ray)
    facing = dr.dot(si.n, light - si.p) > 0
    hit_lit = np.array(_lit(scene, si.p + 1e-3 * si.n, light) & facing)
    assert not hit_lit.any()                                          # the surfaces behind are dark
    assert np.all(np.array(si.p.x) > -1.0 - 1e-4)                     # in the room, not the housing
    steps = 64                                                        # the air in front of them is lit
    frac = np.repeat((np.arange(steps) + 0.5) / steps, dr.width(ray))      # every step of every ray at once
    index = mi.UInt32(np.tile(np.arange(dr.width(ray)), steps))
    points = dr.gather(mi.Point3f, ray.o, index) + dr.gather(mi.Vector3f, ray.d, index) * (
        dr.gather(mi.Float, si.t, index) * mi.Float(frac))
    lit_air = np.array(_lit(scene, points, light)).reshape(steps, -1).sum(axis=0)
    assert np.all(lit_air >= 4), lit_air

    si = scene.ray_intersect(_pixel_rays(scene, rects["floor_light"]))
    assert np.allclose(np.array(si.p.y), 0.0, atol=1e-4)
    assert np.array(_lit(scene, si.p + 1e-3 * si.n, light)).all()


# -- smoke --------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["smoke", "fog"])
def test_smoke_generator_rewrites_the_committed_grid(tmp_path, name):
    make_smoke = _make_smoke(f"make_{name}")
    out = make_smoke.main(str(tmp_path / f"{name}.vol"))
    with open(out, "rb") as f, open(os.path.join(SCENES, f"{name}.vol"), "rb") as g:
        assert f.read() == g.read()
    assert os.path.getsize(out) < 500_000


def test_smoke_grid_is_sparse_and_reads_back_in_mitsuba():
    make_smoke = _make_smoke()
    density = make_smoke.smoke_density()
    assert (density == 0).mean() > 0.8                                # most cells empty
    assert density.max() == 1.0 and density.mean() < 0.05           # one dense core
    grid = mi.VolumeGrid(os.path.join(SCENES, "smoke.vol"))           # the format Mitsuba reads
    assert list(grid.size()) == list(make_smoke.SHAPE) and grid.channel_count() == 1
    np.testing.assert_array_equal(np.array(grid).reshape(density.shape), density)


def test_smoke_is_a_grid_volume_and_the_plume_region_crosses_smoke(scenes):
    scene = scenes["smoke"]
    plume = next(s for s in scene.shapes() if s.id() == "plume")
    medium = plume.interior_medium()
    assert medium is not None and medium.is_homogeneous() is False
    params = _params(scene)
    assert "plume.interior_medium.sigma_t.data" in params            # a gridvolume's data
    scale = float(_value(params, "plume.interior_medium.scale")[0])
    density = _make_smoke().smoke_density() * scale
    _, rects = regions_at("smoke", RES)
    ray = _pixel_rays(scene, rects["plume"])
    # Optical depth along each ray, by the cell each step falls in (the grid fills the box
    # [-0.5, 0.5] x [0.01, 1.51] x [-0.5, 0.5]: smoke.xml's gridvolume to_world).
    o, d = (np.array(v).reshape(3, -1) for v in (ray.o, ray.d))
    nz, ny, nx = density.shape
    ts = np.linspace(1.5, 4.0, 500)
    tau = np.zeros(o.shape[1])
    for t in ts:
        p = o + d * t
        u = np.stack([p[0] + 0.5, (p[1] - 0.01) / 1.5, p[2] + 0.5])
        inside = np.all((u >= 0) & (u < 1), axis=0)
        idx = [np.clip((u[i] * n).astype(int), 0, n - 1) for i, n in enumerate((nx, ny, nz))]
        tau += np.where(inside, density[idx[2], idx[1], idx[0]], 0.0) * (ts[1] - ts[0])
    assert tau.min() > 0.2 and tau.mean() > 3.0, (tau.min(), tau.mean())


# -- chromatic ----------------------------------------------------------------------------------

def test_chromatic_medium_scatters_tenfold_more_in_one_channel(scenes):
    scene = scenes["chromatic"]
    ball = next(s for s in scene.shapes() if s.id() == "ball")
    assert ball.interior_medium() is not None and ball.interior_medium().is_homogeneous()
    assert "dielectric" in str(ball.bsdf()).lower()
    params = _params(scene)
    sigma_t = _value(params, "ball.interior_medium.sigma_t.value.value")
    sigma_s = sigma_t * _value(params, "ball.interior_medium.albedo.value.value") * \
        _value(params, "ball.interior_medium.scale")
    assert sigma_s.size == 3 and sigma_s.max() / sigma_s.min() >= 9.5
    assert scene.sensors()[0].get_medium() is None                   # the camera is outside


def test_chromatic_region_sees_the_ball(scenes):
    scene = scenes["chromatic"]
    ball = next(s for s in scene.shapes() if s.id() == "ball")
    _, rects = regions_at("chromatic", RES)
    si = scene.ray_intersect(_pixel_rays(scene, rects["medium"]))
    assert np.array(si.is_valid() & (si.shape == mi.ShapePtr(ball))).all()
