"""The declared parameters as text: the tables of ``mitsuba-lab plugins``, of the generated
plugin reference (``plugins/README.md``) and of each plugin class's docstring, all written from
the declarations in ``params.py`` (so none of them can disagree with what the plugin reads).

No Mitsuba import (variant-free, as ``params``)."""
from __future__ import annotations

import inspect
import textwrap

from . import params

TYPE_NAMES = {int: "int", float: "float", bool: "bool", str: "string"}


def type_name(param: params.Param) -> str:
    return TYPE_NAMES.get(param.kind, getattr(param.kind, "__name__", str(param.kind)))


def show(value) -> str:
    """A default as a user writes it: true/false, 2 not 2.0, 0.666667, strings bare."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def default_text(param: params.Param) -> str:
    return show(param.default)


def allowed_text(param: params.Param) -> str:
    """The values the parameter takes: its choices, its constraint, or its type."""
    if param.choices:
        return " | ".join(param.choices)
    if param.expected:
        return param.expected
    return {int: "an integer", float: "a number", bool: "true | false", str: "a string"}.get(
        param.kind, type_name(param))


def rst_table(parameters: tuple[params.Param, ...], width: int = 60) -> str:
    """A reStructuredText simple table of ``parameters``: name, type, and what it means with
    its allowed values and default (as Mitsuba's plugin docstrings list their parameters)."""
    rows = [(p.name, type_name(p), f"{p.doc} ({allowed_text(p)}; default: ``{default_text(p) or 'empty'}``)")
            for p in parameters]
    name_w = max(len("parameter"), *(len(r[0]) for r in rows))
    type_w = max(len("type"), *(len(r[1]) for r in rows))
    rule = f"{'=' * name_w} {'=' * type_w} {'=' * width}"
    lines = [rule, f"{'parameter':<{name_w}} {'type':<{type_w}} meaning", rule]
    for name, kind, meaning in rows:
        wrapped = textwrap.wrap(meaning, width) or [""]
        lines.append(f"{name:<{name_w}} {kind:<{type_w}} {wrapped[0]}")
        lines += [f"{'':<{name_w}} {'':<{type_w}} {more}" for more in wrapped[1:]]
    lines.append(rule)
    return "\n".join(lines)


def documented(plugin: str):
    """Class decorator: the plugin's docstring ends with the table of its declared parameters,
    so ``help()`` in a notebook shows them; the source's docstring holds no table of its own."""
    def decorate(cls):
        doc = inspect.cleandoc(cls.__doc__ or "")
        cls.__doc__ = f"{doc}\n\nParameters (declared in ``plugins/params.py``):\n\n{rst_table(params.declared(plugin))}\n"
        return cls
    return decorate
