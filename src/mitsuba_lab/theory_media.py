"""Problems 6 and 7 of :mod:`mitsuba_lab.theory`: participating media, their predictions and samplers.

Problem 6: the transmittance of a 1D heterogeneous medium, estimated by delta tracking (0 or 1) and by
ratio tracking (a product of null-collision weights), both against one constant majorant; predicted
means, variances and ``sigma_t`` look-up counts. Problem 7: single scattering from a point light along
a ray through a thin homogeneous medium, estimated by distance sampling, equi-angular sampling (Kulla
and Fajardo 2012, "Importance Sampling Techniques for Path Tracing in Participating Media") and their
MIS; predicted variances by quadrature. :mod:`mitsuba_lab.theory` measures them (``run_all``). Pure
numpy: no Mitsuba or Dr.Jit import.
"""
from __future__ import annotations

import math

import numpy as np

from . import metrics
from .plugins.integrators.common.mis_weight import mis_weight
from .theory_rows import TOL_SE, mean_row, ratio_row, variance_row

__all__ = [
    "p6_sigma_t",
    "p6_transmittance",
    "p6_predicted",
    "delta_tracking",
    "ratio_tracking",
    "p7_integrand",
    "p7_equiangular_pdf",
    "p7_distance_pdf",
    "p7_predicted",
    "sample_equiangular",
    "problem6",
    "problem7",
]


def _balance_weights(p_a, p_b):
    """Balance-heuristic weights of two techniques with one sample each (the lab's one MIS weight,
    as ``theory.mis_weights`` applies it)."""
    p_a, p_b = np.broadcast_arrays(np.asarray(p_a, float), np.asarray(p_b, float))
    return mis_weight(p_a, p_b, "balance", 2.0), mis_weight(p_b, p_a, "balance", 2.0)


# Problem 6: sigma_t(x) = A + B sin^2(pi x / L) on [0, L], tracked against a constant majorant
# above its maximum A + B = 1.1 (a loose bound, as a coarse majorant grid cell would give).
P6_LENGTH = 2.0
P6_A, P6_B = 0.6, 0.5
P6_MAJORANT = 1.2


def p6_sigma_t(x):
    """Problem 6's extinction at ``x`` in [0, L]: ``A + B sin^2(pi x / L)``, between 0.6 and 1.1."""
    return P6_A + P6_B * np.sin(np.pi * np.asarray(x) / P6_LENGTH) ** 2


def _p6_optical_depth(x):
    """``int_0^x sigma_t``: ``A x + B (x/2 - L sin(2 pi x / L) / (4 pi))`` (1.7 at x = L)."""
    x = np.asarray(x, float)
    return P6_A * x + P6_B * (x / 2 - P6_LENGTH * np.sin(2 * np.pi * x / P6_LENGTH) / (4 * np.pi))


def p6_transmittance() -> float:
    """``T = exp(-int_0^L sigma_t) = exp(-(A L + B L / 2)) = exp(-1.7) = 0.182684``."""
    return math.exp(-float(_p6_optical_depth(P6_LENGTH)))


def p6_predicted() -> dict[str, float]:
    """Problem 6's predictions: the transmittance, each tracker's variance and look-up count.

    Both trackers walk a Poisson process of tentative collisions of rate ``s`` (the majorant)
    along [0, L]. For such a process ``E[prod_i f(x_i)] = exp(-int s (1 - f))``: given n
    points, they are i.i.d. uniform, so the product's mean is ``m^n`` with ``m = int f / L``,
    and summing over ``n ~ Poisson(s L)`` gives ``exp(-s L (1 - m))``.

    * Delta tracking returns 1 when every tentative collision is null (each independently with
      probability ``1 - sigma_t(x)/s``), else 0: a Bernoulli(T) variable, by the identity with
      ``f = 1 - sigma_t/s``, so its variance is ``T (1 - T)`` exactly (0.149311).
    * Ratio tracking returns ``prod_i (1 - sigma_t(x_i)/s)``: mean T by the same identity, and
      second moment (``f^2``, ``s (1 - f^2) = 2 sigma_t - sigma_t^2 / s``)
      ``exp(-int (2 sigma_t - sigma_t^2 / s))``, with ``int sigma_t^2 = A^2 L + A B L + 3 B^2 L / 8``;
      variance 0.083841, 1.78x below delta tracking's (the factors ``1 - sigma_t/s`` lie in
      [0.08, 0.5] here: a tighter majorant would shrink them, and the variance, further).
    * Look-ups of ``sigma_t``: ratio tracking evaluates every tentative collision, ``s L = 2.4``
      on average; delta tracking stops at the first real one, and a tentative collision at x is
      reached when no real collision came before it (probability ``T(0, x)``), so it evaluates
      ``s int_0^L T(0, x) dx = 1.179`` on average (a trapezoid sum on a fine grid).
    """
    length, s = P6_LENGTH, P6_MAJORANT
    t = p6_transmittance()
    integral_sq = (P6_A**2 + P6_A * P6_B + 3 * P6_B**2 / 8) * length
    second = math.exp(-(2 * float(_p6_optical_depth(length)) - integral_sq / s))
    x = np.linspace(0.0, length, 200_001)
    return {"transmittance": t, "var_delta": t * (1 - t), "var_ratio": second - t**2,
            "lookups_delta": s * float(np.trapezoid(np.exp(-_p6_optical_depth(x)), x)),
            "lookups_ratio": s * length}


