"""Scenes written the way users write them: XML files next to their own meshes and textures.

``write_assets(folder)`` writes the assets once (variant-free files): an OBJ sphere with
vertex normals and texture coordinates, a PLY box, PNG textures (albedo checker, blend
weights, a normal map), EXR textures (an area light's radiance, a bump height field, an
environment map). ``scene_path(folder, name, sampler, ...)`` writes one scene's XML (the
sampler is part of the sensor, as users write it) and returns its path; load it with
``mi.load_file`` *after* any variant switch.

Every scene is small (at most 48 x 32 pixels) and combines several features; ``SCENES`` says
which. Emitters are broad and lobes moderately rough, so that every unbiased estimator has
a tame (not heavy-tailed) error at a few samples per pixel. Some shapes carry ids
(``shape_mask`` finds their pixels).

The textured light's EXR holds radiance up to 10, as users write HDR lights: Mitsuba warns
that the bitmap exceeds [0, 1], and under spectral variants its upsampling makes that light
several times dimmer than under RGB (textured_mesh_room's image mean: 0.024 vs 0.158). That
is Mitsuba's behaviour, the same for `path` and the lab's estimators.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class UserScene:
    """One scene: its film, crop window, path length, sensor, features and XML body."""
    film: tuple[int, int]
    crop: tuple[int, int, int, int] | None     # (x, y, width, height) or None
    max_depth: int
    sensor: str                                # perspective, thinlens or orthographic
    rfilter: str
    features: str
    body: Callable[[], str]

    @property
    def block(self) -> tuple[int, int]:
        """(width, height) of the rendered pixel block: the crop window, else the film."""
        return (self.crop[2], self.crop[3]) if self.crop else self.film


#: name -> UserScene, in the order the scenes are defined below.
SCENES: dict[str, UserScene] = {}


def _scene(film, crop=None, max_depth=5, sensor="perspective", rfilter="gaussian", features=""):
    def register(body):
        SCENES[body.__name__] = UserScene(film, crop, max_depth, sensor, rfilter, features, body)
        return body
    return register


# ---------------------------------------------------------------------------- meshes
def sphere_obj(path: str, rings: int = 10, segments: int = 20) -> None:
    """A unit UV sphere: positions, outward vertex normals, (u, v) coordinates, triangles."""
    lines = ["# unit sphere written by tests/user_scenes.py"]
    for i in range(rings + 1):
        theta = math.pi * i / rings
        for j in range(segments + 1):
            phi = 2 * math.pi * j / segments
            n = (math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi))
            lines.append("v %.6f %.6f %.6f" % n)
            lines.append("vn %.6f %.6f %.6f" % n)
            lines.append("vt %.6f %.6f" % (j / segments, 1 - i / rings))
    row = segments + 1
    for i in range(rings):
        for j in range(segments):
            a, b, c, d = i * row + j + 1, i * row + j + 2, (i + 1) * row + j + 1, (i + 1) * row + j + 2
            if i != 0:                           # the top ring's first triangle is degenerate
                lines.append(f"f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")
            if i != rings - 1:                   # so is the bottom ring's second
                lines.append(f"f {b}/{b}/{b} {d}/{d}/{d} {c}/{c}/{c}")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def box_ply(path: str) -> None:
    """The cube [-1, 1]^3 as a binary PLY: 4 vertices per face (flat normals, uv), 12 triangles."""
    vertices, faces = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
            base = len(vertices)
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis], p[u_axis], p[v_axis] = sign, du, dv
                n = [0.0, 0.0, 0.0]
                n[axis] = sign
                vertices.append(p + n + [(du + 1) / 2, (dv + 1) / 2])
            quad = [(0, 1, 2), (0, 2, 3)] if sign > 0 else [(0, 2, 1), (0, 3, 2)]
            faces += [[base + k for k in tri] for tri in quad]
    header = ("ply\nformat binary_little_endian 1.0\ncomment box written by tests/user_scenes.py\n"
              f"element vertex {len(vertices)}\n"
              + "".join(f"property float {p}\n" for p in ("x", "y", "z", "nx", "ny", "nz", "u", "v"))
              + f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    face_dtype = np.dtype([("n", "u1"), ("i", "<i4", 3)])
    face_rows = np.array([(3, tri) for tri in faces], dtype=face_dtype)
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.asarray(vertices, dtype="<f4").tobytes())
        f.write(face_rows.tobytes())


# ---------------------------------------------------------------------------- textures
def _write_bitmap(path: str, array: np.ndarray) -> None:
    import mitsuba as mi

    mi.Bitmap(array).write(path)


def write_assets(folder: str) -> str:
    """Write every mesh and texture the scenes use into ``folder``; returns it."""
    os.makedirs(folder, exist_ok=True)
    sphere_obj(os.path.join(folder, "sphere.obj"))
    box_ply(os.path.join(folder, "box.ply"))
    y, x = np.mgrid[0:64, 0:64] / 64.0
    checker = ((np.floor(x * 8) + np.floor(y * 8)) % 2)[..., None]
    albedo = (checker * [200, 60, 40] + (1 - checker) * [230, 220, 190]).astype(np.uint8)
    _write_bitmap(os.path.join(folder, "albedo.png"), albedo)
    stripes = (0.5 + 0.45 * np.sin(2 * math.pi * 3 * x))[..., None]
    _write_bitmap(os.path.join(folder, "blend.png"), (stripes * 255).astype(np.uint8))
    # Normal map from the height field h = 0.05 sin(2 pi 4 x) sin(2 pi 4 y): n ~ (-h_x, -h_y, 1)
    hx = 0.05 * 8 * math.pi * np.cos(8 * math.pi * x) * np.sin(8 * math.pi * y)
    hy = 0.05 * 8 * math.pi * np.sin(8 * math.pi * x) * np.cos(8 * math.pi * y)
    n = np.stack([-hx, -hy, np.ones_like(hx)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    _write_bitmap(os.path.join(folder, "normals.png"), np.round((n + 1) / 2 * 255).astype(np.uint8))
    height = (0.5 + 0.5 * np.sin(2 * math.pi * 5 * x) * np.cos(2 * math.pi * 3 * y)).astype(np.float32)
    _write_bitmap(os.path.join(folder, "height.exr"), height[..., None])
    ly, lx = np.mgrid[0:16, 0:16] / 16.0
    radiance = np.stack([6 + 4 * lx, 5 + 2 * ly, 3 + 3 * (1 - lx)], axis=-1).astype(np.float32)
    _write_bitmap(os.path.join(folder, "light.exr"), radiance)
    # Environment: a sky gradient and a broad warm glow (peak ~4x the sky: NEE and BSDF
    # sampling both stay tame)
    ey, ex = (np.mgrid[0:16, 0:32] + 0.5) / np.array([16.0, 32.0])[:, None, None]
    glow = 3.0 * np.exp(-((ex - 0.3) ** 2 + (ey - 0.3) ** 2) / 0.02)
    sky = np.stack([0.4 + 0.3 * (1 - ey) + glow, 0.5 + 0.3 * (1 - ey) + 0.8 * glow,
                    0.7 + 0.4 * (1 - ey) + 0.5 * glow], axis=-1).astype(np.float32)
    _write_bitmap(os.path.join(folder, "sky.exr"), sky)
    return folder


# ---------------------------------------------------------------------------- XML pieces
def _rgb(name, v):
    return f'<rgb name="{name}" value="{v}"/>'


def _sampler(sampler: str, spp: int, params: dict | None) -> str:
    extra = "".join(f'<integer name="{k}" value="{v}"/>' for k, v in (params or {}).items())
    return f'<sampler type="{sampler}"><integer name="sample_count" value="{spp}"/>{extra}</sampler>'


def _film(size, crop, rfilter="gaussian") -> str:
    text = f'<film type="hdrfilm"><integer name="width" value="{size[0]}"/>' \
           f'<integer name="height" value="{size[1]}"/><rfilter type="{rfilter}"/>'
    if crop:
        for key, value in zip(("crop_offset_x", "crop_offset_y", "crop_width", "crop_height"), crop):
            text += f'<integer name="{key}" value="{value}"/>'
    return text + "</film>"


def _diffuse(value="0.6 0.6 0.6", twosided=True) -> str:
    bsdf = f'<bsdf type="diffuse">{_rgb("reflectance", value)}</bsdf>'
    return f'<bsdf type="twosided">{bsdf}</bsdf>' if twosided else bsdf


def _rect(transform: str, bsdf: str, extra: str = "") -> str:
    return f'<shape type="rectangle"><transform name="to_world">{transform}</transform>{bsdf}{extra}</shape>'


def _mesh(kind: str, transform: str, bsdf: str, extra: str = "", shape_id: str = "") -> str:
    filename = "sphere.obj" if kind == "obj" else "box.ply"
    ident = f' id="{shape_id}"' if shape_id else ""
    return (f'<shape type="{kind}"{ident}><string name="filename" value="{filename}"/>'
            f'<transform name="to_world">{transform}</transform>{bsdf}{extra}</shape>')


def _textured_area() -> str:
    return ('<emitter type="area"><texture name="radiance" type="bitmap">'
            '<string name="filename" value="light.exr"/></texture></emitter>')


_ROOM = (  # floor, back wall, ceiling with a textured light panel: open to the camera side
    _rect('<scale value="3"/><rotate x="1" angle="-90"/>', _diffuse("0.55 0.55 0.5"))
    + _rect('<scale value="3"/><translate z="-2.5" y="2.5"/>', _diffuse("0.4 0.5 0.6"))
    + _rect('<scale value="3"/><rotate x="1" angle="90"/><translate y="4"/>', _diffuse("0.7 0.7 0.7"))
    + _rect('<scale x="1.2" y="0.8" z="1"/><rotate x="1" angle="90"/><translate y="3.95" z="-0.5"/>',
            '<bsdf type="diffuse"/>', _textured_area()))


_ROUGH_GOLD = '<bsdf type="roughconductor"><string name="material" value="Au"/><float name="alpha" value="0.3"/></bsdf>'
_CHECKER = '<texture name="reflectance" type="bitmap"><string name="filename" value="albedo.png"/></texture>'


@_scene((48, 32), features="OBJ sphere with a PNG albedo, PLY box (roughconductor), textured area "
                           "light (EXR radiance), room of twosided diffuse walls, non-square film")
def textured_mesh_room() -> str:
    return (_ROOM
            + _mesh("obj", '<scale value="0.8"/><translate x="-0.7" y="0.8" z="-0.6"/>',
                    f'<bsdf type="diffuse">{_CHECKER}</bsdf>')
            + _mesh("ply", '<scale value="0.5"/><rotate y="1" angle="30"/><translate x="0.9" y="0.5" z="-0.3"/>',
                    _ROUGH_GOLD, shape_id="gold_box"))


@_scene((40, 40), features="principled with a clear coat (OBJ), blendbsdf weighted by a PNG, smooth "
                           "plastic box (PLY: delta + smooth lobes), area light + constant environment")
def principled_and_blend() -> str:
    blend = ('<bsdf type="blendbsdf"><texture name="weight" type="bitmap"><string name="filename" '
             'value="blend.png"/><boolean name="raw" value="true"/></texture>'
             f'{_diffuse("0.7 0.3 0.2", twosided=False)}<bsdf type="roughconductor">'
             '<float name="alpha" value="0.25"/></bsdf></bsdf>')
    principled = ('<bsdf type="principled">' + _rgb("base_color", "0.2 0.4 0.8")
                  + '<float name="roughness" value="0.4"/><float name="metallic" value="0.2"/>'
                  '<float name="clearcoat" value="0.7"/><float name="clearcoat_gloss" value="0.5"/>'
                  '<float name="specular" value="0.5"/></bsdf>')
    plastic = ('<bsdf type="plastic">' + _rgb("diffuse_reflectance", "0.3 0.6 0.3")
               + '<float name="int_ior" value="1.5"/></bsdf>')
    return (_rect('<scale value="3"/><rotate x="1" angle="-90"/>', blend)
            + _rect('<scale value="3"/><translate z="-2" y="2"/>', _diffuse("0.5 0.5 0.5"))
            + _mesh("obj", '<scale value="0.7"/><translate x="-0.8" y="0.7"/>', principled)
            + _mesh("ply", '<scale value="0.45"/><rotate y="1" angle="-25"/><translate x="0.8" y="0.45" z="0.2"/>',
                    plastic, shape_id="plastic_box")
            + _rect('<scale value="1"/><rotate x="1" angle="90"/><translate y="3"/>',
                    '<bsdf type="diffuse"/>', f'<emitter type="area">{_rgb("radiance", "6 6 5")}</emitter>')
            + f'<emitter type="constant">{_rgb("radiance", "0.3 0.35 0.4")}</emitter>')


@_scene((40, 24), crop=(4, 2, 32, 20), rfilter="box",
        features="spot + directional + point lights only, roughdielectric PLY box, roughconductor "
                 "OBJ sphere, PNG-textured floor, non-square film with a non-square crop window")
def spot_and_directional() -> str:
    return (_rect('<scale value="4"/><rotate x="1" angle="-90"/>',
                  f'<bsdf type="twosided"><bsdf type="diffuse">{_CHECKER}</bsdf></bsdf>')
            + _rect('<scale value="4"/><translate z="-2" y="2"/>', _diffuse("0.5 0.55 0.6"))
            + _mesh("obj", '<scale value="0.6"/><translate x="-0.7" y="0.6"/>',
                    '<bsdf type="roughconductor"><string name="material" value="Cu"/>'
                    '<float name="alpha" value="0.35"/></bsdf>')
            + _mesh("ply", '<scale value="0.45"/><rotate y="1" angle="20"/><translate x="0.8" y="0.45" z="0.3"/>',
                    '<bsdf type="roughdielectric"><float name="alpha" value="0.3"/>'
                    '<string name="distribution" value="ggx"/></bsdf>')
            + '<emitter type="spot"><transform name="to_world"><lookat origin="1.5, 3, 1.5" '
              'target="0, 0, 0" up="0, 1, 0"/></transform>' + _rgb("intensity", "30 28 24")
            + '<float name="cutoff_angle" value="35"/><float name="beam_width" value="25"/></emitter>'
            + '<emitter type="directional"><vector name="direction" x="0.4" y="-1" z="-0.3"/>'
            + _rgb("irradiance", "0.8 0.85 1.0") + '</emitter>'
            + '<emitter type="point"><point name="position" x="-1.5" y="1.5" z="1.2"/>'
            + _rgb("intensity", "3 3 4") + '</emitter>')


@_scene((48, 32), sensor="orthographic", rfilter="box",
        features="shapegroup (OBJ sphere + PLY box) instanced 4 times, orthographic sensor, area "
                 "light + constant environment, non-square film")
def instanced_ortho() -> str:
    group = ('<shape type="shapegroup" id="pair">'
             + _mesh("obj", '<scale value="0.35"/><translate y="0.35"/>', _diffuse("0.7 0.5 0.3", False))
             + _mesh("ply", '<scale value="0.25"/><translate x="0.55" y="0.25"/>',
                     '<bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf>')
             + '</shape>')
    instances = "".join(
        f'<shape type="instance"><ref id="pair"/><transform name="to_world">'
        f'<rotate y="1" angle="{a}"/><translate x="{x}" z="{z}"/></transform></shape>'
        for a, x, z in ((0, -1.2, -0.6), (40, 0.2, -0.9), (90, -0.4, 0.7), (150, 1.1, 0.4)))
    return (group + instances
            + _rect('<scale value="3"/><rotate x="1" angle="-90"/>', _diffuse("0.6 0.6 0.6"))
            # the camera sees the panel's back: twosided, so that it is lit, not a black hole
            + _rect('<scale value="1.2"/><rotate x="1" angle="90"/><translate y="2.5"/>',
                    _diffuse("0.8 0.8 0.8"), f'<emitter type="area">{_rgb("radiance", "5 5 5")}</emitter>')
            + f'<emitter type="constant">{_rgb("radiance", "0.4 0.4 0.45")}</emitter>')


@_scene((32, 32), sensor="thinlens",
        features="thin-lens sensor, EXR environment map, roughdielectric OBJ sphere, twosided "
                 "roughconductor PLY box, principled floor, square film")
def thinlens_envmap() -> str:
    return (_rect('<scale value="4"/><rotate x="1" angle="-90"/>',
                  '<bsdf type="principled">' + _rgb("base_color", "0.6 0.6 0.55")
                  + '<float name="roughness" value="0.6"/></bsdf>')
            + _mesh("obj", '<scale value="0.7"/><translate y="0.7"/>',
                    '<bsdf type="roughdielectric"><float name="alpha" value="0.3"/></bsdf>')
            + _mesh("ply", '<scale value="0.4"/><rotate y="1" angle="35"/><translate x="1.3" y="0.4" z="-1"/>',
                    '<bsdf type="twosided"><bsdf type="roughconductor"><float name="alpha" value="0.4"/>'
                    '</bsdf></bsdf>')
            + '<emitter type="envmap"><string name="filename" value="sky.exr"/></emitter>')


@_scene((32, 32), features="normalmap (PNG) over roughplastic on a wall and an OBJ sphere, bumpmap "
                           "(EXR height) over diffuse on the floor, point light + area light")
def normal_bump_maps() -> str:
    normal = ('<bsdf type="normalmap"><texture name="normalmap" type="bitmap"><boolean name="raw" '
              'value="true"/><string name="filename" value="normals.png"/></texture>'
              '<bsdf type="roughplastic">' + _rgb("diffuse_reflectance", "0.2 0.3 0.7")
              + '<float name="alpha" value="0.2"/></bsdf></bsdf>')
    bump = ('<bsdf type="bumpmap"><texture name="arbitrary" type="bitmap"><boolean name="raw" '
            'value="true"/><string name="filename" value="height.exr"/></texture>'
            '<float name="scale" value="0.5"/>' + _diffuse("0.7 0.6 0.5", twosided=False) + '</bsdf>')
    return (_rect('<scale value="3"/><rotate x="1" angle="-90"/>', bump)
            + _rect('<scale value="3"/><translate z="-1.5" y="2"/>', normal)
            + _mesh("obj", '<scale value="0.6"/><translate x="0.3" y="0.6" z="0.2"/>', normal)
            + _rect('<scale value="0.8"/><rotate x="1" angle="90"/><translate y="3"/>',
                    '<bsdf type="diffuse"/>', f'<emitter type="area">{_rgb("radiance", "5 5 5")}</emitter>')
            + '<emitter type="point"><point name="position" x="-1.2" y="1.8" z="1.5"/>'
            + _rgb("intensity", "4 4 3.5") + '</emitter>')


@_scene((40, 24), crop=(8, 0, 24, 24), sensor="thinlens",
        features="spot + textured area light + constant environment, twosided roughplastic PLY box, "
                 "blendbsdf (roughdielectric / diffuse) OBJ sphere, thin lens, square crop of a wide film")
def mixed_lights_crop() -> str:
    blend = ('<bsdf type="blendbsdf"><float name="weight" value="0.4"/>'
             '<bsdf type="roughdielectric"><float name="alpha" value="0.25"/></bsdf>'
             + _diffuse("0.8 0.7 0.3", twosided=False) + '</bsdf>')
    return (_ROOM
            + _mesh("ply", '<scale value="0.5"/><rotate y="1" angle="-30"/><translate x="0.8" y="0.5" z="-0.4"/>',
                    '<bsdf type="twosided"><bsdf type="roughplastic"><float name="alpha" value="0.3"/>'
                    + _rgb("diffuse_reflectance", "0.6 0.2 0.2") + '</bsdf></bsdf>', shape_id="red_box")
            + _mesh("obj", '<scale value="0.6"/><translate x="-0.6" y="0.6"/>', blend)
            + '<emitter type="spot"><transform name="to_world"><lookat origin="-1.5, 2.5, 1.5" '
              'target="0, 0.5, -0.5" up="0, 1, 0"/></transform>' + _rgb("intensity", "15 15 12")
            + '<float name="cutoff_angle" value="30"/></emitter>'
            + f'<emitter type="constant">{_rgb("radiance", "0.2 0.2 0.25")}</emitter>')


# ---------------------------------------------------------------------------- whole scenes
_LOOK = '<lookat origin="0, 1.6, 5" target="0, 0.8, 0" up="0, 1, 0"/>'


def _sensor(spec: UserScene, sampler_xml: str) -> str:
    film = _film(spec.film, spec.crop, spec.rfilter)
    if spec.sensor == "orthographic":      # a 4.8 x 4.8 view from above, at 45 degrees
        return (f'<sensor type="orthographic"><transform name="to_world"><scale x="2.4" y="2.4" z="1"/>'
                f'<lookat origin="0, 4, 4" target="0, 0.3, 0" up="0, 1, 0"/></transform>'
                f'{sampler_xml}{film}</sensor>')
    lens = ('<float name="aperture_radius" value="0.08"/><float name="focus_distance" value="5"/>'
            if spec.sensor == "thinlens" else "")
    return (f'<sensor type="{spec.sensor}"><float name="fov" value="45"/>{lens}'
            f'<transform name="to_world">{_LOOK}</transform>{sampler_xml}{film}</sensor>')


def scene_xml(name: str, sampler: str = "independent", spp: int = 4,
              sampler_params: dict | None = None) -> str:
    """The scene's XML text, with a ``path`` integrator of the scene's max_depth (for users;
    the tests pass their own integrator)."""
    if name not in SCENES:
        raise ValueError(f"unknown user scene '{name}'; known: {', '.join(SCENES)}")
    spec = SCENES[name]
    return (f'<scene version="3.0.0"><integrator type="path"><integer name="max_depth" '
            f'value="{spec.max_depth}"/></integrator>{spec.body()}'
            f'{_sensor(spec, _sampler(sampler, spp, sampler_params))}</scene>\n')


def scene_path(folder: str, name: str, sampler: str = "independent", spp: int = 4,
               sampler_params: dict | None = None) -> str:
    """Write the scene's XML next to the assets in ``folder`` (from ``write_assets``)."""
    suffix = "_".join([sampler, str(spp)] + [f"{k}{v}" for k, v in sorted((sampler_params or {}).items())])
    path = os.path.join(folder, f"{name}__{suffix}.xml")
    with open(path, "w") as f:
        f.write(scene_xml(name, sampler, spp, sampler_params))
    return path


