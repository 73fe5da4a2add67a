"""Scenes with participating media written as users write them, as dicts for ``mi.load_dict``
(the current variant): a box of fog under an area light, a point light inside fog seen from a
camera inside it, a chromatic medium inside glass, heterogeneous smoke under an environment and
a spot light beside a masked card, a point light inside uneven heterogeneous fog. 32x24 films
(8x8 blocks: 4 x 3), box filter."""
from __future__ import annotations

import numpy as np

import mitsuba as mi

T = mi.ScalarTransform4f


def rgb(*value) -> dict:
    return {"type": "rgb", "value": list(value) if len(value) == 3 else [value[0]] * 3}


def base(sensor_medium: dict | None = None, res=(32, 24)) -> dict:
    """A camera looking at a diffuse floor (4 units across)."""
    sensor = {"type": "perspective", "fov": 45,
              "to_world": T().look_at(origin=[0, 1, 5], target=[0, 0.6, 0], up=[0, 1, 0]),
              "film": {"type": "hdrfilm", "width": res[0], "height": res[1], "rfilter": {"type": "box"}},
              "sampler": {"type": "independent"}}
    if sensor_medium is not None:
        sensor["medium"] = sensor_medium
    return {"type": "scene", "sensor": sensor,
            "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(4),
                      "bsdf": {"type": "diffuse", "reflectance": rgb(0.6, 0.5, 0.4)}}}


def overhead_light(radiance: float = 4.0) -> dict:
    return {"type": "rectangle", "to_world": T().translate([0, 3, 0]).rotate([1, 0, 0], 90),
            "emitter": {"type": "area", "radiance": rgb(radiance)}}


def environment(radiance: float) -> dict:
    return {"type": "constant", "radiance": rgb(radiance)}


