"""mitsuba_lab: a Monte Carlo light-transport laboratory on Mitsuba 3 and Dr.Jit.

Importing the package makes the lab plugins usable from any Mitsuba scene:
it points Dr.Jit at a usable libLLVM, selects a variant when none is set yet
(``$MITSUBA_LAB_VARIANT``, else ``llvm_ad_rgb``), and registers every ``lab_*``
integrator and sampler for that variant. With ``MITSUBA_LAB_ACTIVATE=0`` in the
environment it does none of that until ``activate`` is called: the ``mitsuba-lab``
command (``mitsuba_lab_command``) imports it so, and selects the variant after it has
read ``--variant``, so that a bad environment is reported in one line and a GPU-only
machine never has to start the LLVM backend.

``mitsuba_lab.sweep(config)`` runs a strategy sweep from Python and returns its results
table (``mitsuba_lab.experiment.api``; imported on first use).
"""
from __future__ import annotations

import os as _os

__version__ = "0.1.0"
#: Set to "0" to import the package without selecting a variant (then call ``activate``).
ACTIVATE_ENV = "MITSUBA_LAB_ACTIVATE"
__all__ = ["activate", "use_variant", "register_all", "bind_film_layout", "sweep"]


def activate(variant: str | None = None) -> str:
    """Configure libLLVM, select ``variant`` (or the default) and register the plugins.

    Keeps an already selected Mitsuba variant when ``variant`` is None.
    Raises ``LabError`` with one line when the environment cannot run it.
    """
    from .runtime import activate as _activate

    return _activate(variant)


def use_variant(name: str) -> str:
    """Switch to another Mitsuba variant and register the lab plugins for it."""
    return activate(name)


def register_all():
    from .plugins import register_all as _register_all

    return _register_all()


def bind_film_layout(scene_or_sensor, sensor=0):
    """Tell a sensor's sampler its film's shape before a plain ``mi.render`` (``lab_zsobol``
    orders pixels along a Z-curve; renders through the lab do this themselves). See
    ``mitsuba_lab.plugins.samplers.layout.bind_film_layout``."""
    from .plugins.samplers.layout import bind_film_layout as _bind

    return _bind(scene_or_sensor, sensor)


def __getattr__(name: str):
    """``mitsuba_lab.sweep`` (experiment.api.sweep), imported on first use so that importing the
    package stays cheap."""
    if name == "sweep":
        import importlib

        # (by name: the package's own modules import it, and only this attribute needs the api)
        return importlib.import_module(".experiment.api", __name__).sweep
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


if _os.environ.get(ACTIVATE_ENV) != "0":
    activate()
