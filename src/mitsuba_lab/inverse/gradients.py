"""The gradient's error against time: dLoss/dtheta per sampler x spp, against a reference.

At the start point of the optimisation, for each sampler x spp, ``seeds`` timed gradients
(forward + backward) are compared with a high-spp reference gradient: variance (summed over
components), bias^2, relative MSE and efficiency 1 / (relative variance x time). Also
central finite differences of primal renders, to check prb's gradients.
"""
from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import LabError
from ..interrupts import raise_pending
from .config import InverseConfig
from .prb import TARGET_SEED, loss_function, make_prb, render_image, scalar
from .scenes import load_inverse_scene, select_params, set_values, start_and_truth, to_numpy

GRAD_COLUMNS = ("sampler", "spp", "seeds", "time_s", "time_s_min", "grad_norm", "variance",
                "bias2", "rel_variance", "rel_mse", "efficiency", "status")


def gradient(scene, params, key: str, integrator, spp: int, seed: int, objective) -> tuple[np.ndarray, float]:
    """(dObjective/dparams[key] as numpy, seconds for forward + backward).

    ``objective(image)`` maps the rendered tensor to a scalar. The clock starts after
    a sync and stops after the gradient is evaluated and the thread synced.
    """
    import drjit as dr
    import mitsuba as mi

    value = type(params[key])(params[key])        # a fresh leaf: no accumulated gradient
    dr.enable_grad(value)
    params[key] = value
    params.update()
    dr.sync_thread()
    start = time.perf_counter()
    image = mi.render(scene, params, integrator=integrator, spp=spp, seed=seed)
    dr.backward(objective(image))
    grad = dr.grad(params[key])
    dr.eval(grad)
    dr.sync_thread()
    seconds = time.perf_counter() - start
    result = to_numpy(grad)
    dr.disable_grad(params[key])
    return result, seconds


def finite_difference(scene, params, key: str, integrator, spp: int, seed: int, objective,
                      h: float = 1e-2) -> np.ndarray:
    """Central differences (f(x + h e_i) - f(x - h e_i)) / 2h of primal renders, one
    component of ``params[key]`` at a time, every render with the same seed (common
    random numbers). Meant for parameters with a few components."""
    import drjit as dr
    import mitsuba as mi

    base = to_numpy(params[key])
    grad = np.zeros_like(base)
    flat = grad.reshape(-1)
    for i in range(base.size):
        values = []
        for sign in (1, -1):
            shifted = base.copy().reshape(-1)
            shifted[i] += sign * h
            set_values(params, {key: shifted.reshape(base.shape)})
            with dr.suspend_grad():
                image = mi.render(scene, params, integrator=integrator, spp=spp, seed=seed)
                values.append(scalar(objective(image)))
        flat[i] = (values[0] - values[1]) / (2 * h)
    set_values(params, {key: base})
    return grad


@dataclass
class GradientPoint:
    sampler: str
    spp: int
    seeds: int
    time_s: float = math.nan            # median seconds per gradient (forward + backward)
    time_s_min: float = math.nan
    grad_norm: float = math.nan         # |mean gradient|
    variance: float = math.nan          # sum over components of the variance across seeds
    bias2: float = math.nan             # |mean - reference|^2 minus variance / seeds (can be < 0)
    rel_variance: float = math.nan      # variance / |reference|^2
    rel_mse: float = math.nan           # mean over seeds of |g - reference|^2 / |reference|^2
    efficiency: float = math.nan        # 1 / (rel_variance x time_s): the estimator is unbiased
    status: str = "ok"

    def as_row(self) -> dict:
        return {c: getattr(self, c) for c in GRAD_COLUMNS}


@dataclass
class GradientSweep:
    points: list[GradientPoint]
    reference: np.ndarray
    reference_sem: float                # standard error of |reference| estimate (root of summed variance / n)
    key: str
    loss: str
    notes: list[str] = field(default_factory=list)


def _sampler_dict(name: str) -> dict:
    return {"type": name}