def smoke_grid(n: int = 8) -> mi.VolumeGrid:
    """A sparse plume: density 0 in most cells, up to 3.6 in a ball at the centre."""
    x = np.linspace(-1, 1, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    density = np.clip(1.2 - np.sqrt(X ** 2 + Y ** 2 + Z ** 2), 0, None) * 3.0
    density[density < 0.5] = 0.0
    return mi.VolumeGrid(density.astype(np.float32)[..., None])


def fog_box(albedo: float = 0.8, sigma_t: float = 1.0) -> dict:
    """A cube of homogeneous fog behind an index-matched (null) boundary, under an area light."""
    scene = base()
    scene["box"] = {"type": "cube", "to_world": T().translate([0, 0.6, 0]).scale(0.6), "bsdf": {"type": "null"},
                    "interior": {"type": "homogeneous", "albedo": albedo, "sigma_t": sigma_t}}
    scene["light"] = overhead_light()
    return scene


def fog_box_lifted(albedo: float = 0.8, sigma_t: float = 2.5, res=(16, 12)) -> dict:
    """``fog_box`` lifted 0.1 off the floor (no null face on the floor's plane, where the ray tracer
    breaks the tie between the two surfaces either way: the reference is then the scene's)."""
    scene = fog_box(albedo, sigma_t)
    scene["box"]["to_world"] = T().translate([0, 0.7, 0]).scale(0.6)
    scene["sensor"]["film"].update(width=res[0], height=res[1])
    return scene


def point_in_fog() -> dict:
    """The camera and a point light inside one forward-scattering fog (HG g = 0.5) that fills a
    large null sphere; a card under the light casts a shadow through the fog."""
    scene = base(sensor_medium={"type": "ref", "id": "fog"})
    scene["fog"] = {"type": "homogeneous", "albedo": 0.9, "sigma_t": 0.15, "id": "fog",
                    "phase": {"type": "hg", "g": 0.5}}
    scene["room"] = {"type": "sphere", "radius": 8, "bsdf": {"type": "null"}, "interior": {"type": "ref", "id": "fog"}}
    scene["light"] = {"type": "point", "position": [0.3, 1.5, 0.5], "intensity": rgb(6)}
    scene["card"] = {"type": "rectangle", "to_world": T().translate([0.3, 1.2, 0.5]).rotate([1, 0, 0], 90).scale(0.3),
                     "bsdf": {"type": "diffuse"}}
    return scene


def chromatic_in_glass() -> dict:
    """A glass ball filled with a chromatic medium (sigma_t 0.5 / 2 / 5 per channel), under an
    area light and a dim constant environment."""
    scene = base()
    scene["ball"] = {"type": "sphere", "center": [0, 0.7, 0], "radius": 0.7, "bsdf": {"type": "dielectric", "int_ior": 1.5},
                     "interior": {"type": "homogeneous", "albedo": rgb(0.9, 0.8, 0.95), "sigma_t": rgb(0.1, 0.4, 1.0),
                                  "scale": 5.0}}
    scene["light"] = {"type": "rectangle", "to_world": T().translate([1, 3, 1]).rotate([1, 0, 0], 90),
                      "emitter": {"type": "area", "radiance": rgb(5)}}
    scene["environment"] = {"type": "constant", "radiance": rgb(0.2)}
    return scene


def smoke(albedo=0.9) -> dict:
    """Heterogeneous smoke (``smoke_grid``) in a null box under a sky-blue environment, a spot
    light, and a card of a ``mask``ed red diffuse (opacity 0.4) beside it."""
    scene = base()
    scene["box"] = {"type": "cube", "to_world": T().translate([0, 0.8, 0]).scale(0.8), "bsdf": {"type": "null"},
                    "interior": {"type": "heterogeneous", "albedo": albedo, "scale": 2.0,
                                 "sigma_t": {"type": "gridvolume", "grid": smoke_grid(),
                                             "to_world": T().translate([-0.8, 0, -0.8]).scale(1.6)}}}
    scene["environment"] = {"type": "constant", "radiance": rgb(0.8, 0.9, 1.0)}
    scene["card"] = {"type": "rectangle", "to_world": T().translate([1.3, 0.6, 0]).rotate([0, 1, 0], -60).scale(0.5),
                     "bsdf": {"type": "mask", "opacity": 0.4, "bsdf": {"type": "diffuse", "reflectance": rgb(0.8, 0.2, 0.2)}}}
    scene["spot"] = {"type": "spot", "to_world": T().look_at(origin=[2, 3, 1], target=[0, 0.5, 0], up=[0, 1, 0]),
                     "intensity": rgb(20), "cutoff_angle": 30}
    return scene


def chromatic_smoke() -> dict:
    """``smoke`` with a chromatic albedo, lit by the area light only."""
    scene = smoke(albedo=rgb(0.95, 0.7, 0.5))
    del scene["environment"], scene["card"], scene["spot"]
    scene["light"] = overhead_light(5.0)
    return scene


def uneven_fog_grid(n: int = 8) -> mi.VolumeGrid:
    """Thin fog thickening from 0.1 at the bottom to 0.4 at the top, a clear pocket (0) around
    one lower corner and a dense knot (4) in an upper one."""
    x = np.linspace(0, 1, n)
    Z, Y, X = np.meshgrid(x, x, x, indexing="ij")            # the grid's [z, y, x] order
    density = 0.1 + 0.3 * Y
    density[(X - 1) ** 2 + Y ** 2 + Z ** 2 < 0.5] = 0.0
    density[(X < 0.2) & (Y > 0.8) & (Z < 0.2)] = 4.0
    return mi.VolumeGrid(density.astype(np.float32)[..., None])


def point_in_smoke(albedo: float = 0.3) -> dict:
    """A point light inside a null box of uneven, smoky (albedo 0.3) heterogeneous fog
    (``uneven_fog_grid``, HG g = 0.3), seen from outside: a lantern in smoke, with no floor, so
    that the medium is all there is to see (its single scattering most of the image: a test on it
    sees an error in equi-angular sampling)."""
    scene = base()
    del scene["floor"]
    scene["box"] = {"type": "cube", "to_world": T().translate([0, 0.8, 0]).scale(0.8), "bsdf": {"type": "null"},
                    "interior": {"type": "heterogeneous", "albedo": albedo, "scale": 1.0,
                                 "phase": {"type": "hg", "g": 0.3},
                                 "sigma_t": {"type": "gridvolume", "grid": uneven_fog_grid(),
                                             "to_world": T().translate([-0.8, 0, -0.8]).scale(1.6)}}}
    scene["light"] = {"type": "point", "position": [-0.2, 0.9, 0.2], "intensity": rgb(3)}
    return scene


def spot_into_smoke() -> dict:
    """``smoke`` without its masked card, its box lifted 0.05 off the floor (standing on it, the
    smoke's light tracing differs on the floor, issue 46): the spot light and the environment
    through the plume."""
    scene = smoke()
    del scene["card"]
    scene["box"]["to_world"] = T().translate([0, 0.85, 0]).scale(0.8)
    scene["box"]["interior"]["sigma_t"]["to_world"] = T().translate([-0.8, 0.05, -0.8]).scale(1.6)
    return scene


def smoke_sunk() -> dict:
    """``smoke`` with its box sunk 0.05 into the floor (the fog above the floor unchanged): the box
    standing on the floor without a null face on the floor's plane, where the ray tracer breaks the
    tie between the two surfaces either way, so that light leaks through the floor (both ways)."""
    scene = smoke()
    scene["box"]["to_world"] = T().translate([0, 0.775, 0]).scale([0.8, 0.825, 0.8])
    return scene


def fog_on_floor() -> dict:
    """``smoke`` with homogeneous fog (sigma_t 1.5, albedo 0.9) in its box, which stands on the
    floor (its null bottom face on the floor's plane), with the masked card."""
    scene = smoke()
    scene["box"]["interior"] = {"type": "homogeneous", "albedo": 0.9, "sigma_t": 1.5}
    return scene


def fog_on_floor_sunk() -> dict:
    """``fog_on_floor`` with its box sunk 0.05 into the floor (no null face on the floor's plane)."""
    scene = fog_on_floor()
    scene["box"]["to_world"] = smoke_sunk()["box"]["to_world"]
    return scene


def point_in_plume() -> dict:
    """``smoke`` lit by a point light inside the plume's box, off its dense core, and a dim
    environment."""
    scene = spot_into_smoke()
    del scene["spot"]
    scene["environment"]["radiance"] = rgb(0.1)
    scene["light"] = {"type": "point", "position": [0.45, 1.2, 0.4], "intensity": rgb(3)}
    return scene


def masked_card_in_fog() -> dict:
    """A ``mask``ed red diffuse card (opacity 0.4) inside a null box of thin homogeneous fog (lifted
    off the floor), lit by a point light outside it: a 16x12 film."""
    scene = base(res=(16, 12))
    scene["box"] = {"type": "cube", "to_world": T().translate([0, 0.8, 0]).scale(0.7), "bsdf": {"type": "null"},
                    "interior": {"type": "homogeneous", "albedo": 0.8, "sigma_t": 0.3}}
    scene["card"] = {"type": "rectangle", "to_world": T().translate([0, 0.7, 0]).rotate([1, 0, 0], 30).scale(0.5),
                     "bsdf": {"type": "mask", "opacity": 0.4,
                              "bsdf": {"type": "diffuse", "reflectance": rgb(0.8, 0.2, 0.2)}}}
    scene["light"] = {"type": "point", "position": [0.3, 2.5, 2.0], "intensity": rgb(10)}
    return scene


def lamp_in_housing() -> dict:
    """A point light in a lamp housing of clear air (black walls that name no medium, a null window
    towards the camera whose outside is the fog) inside ``fog_box``'s null cube of fog (sigma_t
    2, albedo 0.9), no other light: a 16x12 film. Five in six of the light's rays meet a black
    wall first, behind which lies the fog cube's boundary."""
    scene = base(res=(16, 12))
    scene["fog"] = {"type": "homogeneous", "albedo": 0.9, "sigma_t": 2.0, "id": "fog"}
    fog = {"type": "ref", "id": "fog"}
    scene["box"] = {"type": "cube", "to_world": T().translate([0, 0.8, 0]).scale(0.8), "bsdf": {"type": "null"},
                    "interior": fog}
    centre, h = [0, 0.8, 0], 0.25
    walls = {"back": T().rotate([0, 1, 0], 180), "left": T().rotate([0, 1, 0], -90),
             "right": T().rotate([0, 1, 0], 90), "top": T().rotate([1, 0, 0], -90),
             "bottom": T().rotate([1, 0, 0], 90), "window": T()}
    for name, turn in walls.items():
        scene["housing_" + name] = {"type": "rectangle", "to_world": T().translate(centre) @ turn @ T().translate([0, 0, h]).scale(h),
                                    "bsdf": {"type": "diffuse", "reflectance": rgb(0)}}
    scene["housing_window"].update(bsdf={"type": "null"}, exterior=fog)
    scene["light"] = {"type": "point", "position": centre, "intensity": rgb(5)}
    return scene


SCENES = {"fog_box": fog_box, "point_in_fog": point_in_fog, "chromatic_in_glass": chromatic_in_glass,
          "smoke": smoke, "chromatic_smoke": chromatic_smoke, "point_in_smoke": point_in_smoke,
          "spot_into_smoke": spot_into_smoke, "point_in_plume": point_in_plume,
          "masked_card_in_fog": masked_card_in_fog, "smoke_sunk": smoke_sunk,
          "fog_on_floor": fog_on_floor, "fog_on_floor_sunk": fog_on_floor_sunk}


def fog_box_point() -> dict:
    """``fog_box`` lit by a point light above it instead of the area light."""
    scene = fog_box()
    scene["light"] = {"type": "point", "position": [0.3, 2.0, 0.5], "intensity": rgb(10)}
    return scene


def fog_box_sky() -> dict:
    """``fog_box_point`` under a dim constant sky and a low sun (``directional``) as well: lights
    at infinity beside a point light, which equi-angular sampling cannot aim at."""
    scene = fog_box_point()
    scene["sky"] = environment(0.3)
    scene["sun"] = {"type": "directional", "direction": [-0.6, -1.0, -0.4], "irradiance": rgb(1.5)}
    return scene



def sky_in_unbounded_fog() -> dict:
    """The sensor's fog (sigma_t 0.5, albedo 0.8) and nothing that bounds it, under a constant
    sky and a sun (``directional``): both at infinity, so inside the fog, infinitely far from
    them, none of their light arrives (the image is black). A 16x12 film."""
    scene = base(sensor_medium={"type": "homogeneous", "sigma_t": 0.5, "albedo": 0.8}, res=(16, 12))
    scene["sky"] = environment(1.0)
    scene["sun"] = {"type": "directional", "direction": [-0.6, -1.0, -0.4], "irradiance": rgb(1.5)}
    return scene


def _sky_smoke_medium() -> dict:
    return {"type": "heterogeneous", "albedo": 0.8,
            "sigma_t": {"type": "gridvolume", "grid": smoke_grid(), "to_world": T().translate([-1.0, 0.001, -1.0]).scale(2.0)}}


def sky_in_unbounded_smoke() -> dict:
    """The sensor's medium heterogeneous smoke (``smoke_grid`` over a 2-unit box on the floor) and
    nothing that bounds it, under a constant sky: a heterogeneous medium is empty outside its grid,
    so the sky is seen and lights the floor through it. A 16x12 film."""
    scene = base(sensor_medium=_sky_smoke_medium(), res=(16, 12))
    scene["sky"] = environment(1.0)
    return scene


def sky_in_unbounded_smoke_twin() -> dict:
    """``sky_in_unbounded_smoke`` written with a null box around the grid instead (the sensor in no
    medium): the same light transport, which Mitsuba's ``volpath`` renders (it ends every ray that
    leaves the scene inside a medium, so it cannot render the unbounded form)."""
    scene = base(res=(16, 12))
    scene["sky"] = environment(1.0)
    scene["box"] = {"type": "cube", "to_world": T().translate([0, 1.001, 0]).scale(1.0), "bsdf": {"type": "null"},
                    "interior": _sky_smoke_medium()}
    return scene
