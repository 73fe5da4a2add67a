"""High-spp references in a content-addressed cache, with their own noise floor.

Key = SHA-256 of: the scene file and the files it references (bytes), the film
size override as rendered (``scene_xml.film_override_key``), scene defaults, the reference integrator and its parameters, spp,
chunk count, the Mitsuba / Dr.Jit versions and variant, and, when a lab plugin
renders the reference, the lab plugins' code version. The reference is
rendered in K independent chunks (disjoint seeds); their mean is the image and
their spread gives the per-pixel variance of that mean: the noise floor that
the reference adds to every MSE measured against it. Stored as two EXRs
(mean, variance of the mean) with metadata, plus a JSON sidecar.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass

import numpy as np

from ... import images, interrupts
from ...render import render
from ...runtime import versions
from ...scene import make_integrator
from ...scene_xml import film_override_key, load_scene_variant, scene_digest
from ...plugins.params import declared
from .config import PluginSpec
from .identity import plugin_code_version

#: Reference chunks use seeds from here on, apart from every sweep seed.
REFERENCE_SEED_BASE = 1 << 24


@dataclass
class Reference:
    key: str
    image: np.ndarray
    variance: np.ndarray          # per-pixel variance of the mean image
    meta: dict

    @property
    def mse_floor(self) -> float:
        """Expected MSE of a perfect estimate measured against this reference."""
        return float(self.variance.mean())

    def rel_mse_floor(self, eps: float = 1e-2) -> float:
        return float(np.mean(self.variance / (self.image.astype(np.float64) ** 2 + eps)))


def reference_key(scene_path, resolution, defaults, integrator: PluginSpec, spp, chunks) -> str:
    info = versions()
    payload = {"scene": scene_digest(scene_path), "resolution": film_override_key(scene_path, resolution, defaults),
               "defaults": defaults,
               "integrator": integrator.type, "params": integrator.params, "spp": spp, "chunks": chunks,
               "mitsuba": info["mitsuba"], "drjit": info["drjit"], "variant": info["variant"]}
    if declared(integrator.type) is not None:      # a lab plugin renders it: its code is part of it
        payload["lab_plugins"] = plugin_code_version()
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:24]


def _paths(cache: str, key: str) -> tuple[str, str, str]:
    stem = os.path.join(cache, key)
    return stem + ".exr", stem + ".var.exr", stem + ".json"


def load_cached(cache: str, key: str) -> Reference | None:
    mean_path, var_path, meta_path = _paths(cache, key)
    if not all(os.path.exists(p) for p in (mean_path, var_path, meta_path)):
        return None
    with open(meta_path) as f:
        meta = json.load(f)
    return Reference(key, images.read_exr(mean_path)[0], images.read_exr(var_path)[0], meta)


def get_reference(scene_path: str, resolution, defaults: dict, integrator: PluginSpec,
                  spp: int, chunks: int, cache: str, progress=None) -> tuple[Reference, bool]:
    """(reference, was_cached). ``progress(done_chunks, chunks)`` is called while rendering."""
    key = reference_key(scene_path, resolution, defaults, integrator, spp, chunks)
    cached = load_cached(cache, key)
    if cached is not None:
        return cached, True
    os.makedirs(cache, exist_ok=True)
    scene = load_scene_variant(scene_path, resolution, None, defaults)
    plugin = make_integrator(integrator.type, integrator.params)
    chunk_spp = spp // chunks                      # the config guarantees chunks divides spp
    stack, start = [], time.perf_counter()
    for k in range(chunks):
        image, _ = render(scene, plugin, spp=chunk_spp, seed=REFERENCE_SEED_BASE + k)
        stack.append(image.astype(np.float64))
        if progress:
            progress(k + 1, chunks)
    stack = np.stack(stack)
    mean = stack.mean(axis=0)
    variance = stack.var(axis=0, ddof=1) / chunks   # variance of the mean of K independent chunks
    meta = {"key": key, "scene": scene_path, "resolution": resolution, "defaults": defaults,
            "integrator": integrator.type, "params": integrator.params, "spp": spp, "chunks": chunks,
            "seconds": time.perf_counter() - start, "mse_floor": float(variance.mean()), **versions()}
    mean_path, var_path, meta_path = _paths(cache, key)
    with interrupts.deferred():                    # the three files, or (Ctrl-C before) none
        images.write_exr(var_path, variance, {"mitsuba_lab.reference": json.dumps(meta)})
        images.write_exr(mean_path, mean, {"mitsuba_lab.reference": json.dumps(meta)})
        with images.atomic_path(meta_path) as tmp:
            with open(tmp, "w") as f:
                json.dump(meta, f, indent=1)
    return Reference(key, mean.astype(np.float32), variance.astype(np.float32), meta), False
