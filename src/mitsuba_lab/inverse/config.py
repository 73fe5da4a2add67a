"""The inverse-rendering TOML file: schema, defaults and validation.

Tables: ``[experiment]`` (``name``, ``output``), ``[scene]`` (``path`` or ``builtin``,
``resolution``, ``texture_size``, ``defaults``), ``[render]`` (``max_depth`` required,
``spp``, ``target_spp``, ``seed``), ``[optimise]`` (``iterations``, ``learning_rate``,
``loss``, ``eval_spp``), ``[parameters."KEY"]`` (``init``, ``min``, ``max``, ``truth``)
and ``[gradients]`` (``key``, ``spp``, ``samplers``, ``seeds``, ``reference_spp``,
``reference_seeds``). A misspelt key or a value of the wrong kind is a one-line
``ConfigError`` naming its key path (``optimise.loss: expected one of l2, relative_l2``).
"""
from __future__ import annotations

import os
from dataclasses import dataclass

from ..experiment.pipeline.config import TableReader, read_resolution, read_toml

LOSSES = ("l2", "relative_l2")
BUILTIN_SCENES = ("cornell_texture",)
#: Samplers of the gradient sweep when the config names none.
DEFAULT_SAMPLERS = ("independent", "lab_independent", "lab_sobol", "lab_stratified")


@dataclass(frozen=True)
class ParamSpec:
    """One optimised scene parameter: its ``mi.traverse`` key, start value, valid range."""
    key: str
    init: float | tuple[float, ...]
    lo: float
    hi: float
    truth: float | tuple[float, ...] | None = None   # None: the scene's own value


@dataclass(frozen=True)
class GradientSpec:
    key: str
    spp: tuple[int, ...]
    samplers: tuple[str, ...]
    seeds: int
    reference_spp: int
    reference_seeds: int


@dataclass(frozen=True)
class InverseConfig:
    name: str
    source: str
    output: str
    scene_path: str | None
    builtin: str | None
    resolution: int | tuple[int, int]      # film override (``film``): the larger side, or (width, height)
    texture_size: int
    defaults: dict
    max_depth: int
    spp: int
    target_spp: int
    seed: int
    iterations: int
    learning_rate: float
    loss: str
    eval_spp: int
    params: tuple[ParamSpec, ...]
    gradients: GradientSpec | None = None
    optimise: bool = True

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(p.key for p in self.params)


def _number_or_list(reader: TableReader, name: str, default=...):
    value = reader.get(name, object, default, expected="a number or a list of numbers")
    if value is None:
        return None
    is_num = lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)
    if is_num(value):
        return float(value)
    if isinstance(value, list) and value and all(is_num(v) for v in value):
        return tuple(float(v) for v in value)
    reader.fail(name, f"a number or a non-empty list of numbers, got {value!r}")


def _positive(v) -> bool:
    return v > 0


def load_config(path: str) -> InverseConfig:
    """Read and validate an inverse-rendering config (schema: this module's docstring)."""
    return parse_config(read_toml(path), path)