def load(folder: str, name: str, sampler: str = "independent", spp: int = 4,
         sampler_params: dict | None = None):
    """Load the scene under the current variant (call after any ``use_variant``)."""
    import mitsuba as mi

    return mi.load_file(scene_path(folder, name, sampler, spp, sampler_params))


def max_depth(name: str) -> int:
    return SCENES[name].max_depth


def shape_mask(scene, shape_id: str) -> np.ndarray:
    """(height, width) booleans of the rendered block: the camera ray through the pixel's
    centre (and the lens centre) first hits the shape with this id."""
    import drjit as dr
    import mitsuba as mi

    shapes = [s for s in scene.shapes() if s.id() == shape_id]
    if not shapes:
        raise ValueError(f"no shape with id '{shape_id}' in the scene")
    sensor = scene.sensors()[0]
    film = sensor.film()
    (width, height), (x0, y0), full = film.crop_size(), film.crop_offset(), film.size()
    index = dr.arange(mi.UInt32, int(width) * int(height))
    pixel = mi.Point2f(mi.Float(index % int(width)) + int(x0) + 0.5, mi.Float(index // int(width)) + int(y0) + 0.5)
    ray, _ = sensor.sample_ray(0.0, 0.5, pixel / mi.ScalarVector2f(full), mi.Point2f(0.5, 0.5))
    hit = scene.ray_intersect(ray).shape == mi.ShapePtr(shapes[0])
    return np.array(hit, dtype=bool).reshape(int(height), int(width))
