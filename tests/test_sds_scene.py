"""scenes/sds.xml (issue #17): the scene loads with the traits it is meant to have, its regions
file parses with the sweep's own loader, and the regions show what they claim: the `sds`
pixels see the floor only through the glass pane and that floor cannot see the light past the
glass sphere (specular-diffuse-specular), the `direct` pixels see a directly lit wall.
Geometry only (ray casts through pixel centres): no render, well under a second."""
import os

import drjit as dr
import mitsuba as mi
import numpy as np

from mitsuba_lab.experiment.pipeline.config import load_config_dict
from mitsuba_lab.experiment.pipeline.run import pixel_regions
from mitsuba_lab.scene import SceneTraits, load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "scenes", "sds.xml")
REGIONS = os.path.join(ROOT, "scenes", "sds.regions.toml")
RES = 64
LIGHT_CENTRE = (-1.2, 2.6, 0.0)          # as in sds.xml


def regions_at(res):
    config = load_config_dict({"experiment": {"spp": [4]},
                               "scenes": {"sds": {"path": SCENE, "resolution": res, "regions_file": REGIONS}},
                               "strategies": {"mis": {"type": "lab_mis"}}})
    return config.scenes[0], pixel_regions(config.scenes[0], res, res)


def test_sds_scene_traits():
    traits = SceneTraits.from_scene(load_scene(SCENE, res=RES))
    assert traits.area_emitters == 1 and traits.emitter_kinds == {"area"} and traits.emits_light
    assert traits.delta_bsdf and traits.smooth_bsdf and not traits.mixed_bsdfs and not traits.media
    assert traits.warnings() == []


def test_sds_regions_parse_to_whole_pixels():
    spec, rects = regions_at(RES)
    assert set(rects) == {"sds", "direct"}
    for name, (x0, y0, x1, y1) in rects.items():
        assert x1 > x0 and y1 > y0, name
        frac = np.array(spec.regions[name]) * RES          # fractions give whole pixels at res 64
        assert np.allclose(frac, np.round(frac)) and tuple(np.round(frac).astype(int)) == rects[name]
    assert rects["sds"] == (34, 43, 38, 46)


def _first_hits(scene, rect):
    """Camera rays through the centres of the pixels of ``rect``: (ray, interaction)."""
    x0, y0, x1, y1 = rect
    xs, ys = np.meshgrid(np.arange(x0, x1) + 0.5, np.arange(y0, y1) + 0.5)
    pos = mi.Point2f(mi.Float(xs.ravel() / RES), mi.Float(ys.ravel() / RES))
    ray, _ = scene.sensors()[0].sample_ray(0.0, 0.5, pos, mi.Point2f(0.5))
    return ray, scene.ray_intersect(ray)


def _is(si, scene, shape_id):
    shape = next(s for s in scene.shapes() if s.id() == shape_id)
    return np.array(si.is_valid() & (si.shape == mi.ShapePtr(shape)))


def _on_plane(si, axis, value):
    """Hits on the diffuse plane ``p[axis] = value`` (Mitsuba merges the floor and the back wall,
    which share a BSDF, into one mesh, so their ids are gone)."""
    smooth = mi.has_flag(si.bsdf().flags(), mi.BSDFFlags.Smooth)
    return np.array(si.is_valid() & smooth & (dr.abs(si.p[axis] - value) < 1e-4))


def _towards_light(si):
    """A ray from the interaction's point towards the light's centre."""
    return si.spawn_ray(dr.normalize(mi.Vector3f(*LIGHT_CENTRE) - si.p))


def test_sds_region_is_seen_through_the_pane_and_lit_through_the_sphere():
    scene = load_scene(SCENE, res=RES)
    _, rects = regions_at(RES)
    ray, si = _first_hits(scene, rects["sds"])
    assert _is(si, scene, "pane").all()                      # delta first: no t = 1 connection
    floor = scene.ray_intersect(si.spawn_ray(ray.d))         # straight on through the thin pane
    assert _on_plane(floor, 1, 0.0).all()                    # the floor
    assert _is(scene.ray_intersect(_towards_light(floor)), scene, "glass-sphere").all()   # NEE blocked

    ray, si = _first_hits(scene, rects["direct"])
    assert _on_plane(si, 2, -1.5).all()                     # the back wall, seen directly
    assert _is(scene.ray_intersect(_towards_light(si)), scene, "light").all()             # lit directly
