"""What a scene contains and needs, read from the loaded scene without rendering
(``SceneTraits``): the path tracers derive their kernel from it, the bidirectional integrators
their refusals, and the orchestration layer (``mitsuba_lab.scene``) which strategies apply."""
from __future__ import annotations

from dataclasses import dataclass

import mitsuba as mi


# ---------------------------------------------------------------------------
# SceneTraits: what a scene contains and needs
# ---------------------------------------------------------------------------
#: Emission factors in an emitter's parameters (``mi.traverse``): the emitted power is
#: a product of these, so one that is zero everywhere makes the emitter dark.
_EMISSION_FACTORS = ("radiance", "intensity", "irradiance", "texture")


#: Mitsuba class name -> plugin name of the delta emitters (for messages).
DELTA_EMITTER_PLUGINS = {"PointLight": "point", "SpotLight": "spot",
                         "DirectionalEmitter": "directional", "Projector": "projector"}


def emitter_kind(emitter) -> str:
    """'delta' (point, spot, directional, projector: no ray can hit it), 'area'
    (on a shape), 'environment' (at infinity, hit by escaping rays) or 'other'
    (anything else: treated as both hittable and sampleable)."""
    flags = int(emitter.flags())
    if flags & int(mi.EmitterFlags.Delta):
        return "delta"
    if flags & int(mi.EmitterFlags.Surface):
        return "area"
    if flags & int(mi.EmitterFlags.Infinite):
        return "environment"
    return "other"


def _bsdf_flags(shape) -> int | None:
    """The flags of the shape's BSDF, or None where it cannot be inspected (shape-group instances)."""
    bsdf = shape.bsdf() if shape.class_name() != "Instance" else None
    return None if bsdf is None else int(bsdf.flags())


def bsdf_has_smooth_component(shape) -> bool:
    """Whether the shape's BSDF has a non-delta lobe (a vertex NEE can connect from).

    Conservative: shapes whose BSDF cannot be inspected (instances of shape groups) count
    as smooth, so no code is ever left out that they might need.
    """
    flags = _bsdf_flags(shape)
    return flags is None or bool(flags & int(mi.BSDFFlags.Smooth))


def bsdf_mixes_delta_and_smooth(shape) -> bool:
    """Whether the shape's BSDF has both a delta lobe (delta reflection or transmission, or a
    null pass-through) and a smooth one: ``plastic``, a ``mask`` or ``blendbsdf`` over a smooth
    BSDF, ``twosided`` of such a BSDF, ``hair``. (Unknown for instances: False.)"""
    flags = _bsdf_flags(shape)
    return flags is not None and bool(flags & int(mi.BSDFFlags.Delta)) and bool(flags & int(mi.BSDFFlags.Smooth))


def bsdf_has_delta_component(shape) -> bool:
    """Whether the shape's BSDF has a delta lobe (mirror, glass, a null pass-through, the
    delta part of ``plastic``). Unknown for instances: True (conservative)."""
    flags = _bsdf_flags(shape)
    return flags is None or bool(flags & int(mi.BSDFFlags.Delta))


def bsdf_uses_tangents(shape) -> bool:
    """Whether the shape's BSDF depends on the surface's tangent directions, not only its
    normal: an anisotropic lobe, or a normal or bump map (which reads dp/du, dp/dv), nested or
    not. Unknown (instances): True (conservative)."""
    bsdf = shape.bsdf() if hasattr(shape, "bsdf") else None
    if bsdf is None:
        return not hasattr(shape, "bsdf")
    if mi.has_flag(bsdf.flags(), mi.BSDFFlags.Anisotropic) or bsdf.class_name() in ("NormalMap", "BumpMap"):
        return True
    parts = {part for key in mi.traverse(bsdf).keys() for part in key.split(".")}
    return bool(parts & {"normalmap", "nested_texture"})


def _all_zero(value) -> bool:
    try:
        import numpy as np

        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return array.size > 0 and bool(np.all(array == 0))


def _emits_nothing(emitter) -> bool:
    """True only when the emitter provably emits nothing: a zero emission factor
    (radiance, intensity, irradiance, texture, scale, bitmap data) or, for an area
    light, a shape of zero area. Unknown parametrisations count as emitting."""
    import numpy as np

    shape = emitter.get_shape()
    if shape is not None:
        area = float(np.asarray(shape.surface_area(), dtype=np.float64).ravel()[0])
        if not area > 0:
            return True
    params = mi.traverse(emitter)
    keys = list(params.keys())
    for key in keys:
        head, _, tail = key.partition(".")
        factor = (head in _EMISSION_FACTORS and tail in ("value", "data")) or key in ("scale", "data")
        # in spectral variants an RGB emission is a sigmoid-polynomial spectrum times D65: its
        # "value" holds coefficients, and all-zero coefficients mean a grey of 0.5, not zero
        factor &= not any(k.startswith(f"{head}.d65.") for k in keys)
        if factor and _all_zero(params[key]):
            return True
    return False


