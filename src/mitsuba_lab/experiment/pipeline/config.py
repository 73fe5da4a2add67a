"""Sweep configuration: a TOML file, validated into frozen dataclasses.

Every error names the file, the key path and what was expected, in one line
(``ConfigError`` is a ``LabError``: the CLI prints it and exits with 2).
The schema is documented in experiments/README.md.
"""
from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field

from ...errors import LabError
from ...features import DEFAULT_REFERENCES
from ...film import RESOLUTION_EXPECTED, as_resolution, is_resolution

OPTIONAL_METRICS = ("flip", "ciede2000")


class _PassParameters(Mapping):
    """{integrator type: the parameter a sweep's sample count sets} for the integrators that a
    sweep scales by passes instead of samples per pixel: a point's sample count N renders N
    passes of one camera sample per pixel each (so N camera samples per pixel in all, as for
    every other strategy). Each lab integrator says so itself (``SAMPLE_COUNT_PARAMETER`` of
    its estimator class, e.g. lab_photon's ``passes``); read on first use, without a Mitsuba
    variant."""

    def _table(self) -> dict[str, str]:
        from ...plugins.integrators.estimator import sample_count_parameters

        return sample_count_parameters()

    def __getitem__(self, plugin_type: str) -> str:
        return self._table()[plugin_type]

    def __iter__(self):
        return iter(self._table())

    def __len__(self) -> int:
        return len(self._table())

    def __repr__(self) -> str:
        return repr(self._table())


PASS_PARAMETER = _PassParameters()
#: ``[experiment] progressive`` when a config leaves it out: strategies that can accumulate render
#: one progressive run per seed (plan.ladder_passes, experiment/execution/progressive.py), not one render
#: per spp (measured on the quick and veach_mis sweeps: the same MSE at each spp, fewer render
#: seconds, more curve points; experiments/README.md).
DEFAULT_PROGRESSIVE = True
#: ``[experiment] checkpoints``: where a progressive run's passes end (plan.ladder_passes).
CHECKPOINTS = ("doubling", "ladder")
DEFAULT_CACHE = os.path.join("~", ".cache", "mitsuba_lab", "references")


class ConfigError(LabError):
    pass


@dataclass(frozen=True)
class PluginSpec:
    """A named plugin: Mitsuba type plus its parameters (strategies, samplers, reference)."""
    name: str
    type: str
    params: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"type": self.type, **self.params}


@dataclass(frozen=True)
class ReferenceSpec:
    integrator: PluginSpec
    spp: int
    chunks: int
    cache: str                      # folder, absolute
    named: bool = True              # False: no config table names the integrator; the sweep picks one
                                    # that renders every feature of the scene (reference_choice.py)


@dataclass(frozen=True)
class SceneSpec:
    name: str
    path: str                       # absolute
    resolution: int | tuple[int, int] | None    # film override (``film``): the larger side, or
                                                # (width, height); None keeps the scene's
    defaults: dict                  # values for the scene's <default> parameters
    regions: dict                   # name -> (x0, y0, x1, y1): pixels (ints) or fractions (floats)
    reference: ReferenceSpec | None = None      # [scenes.X.reference]; None: the experiment's


@dataclass(frozen=True)
class StrategyGridSpec:
    """``[report.strategy_grid]``: lab_bdpt's per-strategy (s, t) images of one scene for path
    lengths k = 1..max_length (``strategy_grid``)."""
    scene: str                      # a [scenes] name
    strategy: str                   # a [strategies] name of type lab_bdpt
    max_length: int                 # K: rows k = 1..K; the grid renders with max_depth = K
    spp: int
    resolution: int | tuple[int, int] | None    # film override (``film``), or None for the scene's


