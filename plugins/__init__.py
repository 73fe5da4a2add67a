"""The lab's Mitsuba plugins, installed as ``mitsuba_lab.plugins``.

The package's modules are listed below by hand, in the order they are imported (as Mitsuba
lists its own Python integrators in ``mitsuba/python/ad/integrators/__init__.py``);
``tests/test_layout.py`` checks that the list names every module once, after every package
module it imports, and that the two groups below are what the sources say.

Mitsuba classes bind to a variant when a Python class deriving from one is defined, so a
module that imports ``mitsuba``, or a module that imports one that does, is *variant-bound*:
``register_all`` runs it again after a variant switch, in list order, so dependencies first (a
reload replaces the module's globals in place, so its registrations and classes are rebuilt
for the new variant in step). The other modules (``params``, the estimators' knowledge, the
MIS weight) import no Mitsuba variant: they are imported once, never re-run, and can be used
before any variant is set (``import_variant_free``).
"""
from __future__ import annotations

import importlib
import sys

#: Every module of the package but itself, each after the package modules it imports.
_ORDER = (
    "integrators", "integrators.common", "integrators.bdpt", "integrators.photon",
    "integrators.vcm", "integrators.mlt", "samplers",
    # needing no variant
    "integrators.bdpt.techniques", "param_types", "params", "param_docs", "variant", "interrupts", "integrators.estimator", "integrators.common.kernels",
    "integrators.common.mis_weight", "integrators.naive", "integrators.nee", "integrators.mis",
    "integrators.photon.estimator", "integrators.bdpt.recursion", "integrators.bdpt.weights", "integrators.bdpt.estimator",
    "integrators.vcm.estimator", "integrators.vcm.selection", "integrators.mlt.estimator",
    # variant-bound: what the plugins share
    "scene_traits", "samplers.layout", "integrators.common.spectral",
    "integrators.common.adjoint", "integrators.common.counters", "integrators.common.roulette",
    "integrators.common.spawn", "integrators.common.direct", "integrators.common.aim",
    "integrators.common.support", "integrators.common.footprint", "integrators.common.density_radius",
    "integrators.common.grid",
    "integrators.common.majorants", "integrators.common.media", "integrators.common.equiangular",
    "integrators.common.subpath_media",
    # the path tracers
    "integrators.path",
    # lab_photon
    "integrators.photon.records", "integrators.photon.grid", "integrators.photon.estimates",
    "integrators.photon.media_camera", "integrators.photon.gather",
    "integrators.photon.tracer", "integrators.photon.integrator",
    # lab_bdpt, then lab_vcm on it
    "integrators.bdpt.endpoints", "integrators.bdpt.splats", "integrators.bdpt.vertices",
    "integrators.bdpt.camera_flight", "integrators.bdpt.media_connections", "integrators.bdpt.media_paths",
    "integrators.bdpt.light_subpath", "integrators.bdpt.camera_subpath", "integrators.bdpt.passes",
    "integrators.bdpt.integrator",
    "integrators.vcm.merging", "integrators.vcm.volume_merging", "integrators.vcm.pilot", "integrators.vcm.integrator",
    # the samplers
    "samplers.common", "samplers.halton", "samplers.independent", "samplers.sobol",
    "samplers.stratified", "samplers.zsobol",
    # lab_pssmlt (its chains read numbers through samplers.common's hash)
    "integrators.mlt.chain", "integrators.mlt.frozen", "integrators.mlt.sampler", "integrators.mlt.integrator",
    # lab_mmlt: lab_pssmlt's chains over lab_bdpt's subpaths
    "integrators.mlt.mmlt",
)
#: The modules of ``_ORDER`` that import no Mitsuba variant, not even through another module.
_VARIANT_FREE = frozenset(_ORDER[:_ORDER.index("scene_traits")])
#: The modules that register plugins (``mi.register_integrator`` / ``mi.register_sampler``).
_REGISTERING = ("integrators.path", "integrators.photon.integrator", "integrators.bdpt.integrator",
                "integrators.vcm.integrator", "integrators.mlt.integrator", "integrators.mlt.mmlt", "samplers.halton", "samplers.independent",
                "samplers.sobol", "samplers.stratified", "samplers.zsobol")

#: Every module of the package (full names), in import order.
MODULES = tuple(f"{__name__}.{name}" for name in _ORDER)
#: The modules that need no Mitsuba variant (full names).
VARIANT_FREE = frozenset(f"{__name__}.{name}" for name in _VARIANT_FREE)
#: Every module that registers plugins (full names), in registration order.
PLUGIN_MODULES = tuple(f"{__name__}.{name}" for name in _REGISTERING)

_module_variant: dict[str, str] = {}


def import_variant_free() -> None:
    """Import every module that needs no Mitsuba variant (estimator classes register
    themselves as they are defined); safe to call again, and before any variant is set."""
    for name in MODULES:
        if name in VARIANT_FREE and name not in sys.modules:
            importlib.import_module(name)


def register_all() -> list[str]:
    """Register every lab plugin for the current variant; safe to call again."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError("set a Mitsuba variant before registering the lab plugins")
    for name in MODULES:
        module = sys.modules.get(name)
        if module is None:
            importlib.import_module(name)
        elif name not in VARIANT_FREE and _module_variant.get(name) != variant:
            importlib.reload(module)
        if name not in VARIANT_FREE:
            _module_variant[name] = variant
    return list(PLUGIN_MODULES)
