"""The optimisation: Adam on the configured scene parameters, every iteration timed.

``mi.traverse`` the scene, keep the chosen keys, render a target at the true values, start
from ``init`` and run ``mi.ad.Adam`` on the loss with ``prb``. Every iteration is timed
(forward + backward + Adam step + clamping to each parameter's [min, max], finished with
``dr.eval`` + ``dr.sync_thread``) and logged as a row: ``iteration, loss, param_error,
time_s, iteration_s, loss_eval``.

* ``loss``: the loss of that iteration's noisy render (what Adam saw);
* ``param_error``: root mean square of (theta - theta_true) over every optimised
  component (3 for an RGB value, 16 x 16 x 3 for a texture);
* ``time_s``: cumulative optimisation time; ``iteration_s``: the step's own time;
* ``loss_eval``: the loss of a fixed-seed render at ``optimise.eval_spp`` (a deterministic
  function of the parameters), made outside the clock so that the loss curve is not buried
  in render noise.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..interrupts import raise_pending
from .config import InverseConfig
from .prb import TARGET_SEED, loss_function, make_prb, render_image, scalar
from .scenes import load_inverse_scene, select_params, set_values, start_and_truth, to_numpy

EVAL_SEED = 2 ** 30 + 11            # the fixed seed of ``loss_eval``


def param_error(values: dict, truth: dict) -> float:
    """Root mean square of (value - truth) over every component of every key."""
    diff = np.concatenate([(np.asarray(values[k]) - truth[k]).ravel() for k in truth])
    return float(np.sqrt(np.mean(diff ** 2)))


@dataclass
class OptimisationResult:
    rows: list[dict]
    init: dict
    truth: dict
    final: dict
    images: dict                     # "initial" / "target" / "final" -> H x W x 3
    compile_note: str = ""

    @property
    def error_start(self) -> float:
        return self.rows[0]["param_error"]

    @property
    def error_end(self) -> float:
        return self.rows[-1]["param_error"]


def optimise(cfg: InverseConfig, progress=None) -> OptimisationResult:
    """Run the configured optimisation; ``progress(i, total, row)`` after each iteration.

    Row 0 is the start point (loss of one render there, time 0); row i >= 1 is after
    Adam step i, with ``time_s`` the cumulative optimisation time.
    """
    import drjit as dr
    import mitsuba as mi

    scene = load_inverse_scene(cfg)
    params = select_params(scene, cfg.keys)
    init, truth = start_and_truth(params, cfg.params)
    integrator = make_prb(cfg.max_depth)
    loss_fn = loss_function(cfg.loss)
    bounds = {p.key: (p.lo, p.hi) for p in cfg.params}

    set_values(params, truth)
    target_np = render_image(scene, integrator, cfg.target_spp, TARGET_SEED)
    target = mi.TensorXf(target_np)
    set_values(params, init)
    initial_np = render_image(scene, integrator, cfg.target_spp, TARGET_SEED)

    opt = mi.ad.Adam(lr=cfg.learning_rate)
    for key in cfg.keys:
        opt[key] = params[key]
    params.update(opt)

    def current() -> dict:
        return {k: to_numpy(opt[k]) for k in cfg.keys}

    def loss_eval() -> float:
        """Loss of a render with a fixed seed (common random numbers), outside the clock."""
        if not cfg.eval_spp:
            return math.nan
        with dr.suspend_grad():
            return scalar(loss_fn(mi.render(scene, params, integrator=integrator, spp=cfg.eval_spp,
                                            seed=EVAL_SEED), target))

    with dr.suspend_grad():
        start_loss = scalar(loss_fn(mi.render(scene, params, integrator=integrator, spp=cfg.spp,
                                              seed=cfg.seed), target))
    rows = [{"iteration": 0, "loss": start_loss, "param_error": param_error(current(), truth),
             "time_s": 0.0, "iteration_s": 0.0, "loss_eval": loss_eval()}]
    elapsed = 0.0
    for it in range(1, cfg.iterations + 1):
        dr.sync_thread()
        start = time.perf_counter()
        image = mi.render(scene, params, integrator=integrator, spp=cfg.spp, seed=cfg.seed + it)
        loss = loss_fn(image, target)
        dr.backward(loss)
        opt.step()
        for key in cfg.keys:
            lo, hi = bounds[key]
            opt[key] = dr.clip(opt[key], lo, hi)
        params.update(opt)
        dr.eval(loss, *[opt[k] for k in cfg.keys])
        dr.sync_thread()
        step = time.perf_counter() - start
        elapsed += step
        row = {"iteration": it, "loss": scalar(loss), "param_error": param_error(current(), truth),
               "time_s": elapsed, "iteration_s": step, "loss_eval": loss_eval()}
        rows.append(row)
        raise_pending()                   # a Ctrl-C that Dr.Jit swallowed stops the loop here
        if progress:
            progress(it, cfg.iterations, row)
    final = current()
    set_values(params, final)
    final_np = render_image(scene, integrator, cfg.target_spp, TARGET_SEED)
    return OptimisationResult(rows, init, truth, final,
                              {"initial": initial_np, "target": target_np, "final": final_np},
                              "iteration 1 includes kernel compilation" if cfg.iterations else "")