@dataclass(frozen=True)
class Config:
    name: str
    source: str
    output: str
    scenes: tuple[SceneSpec, ...]
    strategies: tuple[PluginSpec, ...]
    samplers: tuple[PluginSpec, ...]
    spp: tuple[int, ...]
    time_budgets: tuple[float, ...]
    repetitions: int
    seed: int
    max_depth: int | None
    reference: ReferenceSpec
    metrics: tuple[str, ...]
    cluster: str | None = None      # Dask scheduler address; None = run in this process
    strategy_grid: StrategyGridSpec | None = None
    progressive: bool = DEFAULT_PROGRESSIVE     # one accumulating render per seed (experiment.progressive)
    checkpoints: str = "doubling"   # progressive passes: "doubling" or "ladder" (plan.ladder_passes)
    allow_unsupported: tuple[str, ...] = ()     # strategies that run (marked) where they ignore
                                                # part of a scene, instead of being left out

    def reference_for(self, scene: SceneSpec) -> ReferenceSpec:
        """The reference ``scene`` is measured against: its own table, else the experiment's."""
        return scene.reference or self.reference


class TableReader:
    """Typed access to one TOML table, with the key path for messages."""

    def __init__(self, source: str, table: dict, path: str):
        self.source, self.table, self.path = source, table, path
        if not isinstance(table, dict):
            self.fail("", f"a table, got {type(table).__name__}")

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, expected: str):
        where = self.key(name) if name else (self.path or "top level")
        raise ConfigError(f"{self.source}: {where}: expected {expected}")

    def get(self, name, kind, default=..., check=None, expected=None):
        if name not in self.table:
            if default is ...:
                self.fail(name, f"{expected or kind.__name__} (missing)")
            return default
        value = self.table[name]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            self.fail(name, f"{expected or kind.__name__}, got {value!r}")
        if check is not None and not check(value):
            self.fail(name, f"{expected}, got {value!r}")
        return value

    def sub(self, name, default=...) -> "TableReader":
        value = self.get(name, dict, default, expected="a table")
        return TableReader(self.source, value, self.key(name))

    def unknown(self, allowed):
        extra = sorted(set(self.table) - set(allowed))
        if extra:
            self.fail(extra[0], f"one of the keys {', '.join(sorted(allowed))} (unknown key)")


def _plugins(reader: TableReader, kind: str) -> tuple[PluginSpec, ...]:
    specs = []
    for name, body in reader.table.items():
        item = TableReader(reader.source, body, reader.key(name))
        plugin_type = item.get("type", str, expected=f"the {kind} plugin name as a string")
        params = {k: v for k, v in body.items() if k != "type"}
        specs.append(PluginSpec(name, plugin_type, params))
    if not specs:
        reader.fail("", f"at least one {kind}")
    return tuple(specs)


def _check_pass_parameters(reader: TableReader, specs: tuple[PluginSpec, ...]) -> None:
    """A pass-scaled strategy must leave its pass count to the sweep (PASS_PARAMETER)."""
    for spec in specs:
        name = PASS_PARAMETER.get(spec.type)
        if name in spec.params:
            reader.sub(spec.name).fail(name, f"no '{name}' key: the sweep sets {spec.type}'s {name} from "
                                             "the spp ladder or the time budget (one camera sample per "
                                             "pixel per pass)")


def sample_count_plugin(spec: PluginSpec, count: int) -> tuple[PluginSpec, int]:
    """(plugin, render spp) that give ``count`` camera samples per pixel: ``count`` spp, or for
    a pass-scaled integrator (PASS_PARAMETER) ``count`` passes of 1 spp, or, when the plugin
    sets its pass count P itself (``render`` allows it, sweeps do not), P passes of count / P."""
    name = PASS_PARAMETER.get(spec.type)
    if name is None:
        return spec, count
    passes = spec.params.get(name, count)
    if not isinstance(passes, int) or isinstance(passes, bool) or passes < 1 or count % passes:
        raise LabError(f"{spec.type}: {count} camera samples per pixel is not a multiple of "
                       f"{name} = {passes!r}")
    return PluginSpec(spec.name, spec.type, {**spec.params, name: passes}), count // passes


def _positive_ints(reader: TableReader, name: str, default) -> tuple[int, ...]:
    values = reader.get(name, list, default, expected="a list of positive integers")
    if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in values):
        reader.fail(name, f"a list of positive integers, got {values!r}")
    return tuple(sorted(set(values)))


