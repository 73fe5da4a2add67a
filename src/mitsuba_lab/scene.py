"""Loading scenes and plugins with errors a user can act on."""
from __future__ import annotations

import os
import re

import mitsuba as mi

from .errors import LabError, one_line

LAB_INTEGRATORS = ("lab_naive", "lab_nee", "lab_mis")
#: Mitsuba's own integrators (those present in this build are listed in messages).
MITSUBA_INTEGRATORS = ("path", "direct", "volpath", "volpathmis", "ptracer", "aov", "depth",
                       "moment", "stokes", "prb", "prb_basic", "prbvolpath", "direct_projective",
                       "prb_projective")


def load_scene(path: str, **params) -> mi.Scene:
    """Load a Mitsuba XML scene; ``params`` fill its ``<default>`` values (e.g. res=64)."""
    if not os.path.isfile(path):
        raise LabError(f"scene file not found: {path}")
    try:
        return mi.load_file(path, **{k: str(v) for k, v in params.items()})
    except RuntimeError as err:
        raise LabError(f"cannot load scene {path}: {one_line(err)}") from err


def make_integrator(type_name: str, params: dict | None = None) -> mi.Integrator:
    """Instantiate an integrator plugin by name, with its parameters checked by the plugin."""
    try:
        return mi.load_dict({"type": type_name, **(params or {})})
    except RuntimeError as err:
        text = one_line(err)
        if "not found" in text and f'"{type_name}"' in text:
            raise LabError(f"unknown integrator '{type_name}'; lab integrators: "
                           f"{', '.join(LAB_INTEGRATORS)}; Mitsuba's: "
                           f"{', '.join(MITSUBA_INTEGRATORS)}") from err
        reason = plugin_error_reason(text)
        reason = reason[len(type_name) + 2:] if reason.startswith(f"{type_name}: ") else reason
        raise LabError(f"integrator '{type_name}': {reason}") from err


def plugin_error_reason(text: str) -> str:
    """The reason inside Mitsuba's 'failed to instantiate' / 'unreferenced property' messages."""
    unused = re.findall(r'- \w+ "([^"]+)"', text)
    if "unreferenced propert" in text and unused:
        return f"unknown parameter(s): {', '.join(unused)}"
    return re.sub(r'^.*?plugin of type "[^"]+":\s*', "", text)


def film_size(scene: mi.Scene, sensor: int = 0) -> tuple[int, int]:
    size = scene.sensors()[sensor].film().crop_size()
    return int(size[0]), int(size[1])
