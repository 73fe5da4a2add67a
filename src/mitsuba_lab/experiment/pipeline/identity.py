"""A run's identity: everything that determines its result, and what changed since a stored run.

A stored run is reused on resume only when its identity equals the one the sweep
would give it now: the scene's content (the file and the files it references),
its resolution override and ``<default>`` values; the integrator and sampler with
their fully resolved parameters (defaults filled in, so writing a default out
does not count as a change); the sample count or time budget; the reference it
is measured against; the pass sizes of a progressive run; and the versions of
Mitsuba, Dr.Jit, the variant and the lab's plugin code. The seed is part of a
run's key in the store, so it is not repeated here.
"""
from __future__ import annotations

import functools
import hashlib
import json
import os

from .config import PASS_PARAMETER, PluginSpec

#: Parameters that never change an image: they are left out of identities.
NO_EFFECT = {"count_rays"}
#: Sampler parameters that the sweep overrides with the point's sample count.
SAMPLER_OVERRIDDEN = {"sample_count"}


@functools.lru_cache(maxsize=1)
def plugin_code_version() -> str:
    """SHA-256 (first 16 hex digits) of the lab plugins' Python sources."""
    from ... import plugins

    root = os.path.dirname(os.path.abspath(plugins.__file__))
    digest = hashlib.sha256()
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(folder, name)
            digest.update(os.path.relpath(path, root).encode() + b"\0")
            with open(path, "rb") as f:
                digest.update(hashlib.sha256(f.read()).digest())
    return digest.hexdigest()[:16]


def resolved_params(plugin_type: str, params: dict) -> dict:
    """The plugin's parameters with its defaults filled in (lab plugins; others as given)."""
    from ...plugins.params import resolve

    return resolve(plugin_type, dict(params))


def versions_identity() -> dict:
    from ...runtime import versions

    info = versions()
    return {"mitsuba": info["mitsuba"], "drjit": info["drjit"], "variant": info["variant"],
            "lab_plugins": plugin_code_version()}


def integrator_identity(spec: PluginSpec) -> dict:
    params = resolved_params(spec.type, spec.params)
    for name in NO_EFFECT | {PASS_PARAMETER.get(spec.type)}:
        params.pop(name, None)          # the pass count is the point's sample count
    return {"type": spec.type, "params": params}


def sampler_identity(spec: PluginSpec) -> dict:
    params = {k: v for k, v in resolved_params(spec.type, spec.params).items() if k not in SAMPLER_OVERRIDDEN}
    return {"type": spec.type, "params": params}


def point_identity(scene, strategy: PluginSpec, sampler: PluginSpec, point, reference_key: str,
                   scene_digest: str) -> dict:
    """Identity of a point's runs (``scene`` a config.SceneSpec, ``point`` a plan.Point). A
    progressive point adds its pass sizes (a budget's are fitted by its first run: "fitted");
    a point of separate renders has no such key, so its identity is what it was before
    progressive runs existed."""
    from ...scene_xml import film_override_key

    ident = {"scene": {"digest": scene_digest,
                       "resolution": film_override_key(scene.path, scene.resolution, scene.defaults),
                       "defaults": dict(scene.defaults)},
             "integrator": integrator_identity(strategy),
             "sampler": sampler_identity(sampler),
             "spp": point.spp, "budget_s": point.budget_s,
             "reference": reference_key,
             "versions": versions_identity()}
    if point.progressive:
        ident["progressive"] = {"passes": list(point.passes) if point.passes else "fitted"}
    return ident


def identity_hash(identity: dict) -> str:
    text = json.dumps(identity, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _flatten(value, prefix="") -> dict:
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            out.update(_flatten(item, f"{prefix}{key}."))
        return out
    return {prefix[:-1]: value}


#: How a changed field is named in messages (flattened key -> words).
_LABELS = {"scene.digest": "scene file content", "reference": "reference",
           "versions.lab_plugins": "lab plugin code", "integrator.type": "integrator",
           "sampler.type": "sampler", "progressive.passes": "progressive pass sizes"}


def _label(key: str) -> str:
    if key in _LABELS:
        return _LABELS[key]
    parts = key.split(".")
    if parts[0] in ("integrator", "sampler") and parts[1:2] == ["params"]:
        return f"{parts[0]} {'.'.join(parts[2:])}"
    if parts[0] == "scene" and parts[1:2] == ["defaults"]:
        return f"scene default {'.'.join(parts[2:])}"
    return " ".join(parts)


def describe_changes(old: dict | None, new: dict) -> str:
    """'integrator max_depth 8 -> 5; integrator emitter_samples 2 -> 4': what differs.

    Content hashes and derived keys are named without their values; a change of
    the reference that other listed changes explain is not repeated."""
    if old is None:
        return "stored without a run identity (an older version of the lab)"
    a, b = _flatten(old), _flatten(new)
    changes = []
    for key in sorted(set(a) | set(b), key=lambda k: (k == "reference", k)):
        if a.get(key, "(unset)") == b.get(key, "(unset)"):
            continue
        label = _label(key)
        if key in ("scene.digest", "reference", "versions.lab_plugins"):
            if key == "reference" and changes:
                continue
            changes.append(f"{label} changed")
        else:
            changes.append(f"{label} {_show(a.get(key, '(unset)'))} -> {_show(b.get(key, '(unset)'))}")
    return "; ".join(changes) or "identity changed"


def _show(value) -> str:
    return value if isinstance(value, str) and value == "(unset)" else json.dumps(value)