def gradient_sweep(cfg: InverseConfig, progress=None) -> GradientSweep:
    """The gradient's error against time at the start point, per sampler x spp.

    Target: rendered at the true values (``target_spp``). Reference gradient: the mean
    of ``reference_seeds`` gradients at ``reference_spp`` with Mitsuba's independent
    sampler. Per point: one untimed warm-up gradient (compilation), then ``seeds``
    timed gradients with seeds 1..n.
    """
    import mitsuba as mi

    spec = cfg.gradients
    if spec is None:
        raise LabError(f"{cfg.source}: no [gradients] table")
    integrator = make_prb(cfg.max_depth)
    loss_fn = loss_function(cfg.loss)

    base_scene = load_inverse_scene(cfg)
    base_params = select_params(base_scene, cfg.keys)
    init, truth = start_and_truth(base_params, cfg.params)
    set_values(base_params, truth)
    target = mi.TensorXf(render_image(base_scene, integrator, cfg.target_spp, TARGET_SEED))
    objective = lambda image: loss_fn(image, target)
    set_values(base_params, init)

    total = spec.reference_seeds + sum(spec.seeds + 1 for _ in spec.samplers for _ in spec.spp)
    done = [0]

    def tick(label):
        raise_pending()                   # a Ctrl-C that Dr.Jit swallowed stops the sweep here
        done[0] += 1
        if progress:
            progress(done[0], total, label)

    refs = []
    for s in range(spec.reference_seeds):
        refs.append(gradient(base_scene, base_params, spec.key, integrator, spec.reference_spp,
                             10_000 + s, objective)[0])
        tick(f"reference {s + 1}/{spec.reference_seeds}")
    refs = np.array(refs).reshape(len(refs), -1)
    reference = refs.mean(axis=0)
    ref_var = float(refs.var(axis=0, ddof=1).sum()) if len(refs) > 1 else math.nan
    ref_norm2 = float(np.sum(reference ** 2))
    notes = []
    contenders = {}                      # sampler -> (scene, params); left-out samplers are not
    for name in spec.samplers:
        try:
            scene = load_inverse_scene(cfg, _sampler_dict(name))
        except LabError as err:
            notes.append(f"sampler {name} left out: {err}")
            for _ in range(len(spec.spp) * (spec.seeds + 1)):
                tick(f"{name} left out")
            continue
        params = select_params(scene, cfg.keys)
        set_values(params, init)
        contenders[name] = (scene, params)
    points = []
    for spp in spec.spp:
        grads = {name: [] for name in contenders}
        times = {name: [] for name in contenders}
        for name, (scene, params) in contenders.items():
            gradient(scene, params, spec.key, integrator, spp, 0, objective)      # warm-up: compiles
            tick(f"{name} {spp} spp warm-up")
        for s in range(1, spec.seeds + 1):                # contenders alternate, seed by seed
            for name, (scene, params) in contenders.items():
                g, t = gradient(scene, params, spec.key, integrator, spp, s, objective)
                grads[name].append(g.reshape(-1))
                times[name].append(t)
                tick(f"{name} {spp} spp seed {s}")
        for name in spec.samplers:
            if name in contenders:
                points.append(_point(name, spp, np.array(grads[name]), times[name], reference, ref_norm2))
            else:
                points.append(GradientPoint(name, spp, 0, status="left out (see notes)"))
    points.sort(key=lambda p: (spec.samplers.index(p.sampler), p.spp))
    return GradientSweep(points, reference, math.sqrt(ref_var / len(refs)) if len(refs) > 1 else math.nan,
                         spec.key, cfg.loss, notes)


def _point(name, spp, grads: np.ndarray, times, reference, ref_norm2) -> GradientPoint:
    n = len(grads)
    mean = grads.mean(axis=0)
    variance = float(grads.var(axis=0, ddof=1).sum())
    mse = float(np.mean(np.sum((grads - reference) ** 2, axis=1)))
    bias2 = float(np.sum((mean - reference) ** 2)) - variance / n
    time_s = statistics.median(times)
    rel_mse = mse / ref_norm2 if ref_norm2 > 0 else math.nan
    rel_variance = variance / ref_norm2 if ref_norm2 > 0 else math.nan
    return GradientPoint(name, spp, n, time_s=time_s, time_s_min=min(times),
                         grad_norm=float(np.linalg.norm(mean)), variance=variance, bias2=bias2,
                         rel_variance=rel_variance, rel_mse=rel_mse,
                         efficiency=1.0 / (rel_variance * time_s) if rel_variance > 0 else math.inf)


def best_sampler(points: list[GradientPoint]) -> tuple[str, float] | None:
    """(sampler, efficiency) of the most efficient measured point; None unless at least two
    samplers were measured (with one there is nothing to compare, so no verdict)."""
    ok = [p for p in points if p.status == "ok" and math.isfinite(p.efficiency)]
    if len({p.sampler for p in ok}) < 2:
        return None
    best = max(ok, key=lambda p: p.efficiency)
    return best.sampler, best.efficiency
