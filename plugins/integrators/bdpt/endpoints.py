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
point, spot, ``constant``, ``envmap`` and ``directional`` emitters, pinhole (``perspective``)
sensors.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

_AREA, _AREA_TEXTURED, _POINT, _SPOT, _DIRECTIONAL, _ENVIRONMENT = 0, 1, 2, 3, 4, 5
#: Plugin class -> kind (an area light's kind also depends on its texture).
_KINDS = {"AreaLight": _AREA, "PointLight": _POINT, "SpotLight": _SPOT, "DirectionalEmitter": _DIRECTIONAL,
          "ConstantBackgroundEmitter": _ENVIRONMENT, "EnvironmentMapEmitter": _ENVIRONMENT}


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
        for index, (emitter, slot) in enumerate(zip(emitters, ids)):
            name = emitter.class_name()
            if name not in _KINDS:
                raise ValueError(f"lab_bdpt: emitter '{emitter.id() or name}' ({name}) is not supported: "
                                 f"its emission densities are not known (supported: area, point, spot, "
                                 f"constant, envmap, directional)")
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
        emitter cannot be hit (point, spot, directional). ``point``, ``direction``: the emitted
        point and direction (world space), which an area light's density depends on when it
        aims (``aim``)."""
        slot = self.slot(emitter)
        kind = dr.gather(mi.UInt32, self.kind, slot, active)
        pmf = dr.gather(mi.Float, self.pmf, slot, active)
        position_delta = (kind == _POINT) | (kind == _SPOT)
        pos = dr.select(position_delta, pmf, pmf * dr.gather(mi.Float, self.inv_area, slot, active))
        if self.aim is None:
            area_dir = cos_out * dr.inv_pi
        elif point is None or direction is None:
            raise ValueError("lab_bdpt: an aiming emitter's density needs the emitted point and direction")
        else:
            area_dir = self.aim.pdf(cos_out, point, direction)
        direction = dr.select(kind >= _POINT, dr.gather(mi.Float, self.cone, slot, active), area_dir)
        if pdf_nee is not None:
            pos = dr.select(kind == _AREA_TEXTURED, pdf_nee, pos)
            direction = dr.select(kind == _ENVIRONMENT, pdf_nee / dr.maximum(pmf, 1e-30), direction)
        return pos, direction, position_delta | (kind == _DIRECTIONAL)


def bounding_radius(scene: mi.Scene) -> float:
    """R of the disk that emitters at infinity start their rays from (Mitsuba's ``set_scene``:
    the scene's bounding sphere, enlarged by one ray epsilon)."""
    eps = 1500 * 2.0 ** -24
    bbox = scene.bbox()
    if not bbox.valid():
        return eps
    return max(eps, float(bbox.bounding_sphere().radius) * (1.0 + eps))


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