def parse_config(data: dict, source: str) -> InverseConfig:
    base_dir = os.path.dirname(os.path.abspath(source))
    top = TableReader(source, data, "")
    top.unknown({"experiment", "scene", "render", "optimise", "parameters", "gradients"})
    exp = top.sub("experiment", {})
    exp.unknown({"name", "output"})
    name = exp.get("name", str, os.path.splitext(os.path.basename(source))[0])
    output = exp.get("output", str, os.path.join("out", name))

    sc = top.sub("scene")
    sc.unknown({"path", "builtin", "resolution", "texture_size", "defaults"})
    rel = sc.get("path", str, None)
    builtin = sc.get("builtin", str, None, check=lambda v: v in BUILTIN_SCENES,
                     expected=f"one of {', '.join(BUILTIN_SCENES)}")
    if (rel is None) == (builtin is None):
        sc.fail("path", "exactly one of scene.path (an XML file) and scene.builtin")
    scene_path = None
    if rel is not None:
        scene_path = os.path.normpath(os.path.join(base_dir, rel))
        if not os.path.isfile(scene_path):
            sc.fail("path", f"an existing scene file, but {scene_path} does not exist")
    resolution = read_resolution(sc, 32)
    texture_size = sc.get("texture_size", int, 16, check=_positive, expected="a positive integer")
    defaults = dict(sc.sub("defaults", {}).table)

    rd = top.sub("render", {})
    rd.unknown({"max_depth", "spp", "target_spp", "seed"})
    max_depth = rd.get("max_depth", int, check=lambda v: v >= 1,
                       expected="an integer >= 1 (pinned explicitly: prb defaults to 6, path to unbounded)")
    spp = rd.get("spp", int, 16, check=_positive, expected="a positive integer")
    target_spp = rd.get("target_spp", int, 512, check=_positive, expected="a positive integer")
    seed = rd.get("seed", int, 0, check=lambda v: 0 <= v < 2 ** 30, expected="an integer in [0, 2^30)")

    op = top.sub("optimise", {})
    op.unknown({"iterations", "learning_rate", "loss", "eval_spp"})
    iterations = op.get("iterations", int, 50, check=lambda v: v >= 0, expected="an integer >= 0")
    learning_rate = op.get("learning_rate", float, 0.05, check=_positive, expected="a positive number")
    loss = op.get("loss", str, "l2", check=lambda v: v in LOSSES, expected=f"one of {', '.join(LOSSES)}")
    eval_spp = op.get("eval_spp", int, 64, check=lambda v: v >= 0, expected="an integer >= 0 (0: off)")

    pr = top.sub("parameters")
    params = []
    for key in pr.table:
        item = pr.sub(key)
        item.unknown({"init", "min", "max", "truth"})
        init = _number_or_list(item, "init")
        lo = item.get("min", float, 0.0)
        hi = item.get("max", float, 1.0)
        if not lo < hi:
            item.fail("max", f"a number above min = {lo}, got {hi}")
        params.append(ParamSpec(key, init, lo, hi, _number_or_list(item, "truth", None)))
    if not params:
        pr.fail("", "at least one parameter (a table per mi.traverse key)")

    gradients = None
    if "gradients" in data:
        gr = top.sub("gradients")
        gr.unknown({"key", "spp", "samplers", "seeds", "reference_spp", "reference_seeds"})
        key = gr.get("key", str, params[0].key)
        if key not in {p.key for p in params}:
            gr.fail("key", f"one of the [parameters] keys ({', '.join(p.key for p in params)}), got {key!r}")
        ladder = gr.get("spp", list, [1, 4, 16], expected="a list of positive integers")
        if not ladder or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in ladder):
            gr.fail("spp", f"a non-empty list of positive integers, got {ladder!r}")
        samplers = gr.get("samplers", list, list(DEFAULT_SAMPLERS), expected="a list of sampler plugin names")
        if not samplers or not all(isinstance(s, str) for s in samplers):
            gr.fail("samplers", f"a non-empty list of sampler plugin names, got {samplers!r}")
        seeds = gr.get("seeds", int, 16, check=lambda v: v >= 2, expected="an integer >= 2 (variance needs two)")
        ref_spp = gr.get("reference_spp", int, 1024, check=_positive, expected="a positive integer")
        ref_seeds = gr.get("reference_seeds", int, 4, check=_positive, expected="a positive integer")
        gradients = GradientSpec(key, tuple(sorted(set(ladder))), tuple(dict.fromkeys(samplers)), seeds,
                                 ref_spp, ref_seeds)
    return InverseConfig(name=name, source=source, output=output, scene_path=scene_path, builtin=builtin,
                         resolution=resolution, texture_size=texture_size, defaults=defaults,
                         max_depth=max_depth, spp=spp, target_spp=target_spp, seed=seed,
                         iterations=iterations, learning_rate=learning_rate, loss=loss, eval_spp=eval_spp,
                         params=tuple(params), gradients=gradients, optimise="optimise" in data)

