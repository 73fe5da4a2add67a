"""``mitsuba-lab plugins [NAME]``: the lab's plugins and their declared parameters.

Reads the declarations (``plugins/params.py``) and the plugins' docstrings (parsed from
their source, not imported), so it needs no Mitsuba variant. The helpers that turn a
``Param`` into text (``plugin_text``, and ``parameter_help`` here) also write ``render``'s option help.
"""
from __future__ import annotations

import difflib
import os

from ..plugins import params as declarations
from .plugin_reference import REFERENCE_NAME, write_reference
from .plugin_text import allowed_text, default_text, summaries, type_name


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
