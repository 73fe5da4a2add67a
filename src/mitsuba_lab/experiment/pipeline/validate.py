"""Eager validation: every plugin and every scene x sampler of a sweep is instantiated
before anything renders (and in ``--dry-run``), and all problems are reported at once,
each in one line naming the config key path."""
from __future__ import annotations

import re

from ...errors import LabError, one_line
from .config import Config, ConfigError, sample_count_plugin, with_depth


class ConfigProblems(ConfigError):
    """Several problems in one config; ``problems`` holds one line each."""

    def __init__(self, problems: list[str]):
        self.problems = problems
        super().__init__("\n".join(problems))


_PARAMETER = re.compile(r"parameters? '(\w+)'")


def keyed(source: str, key: str, message: str) -> str:
    """'quick.toml: strategies.mis.heuristc: <message>': the key path of the table, extended by
    the parameter or 'type' the message is about."""
    match = _PARAMETER.search(message)
    if match and not message.startswith("unknown "):
        key = f"{key}.{match[1]}"
    elif message.startswith("unknown ") or " is not a" in message:
        key = f"{key}.type"
    return f"{source}: {key}: {message}"


def validate(config: Config) -> None:
    """Raise ConfigProblems listing every plugin or scene that cannot be instantiated."""
    from ...scene import make_integrator, make_sampler
    from ...scene_xml import load_scene_variant

    problems: list[str] = []

    def attempt(key: str, make) -> bool:
        try:
            make()
            return True
        except (LabError, RuntimeError, ValueError, TypeError) as err:
            problems.append(keyed(config.source, key, one_line(err)))
            return False

    for strategy in config.strategies:
        spec = sample_count_plugin(with_depth(strategy, config.max_depth), 1)[0]
        attempt(f"strategies.{strategy.name}", lambda spec=spec: make_integrator(spec.type, spec.params))
    for key, spec in [("reference", config.reference)] + [(f"scenes.{s.name}.reference", s.reference)
                                                          for s in config.scenes if s.reference]:
        ref = with_depth(spec.integrator, config.max_depth)
        attempt(f"{key}.integrator", lambda ref=ref: make_integrator(ref.type, ref.params))
    usable = [s for s in config.samplers
              if attempt(f"samplers.{s.name}", lambda s=s: make_sampler(s.type, s.params))]
    for scene in config.scenes:
        if not attempt(f"scenes.{scene.name}", lambda scene=scene: load_scene_variant(
                scene.path, scene.resolution, None, scene.defaults)):
            continue
        for sampler in usable:
            attempt(f"scenes.{scene.name} with samplers.{sampler.name}",
                    lambda scene=scene, sampler=sampler: load_scene_variant(
                        scene.path, scene.resolution, sampler.as_dict(), scene.defaults))
    if problems:
        raise ConfigProblems(problems)
