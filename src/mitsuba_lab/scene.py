"""Loading scenes and plugins with errors a user can act on."""
from __future__ import annotations

import os
import re

import mitsuba as mi

from .errors import LabError, UnknownPlugin, one_line
from .plugins.params import lab_plugins, plugin_kind
from .plugins.scene_traits import SceneTraits

#: The lab's path tracers (one path loop, ``plugins/integrators/path.py``).
LAB_INTEGRATORS = ("lab_naive", "lab_nee", "lab_mis")
#: Every lab integrator; each answers the planner's questions itself (``strategy_applicability``).
ALL_LAB_INTEGRATORS = tuple(name for name in lab_plugins() if plugin_kind(name) == "integrator")
#: Mitsuba's own integrators (those present in this build are listed in messages).
MITSUBA_INTEGRATORS = ("path", "direct", "volpath", "volpathmis", "ptracer", "aov", "depth",
                       "moment", "stokes", "prb", "prb_basic", "prbvolpath", "direct_projective",
                       "prb_projective")


def load_scene(path: str, **params) -> mi.Scene:
    """Load a Mitsuba XML scene; ``params`` fill its ``<default>`` values (e.g. res=64)."""
    if not os.path.isfile(path):
        raise LabError(f"scene file not found: {path}")
    try:
        return mi.load_file(path, **{k: str(v) for k, v in params.items()})
    except RuntimeError as err:
        raise LabError(f"cannot load scene {path}: {one_line(err)}") from err


#: Mitsuba's own samplers (named in messages).
MITSUBA_SAMPLERS = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")
LAB_SAMPLERS = tuple(name for name in lab_plugins() if plugin_kind(name) == "sampler")
_KNOWN = {"integrator": (ALL_LAB_INTEGRATORS, MITSUBA_INTEGRATORS),
          "sampler": (LAB_SAMPLERS, MITSUBA_SAMPLERS)}


