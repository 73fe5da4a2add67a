"""Scene variants made by editing the XML: another sampler, another film size (``film``).

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


#: hdrfilm's width and height when the scene gives none (Mitsuba's defaults).
MITSUBA_FILM_SIZE = (768, 576)


def _native_film_size(path: str, root: ET.Element, defaults: dict | None) -> tuple[int, int]:
    """(width, height) of the first sensor's film as written, ``$name`` values resolved from the
    scene's <default>s and ``defaults``; Mitsuba's 768x576 where the scene gives none."""
    values = {**_defaults(root), **{k: str(v) for k, v in (defaults or {}).items()}}
    sensor = root.find("sensor")
    film = sensor.find("film") if sensor is not None else None
    size = list(MITSUBA_FILM_SIZE)
    for index, dim in enumerate(("width", "height")):
        element = next((e for e in (film if film is not None else []) if e.get("name") == dim), None)
        if element is None:
            continue
        text = _substitute(element.get("value", ""), values)
        try:
            size[index] = int(text)
        except ValueError:
            raise LabError(f"scene {path}: cannot read the film's {dim} ('{text}'), so a resolution "
                           f"that keeps its aspect ratio cannot be worked out: give [width, height]") from None
    return size[0], size[1]


def film_size(path: str, resolution=None, defaults: dict | None = None) -> tuple[int, int]:
    """(width, height) the scene's first film has when loaded with the film override
    ``resolution`` (``film.film_shape``: a scalar sets the larger side, the aspect ratio kept)
    and ``defaults`` for its <default> values."""
    from .film import film_shape

    if resolution is not None and not isinstance(resolution, int):
        return film_shape((1, 1), resolution)             # [width, height]: nothing to read
    return film_shape(_native_film_size(path, _parse(path).getroot(), defaults), resolution)


def film_override_key(path: str, resolution=None, defaults: dict | None = None):
    """The override as reference keys and run identities record it (``film.film_key``)."""
    from .film import film_key

    if resolution is None:
        return None
    return film_key(film_size(path, None, defaults), resolution)


def edited_xml(path: str, resolution=None, sampler: dict | None = None, defaults: dict | None = None) -> str:
    """The scene's XML with the first sensor's film size (``film.film_shape`` of ``resolution``,
    with ``defaults`` for the scene's <default> values) and/or sampler replaced."""
    from .film import film_shape

    tree = _parse(path)
    sensor = tree.getroot().find("sensor")
    if sensor is None and (resolution or sampler):
        raise LabError(f"scene {path} has no <sensor> whose film or sampler could be set")
    if resolution:
        size = film_shape(_native_film_size(path, tree.getroot(), defaults), resolution)
        film = sensor.find("film")
        if film is None:
            film = ET.SubElement(sensor, "film", {"type": "hdrfilm"})
        for dim, value in zip(("width", "height"), size):
            for old in [e for e in film if e.get("name") == dim]:
                film.remove(old)
            film.append(ET.Element("integer", {"name": dim, "value": str(value)}))
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


def load_scene_variant(path: str, resolution=None, sampler: dict | None = None,
                       defaults: dict | None = None) -> mi.Scene:
    """Load ``path`` with an optional film size override (``film``: N sets the larger side and
    keeps the aspect ratio, (W, H) sets both) and sampler (type + parameters)."""
    if not os.path.isfile(path):
        raise LabError(f"scene file not found: {path}")
    text = edited_xml(path, resolution, sampler, defaults)
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


_PARSERS = {"integer": int, "float": float, "string": str,
            "boolean": lambda text: {"true": True, "false": False}[text.strip().lower()]}


def scene_defaults(path: str) -> dict[str, str]:
    """The scene's top-level ``<default name=... value=...>`` values, as written."""
    return _defaults(_parse(path).getroot())


def _defaults(root: ET.Element) -> dict[str, str]:
    return {e.get("name"): e.get("value", "") for e in root.findall("default")}


def _parse(path: str) -> ET.ElementTree:
    try:
        return ET.parse(path)
    except ET.ParseError as err:
        raise LabError(f"cannot load scene {path}: {err}") from err


def _substitute(text: str, values: dict[str, str]) -> str:
    for name in sorted(values, key=len, reverse=True):     # $max_depth before $max
        text = text.replace(f"${name}", str(values[name]))
    return text


def plugin_spec(path: str, tag: str, defines: dict | None = None) -> tuple[str, dict] | None:
    """(type, parameters) of the scene's ``<integrator>`` (tag='integrator') or first sensor's
    ``<sampler>`` (tag='sampler'), with ``$name`` references resolved from the scene's
    defaults and ``defines``; None when the scene has none. Raises LabError for a plugin with
    nested plugins or values that are not plain numbers, booleans or strings."""
    root = _parse(path).getroot()
    values = {**_defaults(root), **{k: str(v) for k, v in (defines or {}).items()}}
    if tag == "sampler":
        sensor = root.find("sensor")
        element = sensor.find("sampler") if sensor is not None else None
    else:
        element = root.find(tag)
    if element is None:
        return None
    params = {}
    for child in element:
        if not isinstance(child.tag, str):            # comments
            continue
        parse = _PARSERS.get(child.tag)
        name = child.get("name")
        if parse is None or name is None:
            raise LabError(f"scene {path}: the {tag} '{element.get('type')}' has a <{child.tag}> "
                           f"element; only integer, float, boolean and string parameters can be "
                           f"combined with command-line settings")
        text = _substitute(child.get("value", ""), values)
        try:
            params[name] = parse(text)
        except (KeyError, ValueError) as err:
            raise LabError(f"scene {path}: {tag} parameter '{name}': '{text}' is not "
                           f"{'an' if child.tag == 'integer' else 'a'} {child.tag}") from err
    return _substitute(element.get("type", ""), values), params
