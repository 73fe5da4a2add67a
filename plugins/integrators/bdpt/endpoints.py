"""The densities of BDPT's end vertices that Mitsuba's interfaces do not return directly.

The MIS weights (``weights.py``) need, for every emitter point a path can start from, three
densities, all including the emitter's selection probability (``Scene.pdf_emitter``):

* ``pdf_pos``: area density of the point under emission (``Emitter.sample_ray``'s position:
  uniform over the shape's area, or by the radiance texture for a textured area light; a delta
  position's is its selection probability alone, the delta stripped; an emitter at infinity
  starts its rays on a disk of the scene's bounding-sphere radius R facing the direction,
  1 / (pi R^2));
* ``pdf_dir``: solid-angle density of the emitted direction (area light: cosine-weighted,
  cos / pi; point: uniform sphere, 1 / (4 pi); spot: uniform in the cone of ``cutoff_angle``;
  ``projector``: by its irradiance texture through its frustum, ``ProjectorEmission``;
  ``constant`` and ``envmap``: the same density as emitter sampling's; ``directional``: 1, the
  delta stripped). ``constant`` starts its rays on the bounding sphere with cosine-weighted
  directions, which is the same joint density per unit solid angle and projected area;
* ``pdf_nee``: the density with which emitter sampling (``Scene.sample_emitter_direction``)
  picks the point from a given reference point, converted to area: it may depend on the
  reference (Mitsuba samples a sphere light by the cone it subtends), so it is evaluated with
  ``Scene.pdf_emitter_direction`` once that point is known.

``EmitterTable`` holds per-emitter constants, looked up by the emitter pointer's registry id;
``camera_direction_pdf`` gives the sensor's density of a direction for the t = 1 strategy.
For an emitter at infinity the "vertex" x_0 is a direction: its densities are per unit solid
angle, and the weights take cos = 1 and dist^2 = 1 on the segment that touches it
(``weights.py``). Supported: area lights (rectangles, spheres, meshes, ..., textured or not),
point, spot, ``projector`` (constant or textured), ``constant``, ``envmap`` and ``directional``
emitters, pinhole (``perspective``) and thin-lens sensors, and orthographic ones, whose
direction is a delta (``direction_is_delta``: light tracing cannot reach them).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

#: Emitter kinds; the delta positions (point, spot, projector) lie between _POINT and _PROJECTOR,
#: the emitters at infinity from _DIRECTIONAL on.
_AREA, _AREA_TEXTURED, _POINT, _SPOT, _PROJECTOR, _DIRECTIONAL, _ENVIRONMENT = 0, 1, 2, 3, 4, 5, 6
#: Plugin class -> kind (an area light's kind also depends on its texture).
_KINDS = {"AreaLight": _AREA, "PointLight": _POINT, "SpotLight": _SPOT, "Projector": _PROJECTOR,
          "DirectionalEmitter": _DIRECTIONAL, "ConstantBackgroundEmitter": _ENVIRONMENT,
          "EnvironmentMapEmitter": _ENVIRONMENT}
#: Sensors whose direction is a delta given the sampled film point (no light vertex joins them).
DELTA_DIRECTION_SENSORS = ("OrthographicCamera",)


def direction_is_delta(sensor: mi.Sensor) -> bool:
    """The sensor's ray direction is fixed by its film point (orthographic): light tracing
    (t = 1) cannot reach it, and the weights count t = 1 as impossible (``start_camera``)."""
    return sensor.class_name() in DELTA_DIRECTION_SENSORS


def _textured(emitter) -> bool:
    """The area light's radiance varies over its surface (Mitsuba then samples positions by it):
    a 2D texture has a ``to_uv`` transform; a spectrum (``radiance.value``, a blackbody's
    ``temperature``, the D65 table of an RGB spectrum in spectral variants) does not vary."""
    return any(key.startswith("radiance.") and key.endswith("to_uv") for key in mi.traverse(emitter).keys())


class EmitterTable:
    """Per-emitter constants of one scene, gathered per lane by the emitter pointer.

    ``kind`` (area, textured area, point, spot, directional, environment), ``pmf`` (selection
    probability), ``inv_area`` (1 / shape area; for emitters at infinity 1 / (pi R^2), the
    disk their rays start from), ``cone`` (a spot light's direction density; 1 / (4 pi) for a
    point; 1 for a directional emitter).
    """

    def __init__(self, scene: mi.Scene, aim=None):
        #: ``aim.AimedEmission`` when area lights aim a share of their directions at shapes
        self.aim = aim if aim is not None and aim.enabled else None
        emitters = scene.emitters()
        ids = dr.reinterpret_array(mi.UInt32, scene.emitters_dr()).numpy().tolist() if emitters else []
        size = (max(ids) if ids else 0) + 1
        kind, pmf, inv_area, cone = [0] * size, [0.0] * size, [0.0] * size, [0.0] * size
        #: ``ProjectorEmission`` of each projector (empty: no code for them in the kernels)
        self.projectors = []
        for index, (emitter, slot) in enumerate(zip(emitters, ids)):
            name = emitter.class_name()
            if name not in _KINDS:
                raise ValueError(f"lab_bdpt: emitter '{emitter.id() or name}' ({name}) is not supported: "
                                 f"its emission densities are not known (supported: area, point, spot, "
                                 f"projector, constant, envmap, directional)")
            kind[slot] = _KINDS[name]
            pmf[slot] = float(scene.pdf_emitter(mi.UInt32(index))[0])
            if name == "AreaLight":
                kind[slot] = _AREA_TEXTURED if _textured(emitter) else _AREA
                area = float(emitter.get_shape().surface_area()[0])
                inv_area[slot] = 1.0 / area if area > 0 else 0.0
            elif name == "PointLight":
                cone[slot] = 1.0 / (4.0 * math.pi)
            elif name == "SpotLight":
                cutoff = math.radians(float(mi.traverse(emitter)["cutoff_angle"][0]))
                cone[slot] = 1.0 / (2.0 * math.pi * (1.0 - math.cos(cutoff)))
            elif name == "Projector":                  # its direction density varies: per lane, below
                self.projectors.append(ProjectorEmission(emitter, slot))
            else:                                      # at infinity: rays start on a disk of radius R
                inv_area[slot] = 1.0 / (math.pi * bounding_radius(scene) ** 2)
                cone[slot] = 1.0
        self.kind, self.pmf = mi.UInt32(kind), mi.Float(pmf)
        self.inv_area, self.cone = mi.Float(inv_area), mi.Float(cone)

    @staticmethod
    def slot(emitter):
        """The table index of an ``EmitterPtr`` array (its registry id)."""
        return dr.reinterpret_array(mi.UInt32, emitter)

    def at_infinity(self, emitter, active=True):
        """The emitter is ``constant``, ``envmap`` or ``directional`` (its x_0 is a direction)."""
        return dr.gather(mi.UInt32, self.kind, self.slot(emitter), active) >= _DIRECTIONAL

    def emission(self, emitter, cos_out, pdf_nee=None, active=True, point=None, direction=None):
        """(pdf_pos, pdf_dir, delta) of emitting from a point of ``emitter`` in a direction at
        |cos| ``cos_out`` to its normal. ``pdf_nee``: the point's density under emitter
        sampling (``nee_density``: area, or solid angle at infinity), needed for textured
        area lights and environments, which sample positions or directions the same way for
        emission as for emitter sampling (for the others it may be None). ``delta``: the
        emitter cannot be hit (point, spot, projector, directional). ``point``, ``direction``:
        the emitted point and direction (world space), which an area light's density depends
        on when it aims (``aim``), and a projector's always."""
        slot = self.slot(emitter)
        kind = dr.gather(mi.UInt32, self.kind, slot, active)
        pmf = dr.gather(mi.Float, self.pmf, slot, active)
        position_delta = (kind >= _POINT) & (kind <= _PROJECTOR)
        pos = dr.select(position_delta, pmf, pmf * dr.gather(mi.Float, self.inv_area, slot, active))
        if self.aim is None:
            area_dir = cos_out * dr.inv_pi
        elif point is None or direction is None:
            raise ValueError("lab_bdpt: an aiming emitter's density needs the emitted point and direction")
        else:
            area_dir = self.aim.pdf(cos_out, point, direction)
        pdf_dir = dr.select(kind >= _POINT, dr.gather(mi.Float, self.cone, slot, active), area_dir)
        if self.projectors:
            pdf_dir = self._projected(slot, direction, active, pdf_dir)
        if pdf_nee is not None:
            pos = dr.select(kind == _AREA_TEXTURED, pdf_nee, pos)
            pdf_dir = dr.select(kind == _ENVIRONMENT, pdf_nee / dr.maximum(pmf, 1e-30), pdf_dir)
        return pos, pdf_dir, position_delta | (kind == _DIRECTIONAL)

    def _projected(self, slot, direction, active, pdf_dir):
        """``pdf_dir`` with each projector's lanes given its density of the emitted ``direction``
        (one call per projector: its texture is not reachable through the emitter pointer)."""
        if direction is None:
            raise ValueError("lab_bdpt: a projector's density needs the emitted direction")
        for projector in self.projectors:
            mine = active & (slot == projector.slot)
            pdf_dir = dr.select(mine, projector.pdf_direction(direction, mine), pdf_dir)
        return pdf_dir


