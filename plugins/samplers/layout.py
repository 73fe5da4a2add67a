"""Tell a sensor's sampler the shape of the pixel block it renders.

A Mitsuba sampler learns only ``seed(seed, wavefront_size)`` from a render:
``pixels x spp`` lanes, pixel ``i`` at ``(i mod W, i div W)`` of the film's crop
window (grown by the reconstruction filter's border with ``sample_border``). W
itself never reaches it, nor any reference to its sensor or film. Samplers whose
points depend on where a pixel lies (``lab_zsobol`` orders the pixels along a
Z-curve) expose a hook, ``bind_film(film)``; ``bind_film_layout`` finds a
sensor's sampler and calls it. In JIT variants ``SamplingIntegrator::render``
seeds the sensor's own sampler object and Mitsuba's Python integrators seed a
``clone()`` of it, so a binding made before the render reaches the seeded sampler
(lab samplers copy it in ``clone``/``fork``).

The lab binds before every render it makes (``mitsuba_lab.render.render`` and
the lab integrators' ``render``); outside the lab, call it before ``mi.render``:

.. code-block:: python

    bind_film_layout(scene)            # sensor 0; or bind_film_layout(scene.sensors()[1])
    img = mi.render(scene, integrator=mi.load_dict({"type": "path"}))
"""
from __future__ import annotations

import mitsuba as mi


def film_block_size(film) -> tuple[int, int]:
    """(width, height) of the pixels a render of ``film`` traces: its crop window,
    grown by twice the filter's border when the film samples its border (as
    ``SamplingIntegrator::render`` and Mitsuba's Python integrators size the wavefront)."""
    width, height = (int(v) for v in film.crop_size())
    if film.sample_border():
        border = int(film.rfilter().border_size())
        width, height = width + 2 * border, height + 2 * border
    return width, height


def _sensor(scene_or_sensor, sensor):
    if isinstance(sensor, mi.Sensor):
        return sensor
    if isinstance(scene_or_sensor, mi.Sensor):
        return scene_or_sensor
    if isinstance(scene_or_sensor, mi.Scene):
        sensors = scene_or_sensor.sensors()
        if not 0 <= sensor < len(sensors):
            raise ValueError(f"bind_film_layout: sensor index {sensor} out of range "
                             f"(the scene has {len(sensors)} sensor(s))")
        return sensors[sensor]
    raise ValueError(f"bind_film_layout: expected a mi.Scene or mi.Sensor, got {type(scene_or_sensor).__name__}")


def bind_film_layout(scene_or_sensor, sensor=0) -> tuple[int, int] | None:
    """Bind the film of a sensor (``scene.sensors()[sensor]``, or the sensor given, as the
    first or second argument, as ``Integrator.render`` takes either) to its sampler, if
    that sampler has a ``bind_film`` hook.

    Returns the (width, height) of the pixel block the sampler will see, or None
    when the sampler takes no layout (Mitsuba's own samplers, the lab's other
    samplers): then nothing happens. Cheap and safe to call before every render.
    The sampler reads the film's size again at each ``seed``, so a later change of
    the crop window is followed.
    """
    sensor = _sensor(scene_or_sensor, sensor)
    hook = getattr(sensor.sampler(), "bind_film", None)
    if not callable(hook):
        return None
    film = sensor.film()
    hook(film)
    return film_block_size(film)
