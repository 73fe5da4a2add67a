"""Rendering at ``mitsuba-lab check``'s budgets: a strategy's independent splits, the larger
budgets that tell a bias from a heavy tail (``verdicts.judge``), and, for a consistent
estimator, the bias^2 of its image mean as its budget grows (``verdicts.judge_consistent``)."""
from __future__ import annotations

import math

import numpy as np

from .verdicts import LADDER_SEED, LADDER_SPLITS, BiasRung, Rung, ladder_factors
from ..metrics import luminance


def is_consistent(kind: str, params: dict) -> bool:
    """Biased for a finite budget, consistent as it grows: a merging radius that shrinks within a
    render (lab_vcm's merging modes, lab_photon: ``Estimator.separate_reason``)."""
    from ..plugins.integrators.estimator import lookup
    from ..plugins.params import resolve

    estimator = lookup(kind)
    return estimator is not None and bool(estimator.separate_reason(resolve(kind, params)))


def budget_integrator(kind: str, params: dict, spp: int):
    """(integrator, samples per pixel to render) of ``spp`` samples of the strategy: an
    integrator whose sample count is a parameter of its own (lab_photon's passes) gets it there
    and renders one sample per pixel of each."""
    from ..plugins.integrators.estimator import sample_count_parameters
    from ..scene import make_integrator

    parameter = sample_count_parameters().get(kind)
    if parameter is None:
        return make_integrator(kind, params), spp
    return make_integrator(kind, {**params, parameter: spp}), 1


def render_splits(scene, strategy, spp_total, splits, seed0):
    """(splits x H x W x 3 images, rays by kind, seconds) of ``splits`` renders of the strategy
    ((integrator type, parameters)), ``spp_total`` / ``splits`` samples per pixel each, seeds
    ``seed0``.."""
    from ..render import render

    spp = spp_total // splits
    integrator, spp = budget_integrator(*strategy, spp)
    images, rays, seconds = [], {}, 0.0
    for index in range(splits):
        image, stats = render(scene, integrator, spp=spp, seed=seed0 + index)
        images.append(image[..., :3])
        seconds += stats.wall_s
        for kind, count in stats.rays.items():
            rays[kind] = rays.get(kind, 0) + count
    return np.stack(images), rays, seconds


def render_ladder(scene, strategy, stack, spp, escalate: int):
    """The budgets of ``verdicts.judge``: the first (``stack``: its splits of ``spp``
    samples per pixel each) and the larger ones, rendered here (``LADDER_SPLITS`` splits of
    4, 16, ... x ``spp`` up to ``escalate`` x, seeds from rung x ``LADDER_SEED``). Returns
    (rungs, each pixel's luminance summed over every render, the mean luminance of all samples,
    samples per pixel in all, seconds spent here)."""
    first = luminance(stack.astype(np.float64))
    rungs = [Rung(1, spp, first.mean(axis=(1, 2)))]
    sums, weighted, samples = first.sum(axis=0), first.mean() * spp * len(stack), spp * len(stack)
    seconds = 0.0
    for index, factor in enumerate(ladder_factors(escalate), 1):
        more, _, wall = render_splits(scene, strategy, spp * factor * LADDER_SPLITS, LADDER_SPLITS,
                                      index * LADDER_SEED)
        seconds += wall
        lum = luminance(more.astype(np.float64))
        rungs.append(Rung(factor, spp * factor, lum.mean(axis=(1, 2))))
        sums += lum.sum(axis=0)
        weighted += lum.mean() * spp * factor * LADDER_SPLITS
        samples += spp * factor * LADDER_SPLITS
    return rungs, sums, weighted / samples, samples, seconds


def mean_bias_squared(images: np.ndarray, judged: dict) -> tuple[float, float]:
    """(bias^2, its standard error) of the mean luminance of ``images`` (splits x H x W x C)
    against the judged reference: (m - m_ref)^2 less the variance of that difference (the splits'
    spread and the reference's own error), which makes it unbiased for the squared bias; its
    error from Var(d^2) = 4 d^2 v + 2 v^2 for a normal difference d of variance v. The image mean
    is the quantity check's z-test judges, and far less noisy than any pixel's."""
    means = luminance(images.astype(np.float64)).mean(axis=(1, 2))
    d = float(means.mean()) - judged["mean"]
    v = float(np.var(means, ddof=1)) / len(means) + judged["mean_variance"]
    return d * d - v, math.sqrt(4 * d * d * v + 2 * v * v)


def bias_ladder(scene, strategy, stack, spp, args, judged) -> list[BiasRung]:
    """bias^2 of the image mean against the judged reference (``mean_bias_squared``) at the first
    budget (``stack``) and, when it is resolved there, at 4, 16, ... x the samples per split up to
    ``--escalate`` x (``--splits`` splits each, seeds from rung x ``LADDER_SEED``): how a
    consistent estimator's bias shrinks as its iterations grow."""
    def rung(factor, images):
        return BiasRung(factor, spp * factor, *mean_bias_squared(images, judged))

    rungs = [rung(1, stack)]
    if rungs[0].resolved:
        for index, factor in enumerate(ladder_factors(args.escalate), 1):
            more, _, _ = render_splits(scene, strategy, spp * factor * args.splits, args.splits, index * LADDER_SEED)
            rungs.append(rung(factor, more))
    return rungs