def bounding_radius(scene: mi.Scene) -> float:
    """R of the disk that emitters at infinity start their rays from (Mitsuba's ``set_scene``:
    the scene's bounding sphere, enlarged by one ray epsilon)."""
    eps = 1500 * 2.0 ** -24
    bbox = scene.bbox()
    if not bbox.valid():
        return eps
    return max(eps, float(bbox.bounding_sphere().radius) * (1.0 + eps))


class ProjectorEmission:
    """A ``projector``'s density of an emitted direction, as its ``sample_ray`` draws it.

    Mitsuba's projector is a pinhole camera run backwards: ``sample_ray`` draws a film point uv
    from its irradiance texture (``Texture.sample_position``: by the texels for a bitmap,
    uniform for a constant; density p_uv on [0, 1]^2) and emits through the point of its image
    plane at distance 1 that uv maps to. uv is affine in that plane's coordinates (density
    p_uv / A on the plane), and at angle theta from the optical axis the plane holds
    1 / cos^3 theta of its area per unit solid angle (distance 1 / cos theta, tilted by theta), so

        p(w) = p_uv(uv(w)) / (A cos^3 theta),   A the image plane's area at distance 1,

    and 0 outside the frustum. uv(w) and the frustum test are the projector's own
    (``sample_direction`` at the point one unit along w), p_uv is the texture's
    ``pdf_position``, the same one that ``sample_ray``'s weight divides by: the light side's
    emission and the camera side's next-event estimation see the same density. Assumes a rigid
    ``to_world`` (a ``lookat``), as Mitsuba's projector does for its rays to be unit vectors.
    """

    def __init__(self, emitter, slot: int):
        self.emitter, self.slot = emitter, slot
        self.texture = _irradiance_texture(emitter)
        origin = emitter.sample_position(0.0, mi.Point2f(0.5))[0].p
        self.origin = tuple(float(c[0]) for c in origin)
        self.area = _image_plane_area(emitter)
        if self.texture is not None:                   # (builds its sampling table outside any kernel)
            dr.eval(self.texture.pdf_position(mi.Point2f(0.5, 0.5)))

    def pdf_direction(self, direction, active):
        """Solid-angle density of emitting along the unit world ``direction`` (lanes ``active``)."""
        it = dr.zeros(mi.Interaction3f, dr.width(direction))
        it.p = mi.Point3f(*self.origin) + direction
        ds, _ = self.emitter.sample_direction(it, mi.Point2f(0.5), active)
        inside = active & (ds.pdf > 0)             # (the frustum: uv in [0, 1]^2, in front)
        cos = -dr.dot(dr.normalize(ds.n), ds.d)    # ds.d points back at the projector
        p_uv = mi.Float(1.0) if self.texture is None else self.texture.pdf_position(ds.uv, inside)
        return dr.select(inside & (cos > 0), p_uv / (self.area * cos * dr.square(cos)), 0.0)


