"""Text of the lab plugins read without importing them: each plugin's docstring, parsed from
its source, so no Mitsuba variant is needed (a declared parameter's type, default and allowed
values as text are ``plugins/param_docs.py``'s, re-exported here)."""
from __future__ import annotations

import ast
import os
import re

from ..plugins.param_docs import allowed_text, default_text, show, type_name  # noqa: F401

_MONOSP = re.compile(r"\s*\(:monosp:`[^`]*`\)\s*$")


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