# Problem 7: a ray o + t d, t in [0, T_MAX], through a thin homogeneous medium (0.8 mean free
# paths long), passing a point light of intensity I at distance D from the ray, opposite t0.
P7_SIGMA_T, P7_ALBEDO = 0.2, 0.8
P7_INTENSITY = 1.0
P7_D, P7_T0, P7_TMAX = 0.2, 1.5, 4.0


def _p7_distance_to_light(t):
    return np.sqrt(P7_D**2 + (np.asarray(t, float) - P7_T0) ** 2)


def p7_integrand(t):
    """Single scattering at ``t``: ``T(t) sigma_s (1 / 4 pi) I exp(-sigma_t r) / r^2``, ``r`` the
    distance to the light (isotropic phase, no occluder)."""
    t = np.asarray(t, float)
    r = _p7_distance_to_light(t)
    sigma_s = P7_SIGMA_T * P7_ALBEDO
    return np.exp(-P7_SIGMA_T * (t + r)) * sigma_s * P7_INTENSITY / (4 * math.pi * r**2)


def _p7_angles() -> tuple[float, float]:
    """The angles under which the light sees the segment's ends, measured from the foot t0."""
    return math.atan((0.0 - P7_T0) / P7_D), math.atan((P7_TMAX - P7_T0) / P7_D)


def p7_equiangular_pdf(t):
    """Equi-angular density on [0, T_MAX]: ``D / ((theta_b - theta_a)(D^2 + (t - t0)^2))``."""
    theta_a, theta_b = _p7_angles()
    t = np.asarray(t, float)
    inside = (t >= 0) & (t <= P7_TMAX)
    return np.where(inside, P7_D / ((theta_b - theta_a) * _p7_distance_to_light(t) ** 2), 0.0)


def p7_distance_pdf(t):
    """Free-flight density ``sigma_t exp(-sigma_t t)`` on [0, T_MAX]; the rest of its mass,
    ``exp(-sigma_t T_MAX) = 0.449``, is the flight escaping past T_MAX (no medium sample)."""
    t = np.asarray(t, float)
    inside = (t >= 0) & (t <= P7_TMAX)
    return np.where(inside, P7_SIGMA_T * np.exp(-P7_SIGMA_T * t), 0.0)


def p7_predicted() -> dict[str, float]:
    """Problem 7's integral and single-sample variances, by quadrature.

    ``Var = int f^2 / p - F^2`` for each density (an escaped distance sample scores 0 and adds
    nothing to the first term); for the MIS estimator, one sample of each density weighted by
    the balance heuristic (the lab's ``mis_weights``),
    ``sum_i (int w_i^2 f^2 / p_i - (int w_i f)^2)``. The integrals substitute
    ``t = t0 + D tan(theta)`` (the equi-angular map), which spreads the 1/r^2 peak of width D
    over the grid: a trapezoid sum in theta. F = 0.12751; variances 1.94e-4 (equi-angular),
    9.04e-2 (distance sampling, 465x more: its samples rarely land within D of the light's foot,
    where the integrand is ~1/D^2) and 2.28e-3 for MIS of the two (two samples): 40x below
    distance sampling, 12x above equi-angular alone, whose density is nearly proportional to f
    here (what the balance heuristic gives distance samples near the peak still scores ~f/p_d).
    """
    theta_a, theta_b = _p7_angles()
    theta = np.linspace(theta_a, theta_b, 200_001)
    t = np.clip(P7_T0 + P7_D * np.tan(theta), 0.0, P7_TMAX)     # ends land a rounding outside
    jacobian = P7_D / np.cos(theta) ** 2

    def integral(values):
        return float(np.trapezoid(values * jacobian, theta))

    f, p_e, p_d = p7_integrand(t), p7_equiangular_pdf(t), p7_distance_pdf(t)
    truth = integral(f)
    w_e, w_d = _balance_weights(p_e, p_d)
    mis = sum(integral(w**2 * f**2 / p) - integral(w * f) ** 2 for w, p in ((w_e, p_e), (w_d, p_d)))
    return {"truth": truth, "var_equiangular": integral(f**2 / p_e) - truth**2,
            "var_distance": integral(f**2 / p_d) - truth**2, "var_mis": mis}


def _track(rng, n: int, sigma_t, majorant: float, length: float, ratio: bool):
    """Tentative collisions at rate ``majorant`` over [0, length]. Ratio tracking multiplies
    each lane's estimate by the null-collision probability ``1 - sigma_t/majorant`` at every one;
    delta tracking plays it instead and ends the lane, at 0, on a real collision."""
    x, estimate, lookups = np.zeros(n), np.ones(n), np.zeros(n, dtype=np.int64)
    alive = np.arange(n)
    while alive.size:
        x[alive] += rng.exponential(1 / majorant, alive.size)
        alive = alive[x[alive] < length]
        lookups[alive] += 1
        real_share = sigma_t(x[alive]) / majorant
        if ratio:
            estimate[alive] *= 1 - real_share
        else:
            real = rng.random(alive.size) < real_share
            estimate[alive[real]] = 0.0
            alive = alive[~real]
    return estimate, lookups