def _rect(reader: TableReader, name: str, value) -> tuple:
    ok = (isinstance(value, list) and len(value) == 4
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value))
    if ok:
        is_fraction = any(isinstance(v, float) for v in value)
        ok = value[0] < value[2] and value[1] < value[3] and min(value) >= 0
        ok = ok and (not is_fraction or max(value) <= 1.0)
    if not ok:
        reader.fail(name, "[x0, y0, x1, y1] with x0 < x1, y0 < y1: pixels (integers) or fractions "
                          f"of the image (floats in [0, 1]), got {value!r}")
    return tuple(value)


def _regions(reader: TableReader, base_dir: str) -> dict:
    regions = {}
    regions_file = reader.get("regions_file", str, None)
    if regions_file is not None:
        path = os.path.join(base_dir, regions_file)
        if not os.path.isfile(path):
            reader.fail("regions_file", f"an existing TOML file, but {path} does not exist")
        with open(path, "rb") as f:
            try:
                data = tomllib.load(f)
            except tomllib.TOMLDecodeError as err:
                raise ConfigError(f"{path}: {err}") from err
        file_reader = TableReader(path, data.get("regions", {}), "regions")
        for name, rect in file_reader.table.items():
            regions[name] = _rect(file_reader, name, rect)
    inline = reader.sub("regions", {})
    for name, rect in inline.table.items():
        regions[name] = _rect(inline, name, rect)
    return regions


def read_resolution(reader: TableReader, default=None):
    """A table's ``resolution`` key: the film's larger side (aspect ratio kept) or [width, height]
    (``film``); ``default`` when absent."""
    return as_resolution(reader.get("resolution", object, default, check=is_resolution,
                                    expected=RESOLUTION_EXPECTED))


def _scenes(reader: TableReader, base_dir: str, reference: ReferenceSpec) -> tuple[SceneSpec, ...]:
    """``[scenes]``; a scene's own ``reference`` table (integrator, spp, chunks) replaces what it
    names of ``reference`` (``[reference]``), for a hard region that needs a lower noise floor."""
    scenes = []
    for name, _ in reader.table.items():
        item = reader.sub(name)
        item.unknown({"path", "resolution", "defaults", "regions", "regions_file", "reference"})
        rel = item.get("path", str, expected="the scene's XML path (relative to the config file)")
        path = os.path.normpath(os.path.join(base_dir, rel))
        if not os.path.isfile(path):
            item.fail("path", f"an existing scene file, but {path} does not exist")
        resolution = read_resolution(item)
        defaults = item.sub("defaults", {}).table
        own = None
        if "reference" in item.table:
            table = item.sub("reference")
            table.unknown({"integrator", "spp", "chunks"})
            own = _reference(table, reference)
        scenes.append(SceneSpec(name, path, resolution, dict(defaults), _regions(item, base_dir), own))
    if not scenes:
        reader.fail("", "at least one scene")
    return tuple(scenes)


#: Longest path length a strategy grid may show: K (K + 3) / 2 strategy renders (each compiles its own
#: kernel) and the full image.
GRID_MAX_LENGTH = 8
GRID_INTEGRATOR = "lab_bdpt"


def _strategy_grid(reader: TableReader, scenes, strategies) -> StrategyGridSpec | None:
    """``[report.strategy_grid]``, checked against the config's scenes and strategies."""
    if "strategy_grid" not in reader.table:
        return None
    grid = reader.sub("strategy_grid")
    grid.unknown({"scene", "strategy", "max_length", "spp", "resolution"})
    names = ", ".join(s.name for s in scenes)
    scene = grid.get("scene", str, check=lambda v: v in {s.name for s in scenes},
                     expected=f"the name of a [scenes] table ({names})")
    bdpt = [s.name for s in strategies if s.type == GRID_INTEGRATOR]
    strategy = grid.get("strategy", str, check=lambda v: v in bdpt,
                        expected=f"the name of a [strategies] entry of type {GRID_INTEGRATOR} "
                                 f"({', '.join(bdpt) or 'the config has none'})")
    spec = next(s for s in strategies if s.name == strategy)
    if "only_strategy" in spec.params:
        grid.fail("strategy", f"a {GRID_INTEGRATOR} strategy without 'only_strategy' (the grid sets it per "
                              f"image), but strategies.{strategy} sets it")
    max_length = grid.get("max_length", int, check=lambda v: 1 <= v <= GRID_MAX_LENGTH,
                          expected=f"an integer in [1, {GRID_MAX_LENGTH}] (rows k = 1..max_length)")
    spp = grid.get("spp", int, 64, check=lambda v: v > 0, expected="a positive integer")
    resolution = read_resolution(grid)
    return StrategyGridSpec(scene, strategy, max_length, spp, resolution)