def _irradiance_texture(emitter):
    """The projector's ``irradiance`` texture object (None: none found, sampled uniformly as
    Mitsuba's base ``Texture`` is): the node of its own parameters ``irradiance.<name>``."""
    params = mi.traverse(emitter)
    for key in params.keys():
        if key.startswith("irradiance.") and key.count(".") == 1:
            return params.properties[key][2]
    return None


def _image_plane_area(emitter) -> float:
    """A, the area of a projector's image plane at distance 1 (uv in [0, 1]^2), from its own
    mapping: uv is affine in x / z and y / z, so its slopes between two points each side of
    the axis give the plane's width and height."""
    to_world = emitter.world_transform()
    it = dr.zeros(mi.Interaction3f, 4)
    it.p = to_world @ mi.Point3f(mi.Float(1, -1, 0, 0), mi.Float(0, 0, 1, -1), mi.Float(1, 1, 1, 1))
    uv = emitter.sample_direction(it, mi.Point2f(0.5))[0].uv
    u, v = uv.x.numpy().astype(float), uv.y.numpy().astype(float)
    width, height = 2.0 / abs(u[0] - u[1]), 2.0 / abs(v[2] - v[3])
    return float(width * height)


def nee_density(scene: mi.Scene, ref: mi.Interaction3f, ds: mi.DirectionSample3f, infinite, active=True):
    """Density with which emitter sampling from ``ref`` picks ``ds``'s point: per unit area, or
    per unit solid angle for an emitter at infinity (``infinite``); 0 where not ``active``
    (a delta emitter is handled by the caller)."""
    pdf_solid = scene.pdf_emitter_direction(ref, ds, active)
    to_area = dr.abs(dr.dot(ds.n, ds.d)) / dr.square(ds.dist)
    return dr.select(active, pdf_solid * dr.select(infinite, 1.0, to_area), 0.0)


def camera_direction_pdf(importance, dist2):
    """The pinhole sensor's solid-angle density of a direction, per camera sample over the crop
    window: 1 / (A' cos^3), A' the visible image-plane area at distance 1 (uniform film samples
    mapped to directions). Mitsuba's ``PerspectiveCamera`` importance is that density, and
    ``Sensor.sample_direction`` returns it divided by dist^2."""
    return dr.max(mi.unpolarized_spectrum(importance)) * dist2