def _matrix(transform):
    import numpy as np

    m = np.array(transform.matrix, dtype=np.float64)
    return m.reshape(4, 4) if m.size == 16 else m[..., 0].reshape(4, 4)


def _far_clip_problems(scene, bbox_min, bbox_max) -> tuple[tuple[str, ...], float | None, float | None]:
    """Messages for sensors whose clip range misses part of the scene's geometry."""
    import itertools

    import numpy as np

    problems = []
    far = near = None
    if not all(np.isfinite(bbox_min + bbox_max)):
        return (), None, None
    corners = np.array(list(itertools.product(*zip(bbox_min, bbox_max))))
    for index, sensor in enumerate(scene.sensors()):
        if not hasattr(sensor, "far_clip"):
            continue
        far, near = float(sensor.far_clip()), float(sensor.near_clip())
        origin = _matrix(sensor.world_transform())[:3, 3]
        farthest = float(np.max(np.linalg.norm(corners - origin, axis=1)))
        nearest = float(np.linalg.norm(origin - np.clip(origin, bbox_min, bbox_max)))
        if farthest > far:
            problems.append(f"sensor {index}: geometry reaches {farthest:.4g} from the camera, beyond "
                            f"far_clip = {far:.4g}; camera rays silently miss what lies farther "
                            f"(set the sensor's far_clip above {farthest:.4g})")
        if nearest > 0 and near >= farthest:
            problems.append(f"sensor {index}: all geometry is nearer than near_clip = {near:.4g}")
    return tuple(problems), far, near


def _shape_name(shape, index: int) -> str:
    """A shape's id, else its BSDF's plugin class and index, for messages."""
    name = shape.id()
    if name and not name.startswith("_unnamed"):
        return name
    bsdf = shape.bsdf()
    return f"{bsdf.class_name() if bsdf is not None else shape.class_name()} on shape {index}"


def _media(scene: mi.Scene) -> list:
    """Every medium attached to a shape (inside or outside) or a sensor."""
    found = []
    for shape in scene.shapes():
        found += [m for m in (shape.interior_medium(), shape.exterior_medium()) if m is not None]
    found += [m for m in (getattr(s, "get_medium", lambda: None)() for s in scene.sensors()) if m is not None]
    return found


def _homogeneous(medium) -> bool:
    """The medium's coefficients are constant (Mitsuba's ``is_homogeneous``)."""
    flag = medium.is_homogeneous()
    return bool(flag[0]) if hasattr(flag, "__len__") else bool(flag)


