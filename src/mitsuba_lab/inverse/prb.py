"""Rendering with Mitsuba's ``prb`` (path replay backpropagation, Vicini et al. 2021) and
the losses, shared by the optimisation and the gradient sweep.

* ``loss = "l2"``: mean over pixels and channels of (I - T)^2.
* ``loss = "relative_l2"``: mean of (I - T)^2 / (T^2 + 0.01) (T: the fixed target).

``mi.render`` renders the primal and the gradient pass with decorrelated seeds (its
``seed_grad`` default), so the gradient of the L2 loss is unbiased.
"""
from __future__ import annotations

import numpy as np

from ..errors import LabError
from .config import LOSSES

RELATIVE_EPS = 0.01
TARGET_SEED = 2 ** 30 + 7           # the target's samples are independent of every iteration's


def scalar(value) -> float:
    """A Dr.Jit scalar (Float of size 1, or a 0-d / 1-element tensor) as a Python float."""
    return float(np.array(value, dtype=np.float64).ravel()[0])


def loss_function(kind: str):
    """``loss(image, target)`` -> a differentiable Dr.Jit scalar, for ``kind`` in LOSSES."""
    import drjit as dr

    if kind == "l2":
        return lambda image, target: dr.mean(dr.square(image - target), axis=None)
    if kind == "relative_l2":
        return lambda image, target: dr.mean(dr.square(image - target) / (dr.square(target) + RELATIVE_EPS),
                                             axis=None)
    raise LabError(f"unknown loss '{kind}'; choose one of {', '.join(LOSSES)}")


def make_prb(max_depth: int):
    """Mitsuba's ``prb`` integrator at ``max_depth`` (given explicitly: prb's own default, 6,
    differs from path's unbounded one)."""
    import mitsuba as mi

    return mi.load_dict({"type": "prb", "max_depth": int(max_depth)})


def render_image(scene, integrator, spp: int, seed: int) -> np.ndarray:
    """A primal render (no gradient tracking) as an H x W x C float32 numpy array."""
    import drjit as dr
    import mitsuba as mi

    with dr.suspend_grad():
        image = mi.render(scene, integrator=integrator, spp=spp, seed=seed)
        dr.eval(image)
    return np.array(image, dtype=np.float32)
