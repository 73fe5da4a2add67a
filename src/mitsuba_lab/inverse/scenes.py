"""The scenes of an inversion and their parameters as numpy.

``scene.path`` names a Mitsuba XML scene (``scene.resolution`` sets its film: N the larger side,
keeping the aspect ratio, or [width, height], as everywhere: ``mitsuba_lab.film``;
``scene.defaults`` its ``<default>`` values). ``scene.builtin = "cornell_texture"`` is
the scene built in code by ``cornell_texture_scene``: Mitsuba's ``mi.cornell_box()``
whose back wall has a diffuse BSDF with an RGB ``bitmap`` reflectance of
``scene.texture_size`` squared texels (nearest filtering) and no boxes; the texture of the
*true* scene is ``truth_texture`` (a colour checkerboard with a gradient), so its
key ``back.bsdf.reflectance.data`` can be optimised from grey.

Parameters are reached by their ``mi.traverse`` keys (``select_params``) and moved to and
from numpy (float64) for the optimiser's bookkeeping and the reports.
"""
from __future__ import annotations

import numpy as np

from ..errors import LabError, one_line
from .config import InverseConfig


def truth_texture(size: int) -> np.ndarray:
    """The true back-wall reflectance of ``cornell_texture``: size x size x 3, in [0.1, 0.8].

    A 4 x 4 checkerboard of a warm and a cool colour, modulated by a horizontal ramp,
    so both sharp edges and smooth variation have to be recovered.
    """
    v, u = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size, indexing="ij")
    checker = ((np.floor(u * 4) + np.floor(v * 4)) % 2)[..., None]
    warm, cool = np.array([0.75, 0.45, 0.15]), np.array([0.15, 0.35, 0.7])
    ramp = (0.6 + 0.4 * u)[..., None]
    return np.clip((checker * warm + (1 - checker) * cool) * ramp + 0.05, 0.1, 0.8).astype(np.float32)


#: The film of ``mi.cornell_box()`` (width, height): what a ``resolution`` override scales.
CORNELL_FILM = (256, 256)


def film_of(cfg: InverseConfig) -> tuple[int, int]:
    """(width, height) of the config's film: its ``resolution`` applied to the scene's own."""
    from ..film import film_shape
    from ..scene_xml import film_size

    if cfg.builtin is not None:
        return film_shape(CORNELL_FILM, cfg.resolution)
    return film_size(cfg.scene_path, cfg.resolution, cfg.defaults)


def cornell_texture_scene(resolution, texture_size: int, sampler: dict | None = None,
                          spp: int = 16) -> dict:
    """``mi.cornell_box()`` with a textured back wall (see the module docstring); the film
    is ``resolution`` (``film``: N the larger side, or (width, height)) with a box filter, the
    sampler ``sampler`` (default independent).

    The two boxes are removed: with them, the texels behind the tall box receive
    only a weak, noisy gradient through indirect light, and Adam (which normalises
    each component's step) turns that noise into a random walk of about the learning
    rate per step, so the hidden texels drift while the visible ones are recovered and
    the parameter error, after falling at first, rises again. Without them every texel
    is seen directly.
    """
    import mitsuba as mi

    from ..film import film_shape

    scene = mi.cornell_box()
    del scene["large-box"], scene["small-box"]      # they would hide texels (see the docstring)
    width, height = film_shape(CORNELL_FILM, resolution)
    scene["sensor"]["film"].update({"width": width, "height": height, "rfilter": {"type": "box"}})
    scene["sensor"]["sampler"] = {"sample_count": spp, **(sampler or {"type": "independent"})}
    scene["back"]["bsdf"] = {
        "type": "diffuse",
        "reflectance": {"type": "bitmap", "bitmap": mi.Bitmap(truth_texture(texture_size)),
                        "filter_type": "nearest", "raw": True}}
    return scene


def load_inverse_scene(cfg: InverseConfig, sampler: dict | None = None):
    """The config's scene at its resolution, optionally with another sampler (type + params),
    its film bound to its sampler (``bind_film_layout``: the demos call ``mi.render`` directly)."""
    import mitsuba as mi

    from ..plugins.samplers.layout import bind_film_layout
    from ..scene_xml import load_scene_variant

    if cfg.builtin is not None:
        try:
            scene = mi.load_dict(cornell_texture_scene(cfg.resolution, cfg.texture_size, sampler))
        except RuntimeError as err:
            raise LabError(f"cannot build scene {cfg.builtin}: {one_line(err)}") from err
    else:
        scene = load_scene_variant(cfg.scene_path, cfg.resolution, sampler, cfg.defaults)
    bind_film_layout(scene)
    return scene


def select_params(scene, keys) -> "mi.SceneParameters":
    """``mi.traverse(scene)`` kept to ``keys``; an unknown key is a one-line LabError that
    lists the keys the scene has."""
    import mitsuba as mi

    params = mi.traverse(scene)
    missing = [k for k in keys if k not in params]
    if missing:
        available = ", ".join(k for k in params.keys())
        raise LabError(f"unknown scene parameter key(s) {', '.join(missing)}; the scene has: {available}")
    params.keep(list(keys))
    return params


def to_numpy(value) -> np.ndarray:
    """A parameter value as float64 numpy: Color3f -> (3,), TensorXf -> its shape."""
    import drjit as dr

    array = np.array(value, dtype=np.float64)
    if dr.is_tensor_v(value):
        return array
    return array.reshape(-1)


def from_numpy(like, array: np.ndarray):
    """A numpy array as a value of ``like``'s Dr.Jit type."""
    import drjit as dr
    import mitsuba as mi

    if dr.is_tensor_v(like):
        return type(like)(np.asarray(array, dtype=np.float32).reshape(np.array(like).shape))
    array = np.asarray(array, dtype=np.float32).reshape(-1)
    if dr.size_v(like) == dr.Dynamic:            # a flat Float
        return type(like)(array)
    return type(like)(*[mi.Float(float(a)) for a in array])


def _broadcast(spec_value, shape) -> np.ndarray:
    value = np.asarray(spec_value, dtype=np.float64)
    if value.ndim == 0:
        return np.full(shape, float(value))
    if shape and value.shape[0] == shape[-1]:
        return np.broadcast_to(value, shape).copy()
    raise LabError(f"a value with {value.shape[0]} components does not fit a parameter of shape {shape}")


def start_and_truth(params, specs) -> tuple[dict, dict]:
    """(init values, true values) as numpy, per key; the truth is the scene's value unless given."""
    init, truth = {}, {}
    for spec in specs:
        current = to_numpy(params[spec.key])
        try:
            init[spec.key] = np.clip(_broadcast(spec.init, current.shape), spec.lo, spec.hi)
            truth[spec.key] = current if spec.truth is None else _broadcast(spec.truth, current.shape)
        except LabError as err:
            raise LabError(f"parameters.{spec.key}: {err}") from None
    return init, truth


def set_values(params, values: dict) -> None:
    for key, value in values.items():
        params[key] = from_numpy(params[key], value)
    params.update()
