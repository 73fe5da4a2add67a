"""Choosing between every technique and path tracing alone from a pilot (lab_vcm ``pilot``).

Bidirectional techniques pay for themselves only where path tracing struggles: on a diffuse box
or glossy plates their connections and merges cost more than the variance they remove, while
on a caustic light tracing and merging carry the light. Efficiency-aware MIS (Grittmann, Yazici,
Georgiev & Slusallek 2022) picks techniques from their measured variance and cost; this is its
coarsest form, one choice for the whole image:

* a pilot renders the scene ``PILOT_RENDERS`` times with every technique and as many times with
  path tracing alone (lab_mis, the estimator of lab_vcm's mode pt in a lighter kernel;
  ``pilot_iterations`` iterations each, independent seeds);
* per pixel, the relative variance of one iteration (in relMSE's units, 1 / (mean^2 + 0.01))
  with every technique is its spread over the pilot's renders; path tracing's is its renders'
  mean squared deviation from the every-technique mean, so light that a short pilot of path
  tracing misses (a caustic, a light behind glass) counts as error, not as a small variance
  (a pilot's own spread underestimates a heavy tail: README);
* path tracing alone is chosen when the image's mean relative variance x time per iteration
  (the light pass and grid included for every technique) is lower for it.

Either choice renders one of lab_vcm's estimators unchanged, so the render is unbiased or
consistent as that estimator is. Path tracing's pilot renders are the same estimator as the
render when it is chosen, so their iterations are averaged in; every technique's pilot, whose
merging radius restarts at r_1, is not used in the image.
"""
from __future__ import annotations

import numpy as np

#: Renders of each kind in the pilot (their spread gives the variance).
PILOT_RENDERS = 4
#: The pilot's iterations per render: the render's samples per pixel over PILOT_FRACTION, at least
#: PILOT_MIN_ITERATIONS (one iteration's spread is too heavy-tailed to choose on: sds at 100
#: iterations chose path tracing for 2 seeds of 3 with pilots of 1, none of 5 with pilots of 4).
PILOT_FRACTION = 128
PILOT_MIN_ITERATIONS = 4


def pilot_iterations(spp: int) -> int:
    """Iterations of each pilot render for a render of ``spp`` samples per pixel: each pilot
    traces PILOT_RENDERS / PILOT_FRACTION (1/32) of the render's iterations, or 16 in all."""
    return max(PILOT_MIN_ITERATIONS, spp // PILOT_FRACTION)


def relative_variances(every: np.ndarray, camera: np.ndarray, iterations: int):
    """(every technique's, path tracing's) relative variance of one iteration per pixel, summed
    over the colour channels, from pilot renders ``every`` and ``camera`` (shape (renders, h, w,
    channels), each the mean of ``iterations`` iterations)."""
    mean = every.mean(axis=0)
    scale = iterations / (mean * mean + 0.01)
    var_every = (every.var(axis=0, ddof=1) * scale).sum(axis=-1)
    var_camera = (((camera - mean) ** 2).mean(axis=0) * scale).sum(axis=-1)
    return var_every, var_camera


def path_tracing_wins(var_every, var_camera, time_every: float, time_camera: float) -> bool:
    """Whether path tracing alone gives the image a lower mean relative variance x time per
    iteration than every technique (``time_every``: the light pass, grid and camera pass)."""
    return float(np.mean(var_camera)) * time_camera < float(np.mean(var_every)) * time_every
