"""Scene features an integrator may render as if they were absent, and which integrators do.

A *feature* is part of what a scene asks of an integrator, read from its ``SceneTraits``:

* ``media``: a participating medium is attached to a shape or the sensor;
* ``indirect light``: light that reaches the camera after more than one bounce (any scene with
  an emitter that emits and a surface that scatters; conservative: the traits cannot tell
  whether such paths carry light).

Mitsuba's own integrators are described here, in ``MITSUBA_IGNORES``, in one place; each lab
integrator describes itself (``Estimator.applicability``). ``scene.strategy_applicability``
asks whichever applies; the planner leaves out a strategy that ignores a feature of its scene
(unless the config allows it), and a reference integrator must render every feature
(``default_reference`` picks one that does).
"""
from __future__ import annotations

#: feature -> (what it is, why the scene has it, integrators that render it), for messages.
FEATURES = {
    "media": ("participating media", "the scene has a medium", "volpath or volpathmis"),
    "indirect light": ("indirect light", "light reaches the camera after more than one bounce", "path"),
}

#: Mitsuba's integrators -> the features they render as if absent. Each entry is measured
#: (tests/test_features.py): with and without a homogeneous medium inside a dielectric sphere
#: the same seed gives bit-identical images for every integrator listed with ``media`` (and
#: different ones for volpath, volpathmis and prbvolpath); ``direct`` and ``direct_projective``
#: render paths of at most two segments, the mean of ``path`` with max_depth 2. ``aov``,
#: ``depth`` and ``moment`` render no light of a medium either (``aov`` and ``moment`` wrapping
#: another integrator render what it renders: ``WRAPPERS``).
MITSUBA_IGNORES: dict[str, frozenset[str]] = {
    "path": frozenset({"media"}),
    "ptracer": frozenset({"media"}),
    "prb": frozenset({"media"}),
    "prb_basic": frozenset({"media"}),
    "prb_projective": frozenset({"media"}),
    "direct": frozenset({"media", "indirect light"}),
    "direct_projective": frozenset({"media", "indirect light"}),
    "aov": frozenset({"media"}),
    "depth": frozenset({"media"}),
    "moment": frozenset({"media"}),
    "volpath": frozenset(),
    "volpathmis": frozenset(),
    "prbvolpath": frozenset(),
}
#: Mitsuba's integrators that render what a nested integrator (a table among their parameters)
#: renders.
WRAPPERS = ("aov", "moment")
#: Reference integrators a sweep, ``check`` and ``mitsuba-lab reference`` choose from when none
#: is named: the first that renders every feature of the scene (``path`` unless it has media).
DEFAULT_REFERENCES = ("path", "volpathmis")


def scene_features(traits) -> tuple[str, ...]:
    """The features (``FEATURES`` keys) a scene with these ``SceneTraits`` has."""
    present = []
    if traits.media:
        present.append("media")
    if traits.emits_light and (traits.smooth_bsdf or traits.delta_bsdf):
        present.append("indirect light")
    return tuple(present)


def ignored_features(traits, integrator_type: str, params: dict | None = None) -> tuple[str, ...] | None:
    """The scene's features that the integrator renders as if absent; None for an integrator
    this table does not know (neither Mitsuba's, as listed, nor a lab integrator)."""
    from .plugins.integrators.estimator import lookup

    if integrator_type in WRAPPERS:
        inner = next((v for v in (params or {}).values() if isinstance(v, dict) and "type" in v), None)
        if inner is not None:
            return ignored_features(traits, inner["type"], {k: v for k, v in inner.items() if k != "type"})
    if integrator_type in MITSUBA_IGNORES:
        ignores = MITSUBA_IGNORES[integrator_type]
    elif lookup(integrator_type) is not None:
        ignores = frozenset() if lookup(integrator_type).RENDERS_MEDIA else frozenset({"media"})
    else:
        return None
    return tuple(f for f in scene_features(traits) if f in ignores)


def ignores_text(features) -> str:
    """How a report marks a strategy that ran though it ignores these features: "ignores media"."""
    return "ignores " + " and ".join(features) if features else "unsupported on this scene"


def mitsuba_applicability(traits, integrator_type: str, params: dict | None = None) -> tuple[bool, str]:
    """(True, '') when a non-lab integrator renders every feature of the scene (or is not in
    the table: its limits are its own business), else (False, one-line reason)."""
    ignored = ignored_features(traits, integrator_type, params) or ()
    if not ignored:
        return True, ""
    what = " and ".join(FEATURES[f][0] for f in ignored)
    why = "; ".join(FEATURES[f][1] for f in ignored)
    use = FEATURES[ignored[0]][2]
    return False, f"{integrator_type} ignores {what} ({why}): use {use}"


def default_reference(traits) -> str:
    """The reference integrator for a scene when the user names none: the first of
    ``DEFAULT_REFERENCES`` that renders all its features (``volpathmis`` where it has media)."""
    return next((name for name in DEFAULT_REFERENCES if not ignored_features(traits, name)),
                DEFAULT_REFERENCES[-1])