def delta_tracking(rng, n: int, sigma_t=p6_sigma_t, majorant: float = P6_MAJORANT,
                   length: float = P6_LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """``n`` delta-tracking transmittance estimates over [0, length] (1 when the walk escapes,
    0 at its first real collision) and the number of ``sigma_t`` look-ups each made."""
    return _track(rng, n, sigma_t, majorant, length, ratio=False)


def ratio_tracking(rng, n: int, sigma_t=p6_sigma_t, majorant: float = P6_MAJORANT,
                   length: float = P6_LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """``n`` ratio-tracking estimates (the product of ``1 - sigma_t/majorant`` over every tentative
    collision in [0, length]) and the number of ``sigma_t`` look-ups each made."""
    return _track(rng, n, sigma_t, majorant, length, ratio=True)


def sample_equiangular(rng, n: int) -> np.ndarray:
    """``n`` distances with density :func:`p7_equiangular_pdf`: the angle from the light,
    uniform between the segment's ends, mapped back onto the ray (``t0 + D tan(theta)``)."""
    theta_a, theta_b = _p7_angles()
    return P7_T0 + P7_D * np.tan(rng.uniform(theta_a, theta_b, n))


def _p7_equiangular_values(rng, n):
    t = sample_equiangular(rng, n)
    return p7_integrand(t) / p7_equiangular_pdf(t)


def _p7_distance_values(rng, n):
    """Free flights from the ray's origin; one past T_MAX escapes and scores 0."""
    t = rng.exponential(1 / P7_SIGMA_T, n)
    inside = t <= P7_TMAX
    out = np.zeros(n)
    out[inside] = p7_integrand(t[inside]) / p7_distance_pdf(t[inside])
    return out


def _p7_mis_values(rng, n):
    """One equi-angular and one distance sample per estimate, balance-heuristic weights."""
    total = np.zeros(n)
    for which, t in enumerate((sample_equiangular(rng, n), rng.exponential(1 / P7_SIGMA_T, n))):
        inside = t <= P7_TMAX
        t = t[inside]
        p_e, p_d = p7_equiangular_pdf(t), p7_distance_pdf(t)
        weight = _balance_weights(p_e, p_d)[which]
        total[inside] += weight * p7_integrand(t) / (p_e if which == 0 else p_d)
    return total


# --------------------------------------------------------------------------
# Rows: prediction vs measurement (``theory.run_all`` runs these as P6, P7)
# --------------------------------------------------------------------------
def problem6(rng, n):
    count = n["p6"]
    note = f"sigma_t = 0.6 + 0.5 sin^2(pi x/2) on [0, 2], majorant 1.2, {count} walks, tol {TOL_SE:g} SE"
    pred = p6_predicted()
    delta, delta_lookups = delta_tracking(rng, count)
    ratio, ratio_lookups = ratio_tracking(rng, count)
    var_se = (metrics.variance_standard_error(delta), metrics.variance_standard_error(ratio))
    return [
        mean_row("P6", "T_delta", pred["transmittance"], delta, note),
        variance_row("P6", "var_delta", pred["var_delta"], delta, note),
        mean_row("P6", "T_ratio", pred["transmittance"], ratio, note),
        variance_row("P6", "var_ratio", pred["var_ratio"], ratio, note),
        ratio_row("P6", "var_ratio_delta/ratio", pred["var_delta"] / pred["var_ratio"],
                   metrics.mc_variance(delta), var_se[0], metrics.mc_variance(ratio), var_se[1], note),
        mean_row("P6", "lookups_delta", pred["lookups_delta"], delta_lookups, note),
        mean_row("P6", "lookups_ratio", pred["lookups_ratio"], ratio_lookups, note),
    ]


def problem7(rng, n):
    count = n["p7"]
    note = (f"sigma_t 0.2, albedo 0.8, ray [0, 4], light D=0.2 from t0=1.5, {count} samples, "
            f"tol {TOL_SE:g} SE")
    pred = p7_predicted()
    values = {"equiangular": _p7_equiangular_values(rng, count),
              "distance": _p7_distance_values(rng, count),
              "mis": _p7_mis_values(rng, count)}
    rows = []
    for name, samples in values.items():
        rows.append(mean_row("P7", f"mean_{name} (truth)", pred["truth"], samples, note))
        rows.append(variance_row("P7", f"var_{name}", pred[f"var_{name}"], samples, note))
    dist, equi = values["distance"], values["equiangular"]
    rows.append(ratio_row("P7", "var_ratio_distance/equiangular",
                           pred["var_distance"] / pred["var_equiangular"],
                           metrics.mc_variance(dist), metrics.variance_standard_error(dist),
                           metrics.mc_variance(equi), metrics.variance_standard_error(equi), note))
    return rows
