"""Which integrator renders each scene's reference: one that renders every feature of the scene.

A reference that cannot see part of a scene (Mitsuba's ``path`` and a medium) would make the
one strategy that renders it correctly look biased. So a reference integrator named in the
config must render every feature of each scene it serves (else a config error: one line per
scene, naming the integrator and the feature), and where none is named each scene gets the
first of ``features.DEFAULT_REFERENCES`` that does (``path``, or ``volpathmis`` where the
scene has media).
"""
from __future__ import annotations

import dataclasses

from ...features import default_reference
from .config import Config, PluginSpec, with_depth
from .validate import ConfigProblems


def reference_problem(traits, integrator: PluginSpec) -> str:
    """Why ``integrator`` cannot render a scene with these ``SceneTraits`` as a reference ('' when
    it can): a feature it ignores, or for a lab integrator what its estimator says."""
    from ...scene import strategy_applicability

    ok, reason = strategy_applicability(traits, integrator.type, integrator.params)
    return "" if ok else reason


def choose_references(config: Config, traits: dict) -> Config:
    """``config`` with every scene's reference integrator settled (``traits``: {scene name:
    SceneTraits}): a named one checked, an unnamed one chosen for the scene's features (set as
    the scene's own reference, so every later step reads it from ``Config.reference_for``).
    Raises ConfigProblems, one line per scene whose named reference ignores part of it."""
    problems, scenes = [], []
    for scene in config.scenes:
        spec = config.reference_for(scene)
        if not spec.named:
            chosen = default_reference(traits[scene.name])
            if chosen != spec.integrator.type:
                spec = dataclasses.replace(spec, integrator=PluginSpec(spec.integrator.name, chosen))
                scene = dataclasses.replace(scene, reference=spec)
        else:
            reason = reference_problem(traits[scene.name], with_depth(spec.integrator, config.max_depth))
            if reason:
                own = scene.reference is not None and scene.reference.integrator is not config.reference.integrator
                key = f"scenes.{scene.name}.reference" if own else "reference"
                problems.append(f"{config.source}: {key}.integrator: scene '{scene.name}': the reference "
                                f"must render every feature of the scene, but {reason}")
        scenes.append(scene)
    if problems:
        raise ConfigProblems(problems)
    return dataclasses.replace(config, scenes=tuple(scenes))
