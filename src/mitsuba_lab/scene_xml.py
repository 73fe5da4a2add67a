"""Scene variants made by editing the XML: another sampler, another film size.

A Mitsuba scene fixes its sampler and film inside the sensor, and a loaded
scene cannot swap its sampler's type. A sweep needs both as axes, so the XML
is edited (ElementTree) and loaded from a string, with the scene's folder on
the file resolver so relative paths (meshes, textures) still resolve.
"""
from __future__ import annotations

import hashlib
import os
import xml.etree.ElementTree as ET

import mitsuba as mi

from .errors import LabError, one_line

_TAGS = {bool: "boolean", int: "integer", float: "float", str: "string"}


def _param_element(name: str, value) -> ET.Element:
    tag = _TAGS.get(type(value))
    if tag is None:
        raise LabError(f"sampler parameter '{name}': unsupported value {value!r} (use a number, "
                       "boolean or string)")
    text = str(value).lower() if isinstance(value, bool) else str(value)
    return ET.Element(tag, {"name": name, "value": text})


def edited_xml(path: str, resolution: int | None = None, sampler: dict | None = None) -> str:
    """The scene's XML with the first sensor's film and/or sampler replaced."""
    try:
        tree = ET.parse(path)
    except ET.ParseError as err:
        raise LabError(f"cannot load scene {path}: {err}") from err
    sensor = tree.getroot().find("sensor")
    if sensor is None and (resolution or sampler):
        raise LabError(f"scene {path} has no <sensor> whose film or sampler could be set")
    if resolution:
        film = sensor.find("film")
        if film is None:
            film = ET.SubElement(sensor, "film", {"type": "hdrfilm"})
        for dim in ("width", "height"):
            for old in [e for e in film if e.get("name") == dim]:
                film.remove(old)
            film.append(ET.Element("integer", {"name": dim, "value": str(resolution)}))
    if sampler:
        old = sensor.find("sampler")
        count = None
        if old is not None:
            count = next((e for e in old if e.get("name") == "sample_count"), None)
            sensor.remove(old)
        new = ET.SubElement(sensor, "sampler", {"type": sampler["type"]})
        if count is not None and "sample_count" not in sampler:
            new.append(count)
        for name, value in sampler.items():
            if name != "type":
                new.append(_param_element(name, value))
    return ET.tostring(tree.getroot(), encoding="unicode")


def load_scene_variant(path: str, resolution: int | None = None, sampler: dict | None = None,
                       defaults: dict | None = None) -> mi.Scene:
    """Load ``path`` with an optional square film size and sampler (type + parameters)."""
    if not os.path.isfile(path):
        raise LabError(f"scene file not found: {path}")
    text = edited_xml(path, resolution, sampler)
    resolver = mi.file_resolver()
    folder = os.path.dirname(os.path.abspath(path))
    if not any(str(resolver[i]) == folder for i in range(len(resolver))):
        resolver.prepend(folder)         # (the resolver has no remove: add each folder once)
    try:
        return mi.load_string(text, **{k: str(v) for k, v in (defaults or {}).items()})
    except RuntimeError as err:
        raise LabError(f"cannot load scene {path}: {one_line(err)}") from err


def referenced_files(path: str) -> list[str]:
    """Files a scene names (``filename`` parameters and includes), resolved next to it."""
    folder = os.path.dirname(os.path.abspath(path))
    found = []
    for element in ET.parse(path).getroot().iter():
        value = element.get("filename") if element.tag == "include" else (
            element.get("value") if element.get("name") == "filename" else None)
        if value and "$" not in value:
            candidate = os.path.join(folder, value)
            if os.path.isfile(candidate):
                found.append(candidate)
    return sorted(set(found))


def scene_digest(path: str) -> str:
    """SHA-256 of the scene file and every file it references (content, not names)."""
    digest = hashlib.sha256()
    for name in [path] + referenced_files(path):
        with open(name, "rb") as f:
            digest.update(hashlib.sha256(f.read()).digest())
    return digest.hexdigest()
