"""Rows of :mod:`mitsuba_lab.theory`: a predicted quantity beside its measurement and tolerance.

Each row is ``{"problem", "quantity", "predicted", "measured", "tolerance", "note"}``; Monte Carlo
rows take their tolerance from the measurement's own standard error (``TOL_SE`` of them), exact
identities from floating-point rounding (``FP_TOL``).
"""
from __future__ import annotations

import math

import numpy as np

from . import metrics

__all__ = ["TOL_SE", "FP_TOL", "row", "rmse_row", "ratio_row", "variance_row", "mean_row"]

# A Monte Carlo row passes when |measured - predicted| <= TOL_SE standard
# errors: ~6e-5 two-sided false-alarm chance per row for normal errors.
TOL_SE = 4.0
# Exact identities differ from their prediction by rounding only (a few ulps).
FP_TOL = 1e-12


def row(problem, quantity, predicted, measured, tolerance, note=""):
    return {"problem": problem, "quantity": quantity, "predicted": float(predicted),
            "measured": float(measured), "tolerance": float(tolerance), "note": note}


def rmse_row(problem, quantity, predicted, estimates, truth, note):
    rmse = metrics.rmse_from_trials(estimates, truth)
    se = metrics.rmse_standard_error(estimates, truth)
    return row(problem, quantity, predicted, rmse, TOL_SE * se, note), rmse, se


def ratio_row(problem, quantity, predicted, num, num_se, den, den_se, note):
    """Ratio of two independent estimates; relative errors add in quadrature."""
    ratio = num / den
    rel_se = math.hypot(num_se / num, den_se / den)
    return row(problem, quantity, predicted, ratio, TOL_SE * ratio * rel_se, note)


def variance_row(problem, quantity, predicted, samples, note):
    return row(problem, quantity, predicted, metrics.mc_variance(samples),
               TOL_SE * metrics.variance_standard_error(samples), note)


def mean_row(problem, quantity, predicted, samples, note):
    return row(problem, quantity, predicted, np.mean(samples),
               TOL_SE * metrics.standard_error(samples), note)