@dataclass(frozen=True)
class SceneTraits:
    """What a scene contains, read from the loaded scene without rendering (cheap:
    one pass over its shapes, emitters and sensors).

    The path tracers derive from them which code their kernel needs
    (``plugins/integrators/path.KernelPlan``); the planner asks each lab integrator
    whether it applies (``strategy_applicability``) and which strategies are provably
    identical on the scene (``equivalent_strategies``).
    """
    area_emitters: int                 # emitters on shapes (rays can hit them)
    environment_emitters: int          # emitters at infinity hit by escaping rays (constant, envmap)
    delta_emitters: tuple[str, ...]    # plugin name of each delta emitter (point, spot, directional)
    other_emitters: int                # emitters of no known kind (treated as hittable)
    dark_emitters: tuple[str, ...]     # ids of emitters that emit nothing (zero radiance or area)
    smooth_bsdf: bool                  # some BSDF has a smooth (non-delta) component
    media: bool                        # a participating medium is attached to a shape or sensor
    bbox_min: tuple[float, float, float]
    bbox_max: tuple[float, float, float]
    far_clip: float | None             # of the last perspective-like sensor (None: no such sensor)
    near_clip: float | None
    far_clip_problems: tuple[str, ...]
    mixed_bsdfs: tuple[str, ...] = ()  # shapes whose BSDF mixes delta and smooth lobes (e.g. plastic)
    sensor_kinds: tuple[str, ...] = ()  # plugin class of each sensor (PerspectiveCamera, ThinLensCamera, ..)
    delta_bsdf: bool = False           # some BSDF has a delta lobe (mirror, glass, null, plastic's)
    tangent_bsdf: bool = True          # some BSDF depends on tangents (anisotropy, normal/bump maps)
    heterogeneous_media: bool = False  # some medium is not homogeneous (a grid volume)

    @staticmethod
    def from_scene(scene: mi.Scene) -> "SceneTraits":
        import numpy as np

        kinds, delta, dark = [], [], []
        for index, emitter in enumerate(scene.emitters()):
            kind = emitter_kind(emitter)
            kinds.append(kind)
            if kind == "delta":
                delta.append(DELTA_EMITTER_PLUGINS.get(emitter.class_name(), emitter.class_name()))
            if _emits_nothing(emitter):
                shape = emitter.get_shape()
                dark.append((shape.id() if shape is not None else "") or emitter.id() or f"emitter {index}")
        shapes = scene.shapes()
        media = any(s.interior_medium() is not None or s.exterior_medium() is not None for s in shapes)
        media = media or any(getattr(s, "get_medium", lambda: None)() is not None for s in scene.sensors())
        bbox = scene.bbox()
        lo = tuple(float(v) for v in np.array(bbox.min).ravel()) if shapes else (0.0, 0.0, 0.0)
        hi = tuple(float(v) for v in np.array(bbox.max).ravel()) if shapes else (0.0, 0.0, 0.0)
        problems, far, near = _far_clip_problems(scene, np.array(lo), np.array(hi))
        return SceneTraits(area_emitters=kinds.count("area"),
                           environment_emitters=kinds.count("environment"),
                           delta_emitters=tuple(delta), other_emitters=kinds.count("other"),
                           dark_emitters=tuple(dark),
                           smooth_bsdf=any(bsdf_has_smooth_component(s) for s in shapes),
                           media=media, bbox_min=lo, bbox_max=hi, far_clip=far, near_clip=near,
                           far_clip_problems=problems,
                           mixed_bsdfs=tuple(_shape_name(s, i) for i, s in enumerate(shapes)
                                             if bsdf_mixes_delta_and_smooth(s)),
                           sensor_kinds=tuple(sensor.class_name() for sensor in scene.sensors()),
                           delta_bsdf=any(bsdf_has_delta_component(s) for s in shapes),
                           tangent_bsdf=any(bsdf_uses_tangents(s) for s in shapes),
                           heterogeneous_media=any(not _homogeneous(m) for m in _media(scene)))

    # -- Derived facts ----------------------------------------------------------------
    @property
    def emitters(self) -> int:
        return self.area_emitters + self.environment_emitters + len(self.delta_emitters) + self.other_emitters

    @property
    def emitter_kinds(self) -> frozenset[str]:
        """Subset of {'area', 'delta', 'environment', 'other'}."""
        present = {"area": self.area_emitters, "environment": self.environment_emitters,
                   "delta": len(self.delta_emitters), "other": self.other_emitters}
        return frozenset(kind for kind, count in present.items() if count)

    @property
    def hittable_emitters(self) -> bool:
        """A ray can find emission (an area, environment or unknown emitter exists)."""
        return self.area_emitters + self.environment_emitters + self.other_emitters > 0

    @property
    def all_bsdfs_delta(self) -> bool:
        """Every BSDF is delta (mirror, glass, null): no vertex can use an emitter sample."""
        return not self.smooth_bsdf

    @property
    def emits_light(self) -> bool:
        """Some emitter emits (provably dark emitters do not count)."""
        return self.emitters > len(self.dark_emitters)

    @property
    def extent(self) -> float:
        """Length of the bounding box diagonal of the geometry (0 without shapes)."""
        return float(sum((b - a) ** 2 for a, b in zip(self.bbox_min, self.bbox_max)) ** 0.5)

    def warnings(self, media: bool = True) -> list[str]:
        """Problems a user should know about before trusting a render of this scene
        (``media``: include the note on participating media)."""
        notes = list(self.far_clip_problems)
        for name in self.dark_emitters:
            notes.append(f"emitter '{name}' emits nothing (zero radiance or zero area)")
        if not self.emits_light:
            notes.append("no emitter emits light: every image is black")
        if self.media and media:
            notes.append("the scene has participating media, which Mitsuba's path ignores and lab_mmlt refuses: "
                         "render it with lab_mis (lab_nee, lab_naive), lab_bdpt, lab_vcm, lab_photon or Mitsuba's "
                         "volpath")
        return notes