def read_toml(path: str) -> dict:
    """A TOML file's tables, or ConfigError naming the file and what is wrong."""
    if not os.path.isfile(path):
        raise ConfigError(f"config file not found: {path}")
    with open(path, "rb") as f:
        try:
            return tomllib.load(f)
        except tomllib.TOMLDecodeError as err:
            raise ConfigError(f"{path}: not valid TOML: {err}") from err


#: How messages name a config given as a dict (``mitsuba_lab.sweep({...})``).
DICT_SOURCE = "config dict"


def load_config(source) -> Config:
    """Read and validate a sweep configuration (see experiments/README.md): the path of a TOML
    file, or a dict of the same tables (``load_config_dict``)."""
    if isinstance(source, Mapping):
        return load_config_dict(source)
    if not isinstance(source, (str, os.PathLike)):
        raise ConfigError("a sweep config is the path of a TOML file or a dict of its tables, got "
                          f"{type(source).__name__}")
    path = os.fspath(source)
    return parse_config(read_toml(path), path)


def _plain(value):
    """A dict config as TOML would have given it: mappings as dicts, tuples as lists, paths as str."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value


def load_config_dict(data: Mapping, source: str = DICT_SOURCE) -> Config:
    """Validate a configuration given as a dict with the TOML file's tables. Relative paths in it
    (scenes, regions files) resolve against the current directory; messages name it ``source``;
    ``experiment.name`` defaults to "sweep" (so the output folder to out/sweep)."""
    return parse_config(_plain(data), source, base_dir=os.getcwd())


def parse_config(data: dict, source: str, base_dir: str | None = None) -> Config:
    """``data`` (a TOML file's tables) validated. ``source`` names it in messages; it is the
    file's path unless ``base_dir`` is given, the folder relative paths resolve against (by
    default the file's folder), in which case it is only a label."""
    from_file = base_dir is None
    base_dir = os.path.dirname(os.path.abspath(source)) if from_file else base_dir
    top = TableReader(source, data, "")
    top.unknown({"experiment", "reference", "scenes", "strategies", "samplers", "executor", "report"})
    exp = top.sub("experiment", {})
    exp.unknown({"name", "output", "spp", "time_budgets", "repetitions", "seed", "max_depth", "metrics",
                 "progressive", "checkpoints", "allow_unsupported"})
    name = exp.get("name", str, os.path.splitext(os.path.basename(source))[0] if from_file else "sweep")
    output = exp.get("output", str, os.path.join("out", name))
    spp = _positive_ints(exp, "spp", [])
    budgets = exp.get("time_budgets", list, [], expected="a list of positive numbers (seconds)")
    if not all(isinstance(b, (int, float)) and not isinstance(b, bool) and b > 0 for b in budgets):
        exp.fail("time_budgets", f"a list of positive numbers (seconds), got {budgets!r}")
    if not spp and not budgets:
        exp.fail("spp", "an spp ladder (e.g. spp = [4, 16, 64]) and/or time_budgets (missing both)")
    repetitions = exp.get("repetitions", int, 4, check=lambda v: v >= 2,
                          expected="an integer >= 2 (variance across seeds needs two)")
    seed = exp.get("seed", int, 0, check=lambda v: 0 <= v < 2 ** 20, expected="an integer in [0, 2^20)")
    max_depth = exp.get("max_depth", int, None, check=lambda v: v == -1 or v >= 1,
                        expected="-1 (unbounded) or an integer >= 1")
    progressive = exp.get("progressive", bool, DEFAULT_PROGRESSIVE,
                          expected="true (one accumulating render per seed) or false (one render per spp)")
    checkpoints = exp.get("checkpoints", str, CHECKPOINTS[0], check=lambda v: v in CHECKPOINTS,
                          expected='"doubling" (passes P, P, 2P, 4P, ...) or "ladder" (passes end at the '
                                   'spp ladder\'s values only)')
    metrics = exp.get("metrics", list, list(OPTIONAL_METRICS),
                      expected=f"a list drawn from {', '.join(OPTIONAL_METRICS)}")
    if not all(m in OPTIONAL_METRICS for m in metrics):
        exp.fail("metrics", f"a list drawn from {', '.join(OPTIONAL_METRICS)} (MSE and relMSE are "
                            f"always computed), got {metrics!r}")

    ref = top.sub("reference", {})
    ref.unknown({"integrator", "spp", "chunks", "cache"})
    cache = os.path.abspath(os.path.expanduser(os.environ.get("MITSUBA_LAB_CACHE") or
                                               ref.get("cache", str, DEFAULT_CACHE)))
    reference = _reference(ref, ReferenceSpec(PluginSpec("integrator", DEFAULT_REFERENCES[0]), 4096, 8, cache, False))

    executor = top.sub("executor", {})
    executor.unknown({"cluster"})
    cluster = executor.get("cluster", str, None, check=lambda v: "://" in v,
                           expected='a Dask scheduler address such as "tcp://host:8786"')

    scenes = _scenes(top.sub("scenes"), base_dir, reference)
    strategies = _plugins(top.sub("strategies"), "integrator")
    _check_pass_parameters(top.sub("strategies"), strategies)
    samplers = _plugins(top.sub("samplers"), "sampler") if "samplers" in data else \
        (PluginSpec("independent", "independent", {}),)
    report = top.sub("report", {})
    report.unknown({"strategy_grid"})
    grid = _strategy_grid(report, scenes, strategies)
    allowed = _allowed(exp, strategies)
    return Config(name=name, source=os.path.abspath(source) if from_file else source, output=output, scenes=scenes,
                  strategies=strategies, samplers=samplers, spp=spp,
                  time_budgets=tuple(sorted(set(float(b) for b in budgets))), repetitions=repetitions,
                  seed=seed, max_depth=max_depth,
                  reference=reference, metrics=tuple(metrics),
                  cluster=cluster, strategy_grid=grid, progressive=progressive,
                  checkpoints=checkpoints, allow_unsupported=allowed)


def _allowed(exp: TableReader, strategies: tuple[PluginSpec, ...]) -> tuple[str, ...]:
    """``experiment.allow_unsupported``: names of [strategies] that run, marked in the report, on
    a scene they cannot render correctly (as ``render --allow-unsupported``), instead of being left
    out."""
    names = [s.name for s in strategies]
    expected = f"a list of [strategies] names ({', '.join(names)})"
    value = exp.get("allow_unsupported", list, [], expected=expected)
    if not all(isinstance(v, str) and v in names for v in value):
        exp.fail("allow_unsupported", f"{expected}, got {value!r}")
    return tuple(dict.fromkeys(value))


def _reference(ref: TableReader, default: ReferenceSpec) -> ReferenceSpec:
    """``[reference]`` (or a scene's ``reference`` table; its cache is the experiment's): what
    it leaves out is ``default``'s."""
    integrator = ref.get("integrator", dict, None, expected="a table like { type = \"path\" }")
    plugin = default.integrator if integrator is None else \
        _plugins(TableReader(ref.source, {"integrator": integrator}, ref.path), "integrator")[0]
    spp = ref.get("spp", int, default.spp, check=lambda v: v > 0, expected="a positive integer")
    chunks = ref.get("chunks", int, default.chunks, check=lambda v: v >= 2 and spp % v == 0,
                     expected=f"an integer >= 2 that divides {ref.key('spp')} = {spp} (the noise "
                              "floor needs two equal chunks)")
    return ReferenceSpec(plugin, spp, chunks, default.cache, default.named or integrator is not None)


def with_depth(spec: PluginSpec, max_depth: int | None) -> PluginSpec:
    """The experiment-wide max_depth applies unless the plugin sets its own."""
    if max_depth is None or "max_depth" in spec.params:
        return spec
    return PluginSpec(spec.name, spec.type, {**spec.params, "max_depth": max_depth})
