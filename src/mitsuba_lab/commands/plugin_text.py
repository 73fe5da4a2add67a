"""Text of the lab plugins read without importing them: a declared parameter's type,
default and allowed values (``plugins/params.py``), and each plugin's docstring (parsed from
its source, so no Mitsuba variant is needed)."""
from __future__ import annotations

import ast
import os
import re

TYPE_NAMES = {int: "int", float: "float", bool: "bool", str: "string"}
_MONOSP = re.compile(r"\s*\(:monosp:`[^`]*`\)\s*$")


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