def make_plugin(kind: str, type_name: str, params: dict | None = None):
    """Instantiate a plugin of ``kind`` ('integrator' or 'sampler') by name, its parameters
    checked by the plugin. Errors are LabError lines: "unknown integrator 'lab_nea' (did you
    mean 'lab_nee'?) ...", "integrator 'lab_mis': unknown parameter 'heuristc' ..."."""
    import difflib

    try:
        plugin = mi.load_dict({"type": type_name, **(params or {})})
    except RuntimeError as err:
        text = one_line(err)
        if "not found" in text and f'"{type_name}"' in text:
            lab, mitsuba = _KNOWN[kind]
            close = difflib.get_close_matches(type_name, lab + mitsuba, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise UnknownPlugin(f"unknown {kind} '{type_name}'{hint}; lab {kind}s: {', '.join(lab)}; "
                                f"Mitsuba's: {', '.join(mitsuba)}") from err
        reason = plugin_error_reason(text, params or {})
        if reason.startswith(f"{type_name}: "):       # a lab plugin's own message names it already
            raise LabError(reason) from err
        raise LabError(f"{kind} '{type_name}': {reason}") from err
    expected = {"integrator": mi.Integrator, "sampler": mi.Sampler}[kind]
    if not isinstance(plugin, expected):
        raise LabError(f"'{type_name}' is not {_article(kind)} plugin")
    return plugin


def make_integrator(type_name: str, params: dict | None = None) -> mi.Integrator:
    """Instantiate an integrator plugin by name, with its parameters checked by the plugin."""
    return make_plugin("integrator", type_name, params)


def make_sampler(type_name: str, params: dict | None = None) -> mi.Sampler:
    """Instantiate a sampler plugin by name, with its parameters checked by the plugin."""
    return make_plugin("sampler", type_name, params)


def plugin_error_reason(text: str, params: dict | None = None) -> str:
    """The reason inside Mitsuba's 'failed to instantiate' / 'unreferenced property' messages."""
    unused = re.findall(r'- \w+ "([^"]+)"', text)
    if "unreferenced propert" in text and unused:
        names = ", ".join(f"'{name}'" for name in unused)
        return f"unknown parameter{'s' if len(unused) > 1 else ''} {names}"
    wrong = re.search(r'property "(\w+)" has the wrong type \(expected (\w+), got (\w+)\)', text)
    if wrong:
        given = (params or {}).get(wrong[1], ...)
        got = repr(given) if given is not ... else _article(wrong[3])
        return f"parameter '{wrong[1]}' expects {_article(wrong[2])}, got {got}"
    bounds = re.search(r'Property "(\w+)": value (\S+) is out of bounds, must be in the range (\[[^\]]+\])', text)
    if bounds:
        return f"parameter '{bounds[1]}' must be in {bounds[3]}, got {bounds[2]}"
    return re.sub(r'^.*?plugin of type "[^"]+":\s*', "", text)


def _article(word: str) -> str:
    return f"an {word}" if word[:1] in "aeiou" else f"a {word}"


def film_size(scene: mi.Scene, sensor: int = 0) -> tuple[int, int]:
    size = scene.sensors()[sensor].film().crop_size()
    return int(size[0]), int(size[1])



# ---------------------------------------------------------------------------
# Strategies: which apply to a scene, and which are the same estimator on it
# ---------------------------------------------------------------------------
# Each lab integrator answers these questions itself, through its estimator class
# (``plugins/integrators/estimator.py``); the functions here look it up and ask it.

def _estimator(integrator_type: str):
    """The estimator class of a lab integrator (``Estimator``), or None for any other plugin."""
    from .plugins.integrators.estimator import lookup

    return lookup(integrator_type)


def strategy_applicability(traits: SceneTraits, integrator_type: str, params: dict) -> tuple[bool, str]:
    """(True, '') when the integrator renders the scene correctly, else (False, one-line reason):
    a lab integrator as its estimator says (``Estimator.applicability``), Mitsuba's own as the
    table of what they ignore says (``features.MITSUBA_IGNORES``: ``path`` ignores participating
    media). Integrators known to neither are taken as applicable."""
    estimator = _estimator(integrator_type)
    if estimator is None:
        from .features import mitsuba_applicability

        return mitsuba_applicability(traits, integrator_type, params)
    from .plugins.params import resolve

    return estimator.applicability(traits, resolve(integrator_type, params or {}))


def _equivalence(traits: SceneTraits, integrator_type: str, params: dict) -> tuple[tuple, str]:
    """(key, reason): equal keys only for provably identical estimators on this scene
    (``Estimator.equivalence``, with parameters checked and defaults filled in); integrators
    other than the lab's merge only when type and parameters are identical."""
    estimator = _estimator(integrator_type)
    if estimator is None:
        from .plugins.integrators.estimator import exact_key

        return exact_key(integrator_type, params), "same parameters (exact)"
    from .plugins.params import resolve   # checked, normalised, every default filled in

    return estimator.equivalence(traits, resolve(integrator_type, params))


def equivalent_strategies(traits: SceneTraits,
                          strategies: dict[str, tuple[str, dict]]) -> dict[str, str]:
    """Map every strategy name to the canonical name of its class of provably identical
    estimators on this scene (itself when it has no twin).

    The canonical member is the simplest (``Estimator.SIMPLICITY``: lab_naive, then lab_nee,
    then lab_mis; ties by the order of ``strategies``).
    """
    from .plugins.integrators.estimator import OTHER_SIMPLICITY

    classes: dict = {}
    for order, (name, (kind, params)) in enumerate(strategies.items()):
        key, _ = _equivalence(traits, kind, params or {})
        estimator = _estimator(kind)
        rank = estimator.SIMPLICITY if estimator is not None else OTHER_SIMPLICITY
        classes.setdefault(key, []).append((rank, order, name))
    canonical = {}
    for members in classes.values():
        best = min(members)[2]
        for _, _, name in members:
            canonical[name] = best
    return {name: canonical[name] for name in strategies}


def equivalence_reason(traits: SceneTraits, integrator_type: str, params: dict) -> str:
    """Why a strategy is merged with its twins on this scene, e.g. "all BSDFs are delta: no
    vertex can sample an emitter, so every strategy is BSDF sampling with weight 1"."""
    return _equivalence(traits, integrator_type, params or {})[1]
