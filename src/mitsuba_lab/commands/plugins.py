"""``mitsuba-lab plugins [NAME]``: the lab's plugins and their declared parameters.

Reads the declarations (``plugins/params.py``) and the plugins' docstrings (parsed from
their source, not imported), so it needs no Mitsuba variant. The helpers that turn a
``Param`` into text (``type_name``, ``default_text``, ``allowed_text``,
``parameter_help``) also write ``render``'s option help.
"""
from __future__ import annotations

import ast
import difflib
import os
import re

from ..plugins import params as declarations

TYPE_NAMES = {int: "int", float: "float", bool: "bool", str: "string"}
_MONOSP = re.compile(r"\s*\(:monosp:`[^`]*`\)\s*$")
#: The generated plugin reference, in the plugins' folder.
REFERENCE_NAME = "README.md"


def add_arguments(parser) -> None:
    parser.description = ("List the lab's integrators and samplers (name, kind, what it is), or with "
                          "NAME print that plugin's parameters as declared: type, default, allowed "
                          "values and meaning. Needs no Mitsuba variant.")
    parser.add_argument("name", nargs="?", metavar="NAME",
                        help="a lab plugin, e.g. lab_mis (default: list them all)")
    parser.add_argument("--markdown", action="store_true",
                        help=f"write the plugin reference ({REFERENCE_NAME} beside the plugins: every "
                             f"plugin's description and parameter table) from the declarations and docstrings")


def run(args, out) -> int:
    if args.markdown:
        from ..errors import LabError
        from .plugin_reference import write_reference

        if args.name is not None:
            raise LabError("plugins --markdown writes the reference of every plugin: give no NAME")
        path = write_reference()
        print(f"wrote {os.path.relpath(path)} ({len(declarations.lab_plugins())} plugins)", file=out)
    elif args.name is None:
        print(format_list(), file=out)
    else:
        print(format_plugin(args.name), file=out)
    return 0


# -- Text of a declared parameter ---------------------------------------------------------------

def type_name(param) -> str:
    return TYPE_NAMES.get(param.kind, getattr(param.kind, "__name__", str(param.kind)))


def show(value) -> str:
    """A default as a user writes it: true/false, 2 not 2.0, 0.666667, strings bare."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def default_text(param) -> str:
    return show(param.default)


def allowed_text(param) -> str:
    """The values the parameter takes: its choices, its constraint, or its type."""
    if param.choices:
        return " | ".join(param.choices)
    if param.expected:
        return param.expected
    return {int: "an integer", float: "a number", bool: "true | false", str: "a string"}.get(
        param.kind, type_name(param))


def parameter_help(name: str, plugins: tuple[str, ...]) -> str:
    """Help text for an option setting parameter ``name`` of the given ``plugins``: the
    declared meaning, then allowed values and default per group of plugins that agree."""
    holders = [(plugin, p) for plugin in plugins for p in declarations.declared(plugin) or ()
               if p.name == name]
    if not holders:
        raise KeyError(f"no lab plugin among {', '.join(plugins)} declares '{name}'")
    groups: dict[tuple[str, str], list[str]] = {}
    for plugin, p in holders:
        groups.setdefault((allowed_text(p), default_text(p)), []).append(plugin)
    parts = []
    for (allowed, default), names in groups.items():
        if len(groups) == 1 and len(names) == len(plugins):
            label = ""
        elif len(groups) == 1 and len(names) == 1:
            label = f"{names[0]} only: "
        else:
            label = f"{', '.join(names)}: "
        parts.append(f"{label}{allowed} (default: {default})")
    return f"{holders[0][1].doc}; {'; '.join(parts)}".replace("%", "%%")


def lab_integrators() -> tuple[str, ...]:
    return tuple(p for p in declarations.lab_plugins() if declarations.plugin_kind(p) == "integrator")


# -- Listing ----------------------------------------------------------------------------------

def summaries() -> dict[str, str]:
    """Plugin name -> first line of its class docstring (else its module docstring), read
    from the plugin sources named by ``plugins.PLUGIN_MODULES`` without importing them."""
    return {name: _MONOSP.sub("", doc.strip().splitlines()[0]).rstrip(".") if doc.strip() else ""
            for name, doc in docstrings().items()}


def docstrings() -> dict[str, str]:
    """Plugin name -> its class docstring (else its module docstring), read from the plugin
    sources named by ``plugins.PLUGIN_MODULES`` without importing them."""
    from .. import plugins as package

    root = package.__path__[0]
    found = {}
    for module in package.PLUGIN_MODULES:
        path = os.path.join(root, *module.removeprefix(package.__name__ + ".").split(".")) + ".py"
        try:
            with open(path, encoding="utf-8") as handle:
                tree = ast.parse(handle.read())
        except (OSError, SyntaxError):
            continue
        found.update(_registered(tree))
    return found


def _registered(tree: ast.Module) -> dict[str, str]:
    """``mi.register_*("name", lambda props: Class(props))`` -> {name: Class's docstring}."""
    classes = {node.name: ast.get_docstring(node) or "" for node in tree.body
               if isinstance(node, ast.ClassDef)}
    module_doc = (ast.get_docstring(tree) or "").split(":", 1)[-1].strip()
    found = {}
    for node in tree.body:
        call = node.value if isinstance(node, ast.Expr) else None
        if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)
                and call.func.attr in ("register_integrator", "register_sampler") and call.args
                and isinstance(call.args[0], ast.Constant)):
            continue
        doc = ""
        if len(call.args) > 1 and isinstance(call.args[1], ast.Lambda):
            body = call.args[1].body
            if isinstance(body, ast.Call) and isinstance(body.func, ast.Name):
                doc = classes.get(body.func.id, "")
        found[call.args[0].value] = doc or module_doc
    return found


def format_list() -> str:
    names = declarations.lab_plugins()
    about = summaries()
    width = max(len(n) for n in names)
    return "\n".join(f"{name:<{width}}  {declarations.plugin_kind(name):<10}  {about.get(name, '-')}".rstrip()
                     for name in names)


def format_plugin(name: str) -> str:
    from ..errors import LabError

    parameters = declarations.declared(name)
    if parameters is None:
        names = declarations.lab_plugins()
        close = difflib.get_close_matches(name, names, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise LabError(f"unknown lab plugin '{name}'{hint}; lab plugins: {', '.join(names)}")
    kind = declarations.plugin_kind(name)
    about = summaries().get(name)
    rows = [("parameter", "type", "default", "allowed", "meaning")]
    rows += [(p.name, type_name(p), default_text(p), allowed_text(p), p.doc) for p in parameters]
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    lines = [f"{name} ({kind})" + (f": {about}" if about else "")]
    lines += ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)) + "  " + row[4] for row in rows]
    base = declarations.base_parameters(name, kind)
    if base:
        lines.append(f"also accepted, read by Mitsuba's base class: {', '.join(base)}")
    return "\n".join(line.rstrip() for line in lines)
