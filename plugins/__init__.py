"""The lab's Mitsuba plugins, installed as ``mitsuba_lab.plugins``.

Each plugin module registers itself on its last line for the variant that is
active when the module runs. Mitsuba classes bind to a variant when a Python
class is defined, so after a variant switch the modules are executed again
(a reload replaces the module's globals in place, so registrations made for an
earlier variant would build the new variant's classes: re-running on every
switch keeps the registration and the classes in step).

``params`` (every plugin's declared parameters, ``resolve``) imports no Mitsuba
variant and holds no variant-bound class, so it is neither a plugin nor a helper
module here: it is imported once and never re-run.
"""
from __future__ import annotations

import importlib
import sys

#: Every plugin module, in registration order (shared helpers first).
PLUGIN_MODULES = (
    "mitsuba_lab.plugins.integrators.naive",
    "mitsuba_lab.plugins.integrators.nee",
    "mitsuba_lab.plugins.integrators.mis",
    "mitsuba_lab.plugins.integrators.photon.integrator",
    "mitsuba_lab.plugins.samplers.independent",
    "mitsuba_lab.plugins.samplers.stratified",
    "mitsuba_lab.plugins.samplers.halton",
    "mitsuba_lab.plugins.samplers.sobol",
    "mitsuba_lab.plugins.samplers.zsobol",
)

#: Modules that plugin classes derive from; re-run before the plugins on a switch.
HELPER_MODULES = (
    "mitsuba_lab.plugins.integrators.common",
    "mitsuba_lab.plugins.integrators.photon.gather",
    "mitsuba_lab.plugins.samplers.common",
)

_module_variant: dict[str, str] = {}


def register_all() -> list[str]:
    """Register every lab plugin for the current variant; safe to call again."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError("set a Mitsuba variant before registering the lab plugins")
    for name in HELPER_MODULES + PLUGIN_MODULES:
        module = sys.modules.get(name)
        if module is None:
            importlib.import_module(name)
        elif _module_variant.get(name) != variant:
            importlib.reload(module)
        _module_variant[name] = variant
    return list(PLUGIN_MODULES)
