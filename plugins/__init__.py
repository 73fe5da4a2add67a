"""The lab's Mitsuba plugins, installed as ``mitsuba_lab.plugins``.

Every module of this package is found by walking its folder (nothing is listed by hand)
and read without being imported, to learn which package modules it imports when it runs
(``import`` statements outside function bodies) and whether it registers plugins
(``mi.register_integrator`` / ``mi.register_sampler`` at module level).

Mitsuba classes bind to a variant when a Python class deriving from one is defined, so a
module that imports ``mitsuba``, or a module that imports one that does, is *variant-bound*:
``register_all`` runs it again after a variant switch, dependencies first (a reload replaces
the module's globals in place, so its registrations and classes are rebuilt for the new
variant in step). The other modules (``params``, the estimators' knowledge, the MIS weight)
import no Mitsuba variant: they are imported once, never re-run, and can be used before any
variant is set (``import_variant_free``).
"""
from __future__ import annotations

import ast
import functools
import importlib
import os
import sys

_module_variant: dict[str, str] = {}


def _module_names() -> dict[str, str]:
    """Module name -> file, for every module of this package (itself excluded)."""
    root = os.path.dirname(os.path.abspath(__file__))
    found = {}
    for here, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__" and os.path.isfile(os.path.join(here, d, "__init__.py")))
        rel = os.path.relpath(here, root)
        parts = [__name__] + ([] if rel == "." else rel.split(os.sep))
        for name in sorted(f for f in files if f.endswith(".py")):
            stem = name[:-3]
            module = ".".join(parts if stem == "__init__" else parts + [stem])
            if module != __name__:
                found[module] = os.path.join(here, name)
    return found


def _runtime_statements(tree: ast.Module):
    """The statements that run when the module is imported (function bodies left out)."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        yield node
        stack.extend(ast.iter_child_nodes(node))


def _scan(name: str, path: str, modules) -> tuple[set[str], bool, bool]:
    """(package modules imported, imports mitsuba, registers plugins) of one module's source."""
    with open(path, encoding="utf-8") as handle:
        tree = ast.parse(handle.read(), path)
    package = name if path.endswith("__init__.py") else name.rpartition(".")[0]
    imports, mitsuba, registers = set(), False, False
    for node in _runtime_statements(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{anchor}.{base}" if base else anchor
            targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
        else:
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr in ("register_integrator", "register_sampler")):
                registers = True
            continue
        mitsuba = mitsuba or any(t == "mitsuba" or t.startswith("mitsuba.") for t in targets)
        imports.update(t for t in targets if t in modules and t != name)
    return imports, mitsuba, registers


@functools.lru_cache(maxsize=1)
def _plan() -> tuple[tuple[str, ...], frozenset[str], tuple[str, ...]]:
    """(every module, dependencies first; the variant-bound ones; those that register plugins)."""
    files = _module_names()
    scanned = {name: _scan(name, path, files) for name, path in files.items()}
    order: list[str] = []
    seen: set[str] = set()

    def visit(name):
        if name in seen:
            return
        seen.add(name)
        for dependency in sorted(scanned[name][0]):
            visit(dependency)
        order.append(name)

    for name in sorted(scanned):
        visit(name)
    bound: set[str] = set()
    for name in order:                   # dependencies come first, so one pass settles it
        imports, mitsuba, _ = scanned[name]
        if mitsuba or imports & bound:
            bound.add(name)
    registering = tuple(name for name in order if scanned[name][2])
    return tuple(order), frozenset(bound), registering


def __getattr__(name: str):
    """``PLUGIN_MODULES``: every module that registers plugins, in registration order (found
    by ``_plan`` on first use, so importing ``params`` alone reads no source)."""
    if name == "PLUGIN_MODULES":
        return _plan()[2]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def import_variant_free() -> None:
    """Import every module that needs no Mitsuba variant (estimator classes register
    themselves as they are defined); safe to call again, and before any variant is set."""
    order, bound, _ = _plan()
    for name in order:
        if name not in bound and name not in sys.modules:
            importlib.import_module(name)


def register_all() -> list[str]:
    """Register every lab plugin for the current variant; safe to call again."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError("set a Mitsuba variant before registering the lab plugins")
    order, bound, registering = _plan()
    for name in order:
        module = sys.modules.get(name)
        if module is None:
            importlib.import_module(name)
        elif name in bound and _module_variant.get(name) != variant:
            importlib.reload(module)
        if name in bound:
            _module_variant[name] = variant
    return list(registering)
