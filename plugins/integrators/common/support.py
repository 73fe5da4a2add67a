"""What a lab integrator says when it is given a scene it cannot render correctly, how its
own ``render`` reads Mitsuba's arguments, and how it calls Mitsuba's.

Used as a plugin inside a user's scene, it renders anyway (a scene may be right apart from
one object) and logs one warning per render through Mitsuba's logger, naming the plugin and
the reason (``Estimator.applicability``: participating media, delta lights for lab_naive).
``mitsuba-lab render`` asks first and refuses such a scene unless ``--allow-unsupported``.
"""
from __future__ import annotations

import mitsuba as mi

from mitsuba_lab.plugins import interrupts


def warn_if_unsupported(integrator, traits) -> str:
    """Log the reason ``integrator`` (a lab integrator) cannot render a scene with these
    ``SceneTraits`` correctly, unless its caller has already said it (its
    ``unsupported_acknowledged`` attribute is set). Returns the reason ('' when supported)."""
    ok, reason = integrator.ESTIMATOR.applicability(traits, integrator.settings())
    if ok:
        return ""
    if not getattr(integrator, "unsupported_acknowledged", False):
        mi.Log(mi.LogLevel.Warn, f"{reason} (rendering it anyway: the image will lack what the "
                                 f"integrator cannot render)")
    return reason


def render_arguments(scene: mi.Scene, sensor, seed, spp: int):
    """(sensor, seed, spp) of a ``render`` call as plain values: the sensor object (from its
    index too), the seed as an int (a one-element Dr.Jit array too), and spp (0: the sensor's
    sampler's)."""
    if isinstance(sensor, int):
        sensor = scene.sensors()[sensor]
    seed = int(seed[0]) if hasattr(seed, "__len__") and not isinstance(seed, int) else int(seed)
    return sensor, seed, spp or sensor.sampler().sample_count()


def base_render(integrator, scene: mi.Scene, sensor, seed, spp: int, develop: bool = True,
                evaluate: bool = True):
    """Mitsuba's own ``SamplingIntegrator.render`` for ``integrator``, a lab integrator that
    overrides ``render``. Python's SIGINT handler is installed first (``interrupts.restore``).
    Mitsuba then calls the Python ``render`` back, and a call made there records the handler
    it finds as the one to pass Ctrl-C on to. Without this it would find Mitsuba's own, and
    Ctrl-C would be lost."""
    interrupts.restore()
    return mi.SamplingIntegrator.render(integrator, scene, sensor, seed, spp, develop, evaluate)
