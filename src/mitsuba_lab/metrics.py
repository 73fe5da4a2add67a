"""Error and efficiency metrics for Monte Carlo renders (pure numpy).

Images are float arrays of shape ``(H, W, C)`` or ``(H, W)``; a *stack* is
``R`` independent renders of the same image, shape ``(R, H, W[, C])``.
Every function does one job and states its formula; nothing here imports
Mitsuba or Dr.Jit, so the module loads instantly and is usable on the
output of any renderer.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = [
    "mse",
    "rel_mse",
    "per_pixel_variance",
    "mean_variance",
    "variance_of_mean",
    "bias_squared",
    "efficiency",
    "flip_hdr",
    "ciede2000_mean",
    "loglog_fit",
    "loglog_slope",
    "interpolate_at_time",
    "region",
    "fraction_rect_to_pixels",
    "z_score",
    "rmse_from_trials",
    "rmse_standard_error",
    "mc_variance",
    "standard_error",
    "variance_standard_error",
]


def _f64(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64)


# --------------------------------------------------------------------------
# Image error
# --------------------------------------------------------------------------
def mse(img, ref) -> float:
    """Mean squared error ``mean_{pixels, channels} (img - ref)^2``."""
    return float(np.mean((_f64(img) - _f64(ref)) ** 2))


def rel_mse(img, ref, eps: float = 1e-2) -> float:
    """Relative MSE ``mean_{pixels, channels} (img - ref)^2 / (ref^2 + eps)``.

    Dividing by ``ref^2`` makes the error scale-free, so dark and bright
    regions count alike; ``eps`` keeps near-black pixels (``ref ~ 0``) from
    dominating or dividing by zero. ``1e-2`` is the customary value in the
    adaptive-sampling and denoising literature (e.g. Rousselle et al.).
    """
    ref = _f64(ref)
    return float(np.mean((_f64(img) - ref) ** 2 / (ref**2 + eps)))


# --------------------------------------------------------------------------
# Variance and bias from a stack of independent renders
# --------------------------------------------------------------------------
def per_pixel_variance(stack) -> np.ndarray:
    """Unbiased sample variance across renders, per pixel and channel.

    ``s^2_p = 1/(R-1) * sum_r (img_r[p] - mean_r img_r[p])^2`` for a stack of
    shape ``(R, H, W[, C])``; returns shape ``(H, W[, C])``. Needs ``R >= 2``.
    """
    stack = _f64(stack)
    if stack.shape[0] < 2:
        raise ValueError("per-pixel variance needs at least 2 renders")
    return np.var(stack, axis=0, ddof=1)


def mean_variance(stack) -> float:
    """Image-averaged per-pixel variance ``mean_p s^2_p`` (the MSE of one render
    about its own expectation, i.e. the variance part of its error)."""
    return float(np.mean(per_pixel_variance(stack)))


def variance_of_mean(stack) -> np.ndarray:
    """Per-pixel variance of the average of the ``R`` renders: ``s^2_p / R``."""
    stack = _f64(stack)
    return per_pixel_variance(stack) / stack.shape[0]


def bias_squared(stack, ref, ref_floor=0.0, tile: int | None = None) -> tuple[float, float]:
    """Estimate the squared bias of the estimator that produced ``stack``.

    For each pixel ``p`` (channels averaged), with ``m_p = mean_r img_r[p]``::

        d_p = (m_p - ref_p)^2 - s^2_p / R - ref_floor_p

    Because ``E[(m_p - ref_p)^2] = bias_p^2 + Var[m_p] + Var[ref_p]`` for an
    independent reference, and ``s^2_p / R`` is unbiased for ``Var[m_p]``,
    ``d_p`` is an unbiased estimate of ``bias_p^2`` when ``ref_floor`` is the
    per-pixel variance of the reference (a scalar image average is fine when
    only the mean is wanted). The estimate may therefore be slightly negative
    for an unbiased estimator.

    Returns ``(mean_p d_p, std_p(d_p) / sqrt(P))``. The standard error treats
    the ``P`` pixels as independent samples of ``d``; channels of one pixel
    are averaged first because they share sample paths. Correlated pixels (a
    wide reconstruction filter, a photon map's kernel) make this error bar optimistic;
    with ``tile`` the error is the larger of that and the one from the means of
    ``tile`` x ``tile`` pixel blocks, which holds correlations shorter than a block.
    """
    stack = _f64(stack)
    n_renders = stack.shape[0]
    mean_img = stack.mean(axis=0)
    d = (
        (mean_img - _f64(ref)) ** 2
        - per_pixel_variance(stack) / n_renders
        - _f64(ref_floor)
    )
    d = np.broadcast_to(d, mean_img.shape)
    if d.ndim == 3:
        d = d.mean(axis=-1)
    if tile and tile > 1 and d.ndim == 2:
        return float(d.mean()), max(_pixel_se(d.ravel()), _tile_se(d, tile))
    d = d.ravel()
    return float(d.mean()), _pixel_se(d)


def _pixel_se(d: np.ndarray) -> float:
    return float(np.std(d, ddof=1) / math.sqrt(d.size)) if d.size > 1 else math.inf


def _tile_se(d: np.ndarray, tile: int) -> float:
    """The standard error of ``d``'s mean from the means of ``tile`` x ``tile`` blocks (the
    whole blocks; their spread holds the correlation of neighbouring pixels)."""
    h, w = (d.shape[0] // tile) * tile, (d.shape[1] // tile) * tile
    blocks = d[:h, :w].reshape(h // tile, tile, w // tile, tile).mean(axis=(1, 3)).ravel()
    return _pixel_se(blocks) if blocks.size > 1 else math.inf


# --------------------------------------------------------------------------
# Efficiency and convergence curves
# --------------------------------------------------------------------------
def efficiency(mse_value: float, time_s: float) -> float:
    """Monte Carlo efficiency ``1 / (MSE * time)`` (Veach; higher is better).

    A zero product (exact image, or a time below the clock's resolution)
    returns ``inf``: the efficiency is unbounded, and ``inf`` sorts as best
    instead of raising mid-experiment. Negative inputs raise ``ValueError``;
    NaN propagates.
    """
    if mse_value < 0 or time_s < 0:
        raise ValueError("mse and time must be non-negative")
    product = mse_value * time_s
    if product == 0:
        return math.inf
    return 1.0 / product


def _positive_log(values, name: str) -> np.ndarray:
    values = _f64(values)
    if np.any(~(values > 0)):
        raise ValueError(f"{name} must be positive (log-log space)")
    return np.log(values)


def loglog_fit(times, errors) -> tuple[float, float]:
    """Least-squares line ``log(error) = slope * log(time) + intercept``.

    Returns ``(slope, intercept)``. An unbiased Monte Carlo estimator has
    ``MSE ~ sigma^2 / N ~ 1 / time``, so ``slope ~ -1`` for MSE vs time
    (``-1/2`` for RMSE). Needs at least two distinct times.
    """
    log_t = _positive_log(times, "times")
    log_e = _positive_log(errors, "errors")
    if log_t.size < 2 or np.ptp(log_t) == 0:
        raise ValueError("need at least two distinct times")
    slope, intercept = np.polyfit(log_t, log_e, 1)
    return float(slope), float(intercept)


def loglog_slope(times, errors) -> float:
    """Slope of :func:`loglog_fit` (about -1 for unbiased MC, MSE vs time)."""
    return loglog_fit(times, errors)[0]


def interpolate_at_time(times, errors, t: float) -> float:
    """Error of a convergence curve at time budget ``t``, interpolated in log-log.

    Piecewise-linear in ``(log time, log error)``, which is exact for power
    laws such as ``MSE = c / time``. Outside ``[min(times), max(times)]`` it
    returns NaN rather than extrapolating: a budget the experiment did not
    reach has no measured error.
    """
    log_t = _positive_log(times, "times")
    log_e = _positive_log(errors, "errors")
    if not t > 0:
        return math.nan
    order = np.argsort(log_t)
    log_t, log_e = log_t[order], log_e[order]
    x = math.log(t)
    if x < log_t[0] or x > log_t[-1]:
        return math.nan
    return float(np.exp(np.interp(x, log_t, log_e)))


# --------------------------------------------------------------------------
# Perceptual error (optional packages, imported when used)
# --------------------------------------------------------------------------
def flip_hdr(img, ref) -> float:
    """Mean HDR-FLIP error (Andersson et al. 2021, the ``flip-evaluator`` package)
    of linear RGB ``img`` against ``ref``, default viewing conditions (67 ppd)."""
    import flip_evaluator

    clean = lambda a: np.ascontiguousarray(np.clip(np.nan_to_num(_f64(a)), 0, None), dtype=np.float32)
    _, mean_error, _ = flip_evaluator.evaluate(clean(ref), clean(img), "HDR", applyMagma=False)
    return float(mean_error)


def ciede2000_mean(img, ref) -> float:
    """Mean CIEDE2000 colour difference of the sRGB-displayed images.

    Linear RGB is clipped to [0, 1] (what an sRGB display shows without tone
    mapping), converted to CIE XYZ with the sRGB primaries and to CIE L*a*b*
    (D65), then compared pixel by pixel with colour-science's CIE 2000 formula.
    """
    import colour

    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]

    def lab(a):
        rgb = np.clip(np.nan_to_num(_f64(a)[..., :3]), 0.0, 1.0)
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, "sRGB"), d65)

    return float(np.mean(colour.delta_E(lab(img), lab(ref), method="CIE 2000")))


# --------------------------------------------------------------------------
# Regions of interest
# --------------------------------------------------------------------------
def region(img, rect) -> np.ndarray:
    """Crop ``img[y0:y1, x0:x1]`` for ``rect = (x0, y0, x1, y1)`` in pixels.

    Origin is the top-left pixel, ends are exclusive (numpy slicing). Raises
    ``ValueError`` for an empty or out-of-bounds rectangle instead of
    silently returning a clipped crop.
    """
    x0, y0, x1, y1 = (int(v) for v in rect)
    height, width = np.shape(img)[:2]
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise ValueError(f"rect {rect} is empty or outside a {width}x{height} image")
    return np.asarray(img)[y0:y1, x0:x1]


def fraction_rect_to_pixels(rect_frac, width: int, height: int) -> tuple[int, int, int, int]:
    """Convert ``(fx0, fy0, fx1, fy1)`` in ``[0, 1]`` image fractions to pixels.

    Edges round half-up to the nearest pixel boundary (``0.3 * 10`` gives 3
    despite floating point, ``0.25 * 10`` gives 3), are clamped to the image,
    and the result always keeps at least one pixel per axis. The output suits :func:`region`.
    """
    fx0, fy0, fx1, fy1 = rect_frac

    def edges(f0: float, f1: float, size: int) -> tuple[int, int]:
        lo = min(max(math.floor(f0 * size + 0.5), 0), size - 1)
        hi = min(max(math.floor(f1 * size + 0.5), lo + 1), size)
        return lo, hi

    x0, x1 = edges(fx0, fx1, width)
    y0, y1 = edges(fy0, fy1, height)
    return x0, y0, x1, y1


# --------------------------------------------------------------------------
# Statistics on independent trials and samples
# --------------------------------------------------------------------------
def z_score(mean_a, var_a, n_a, mean_b, var_b, n_b):
    """Welch z-score of a difference of two independent sample means.

    ``z = (mean_a - mean_b) / sqrt(var_a / n_a + var_b / n_b)`` where ``var_*``
    are the per-sample variances (for a side known only by the variance of its
    mean, pass that variance with ``n = 1``). With zero standard error the score
    is 0 for equal means and ``+-inf`` otherwise. Works elementwise on arrays (a
    float for scalars). ``mitsuba-lab check`` scores every strategy's mean against
    the reference with it, and the tests score pixel blocks with it.
    """
    diff = np.asarray(mean_a, dtype=np.float64) - np.asarray(mean_b, dtype=np.float64)
    se = np.sqrt(np.asarray(var_a, dtype=np.float64) / n_a + np.asarray(var_b, dtype=np.float64) / n_b)
    safe = np.where(se > 0, se, 1.0)
    z = np.where(se > 0, diff / safe, np.where(diff == 0, 0.0, np.copysign(np.inf, diff)))
    return float(z) if z.ndim == 0 else z


def rmse_from_trials(estimates, truth) -> float:
    """Root-mean-square error over independent trials, ``sqrt(mean_t (est_t - I)^2)``."""
    return float(np.sqrt(np.mean((_f64(estimates) - _f64(truth)) ** 2)))


def rmse_standard_error(estimates, truth) -> float:
    """Standard error of :func:`rmse_from_trials` over ``T`` trials.

    With squared errors ``e_t^2``, ``SE(MSE) = std(e^2) / sqrt(T)`` and by the
    delta method ``SE(RMSE) = SE(MSE) / (2 RMSE)``. For normally distributed
    errors this is ``RMSE / sqrt(2T)``; using the measured spread of ``e^2``
    keeps it honest for heavy-tailed estimators.
    """
    sq = (_f64(estimates) - _f64(truth)).ravel() ** 2
    rmse = math.sqrt(sq.mean())
    if rmse == 0:
        return 0.0
    return float(np.std(sq, ddof=1) / math.sqrt(sq.size) / (2 * rmse))


def mc_variance(samples) -> float:
    """Single-sample variance ``sigma^2 = Var[f(X)/p(X)]`` (unbiased, ddof=1)."""
    return float(np.var(_f64(samples), ddof=1))


def standard_error(samples) -> float:
    """Standard error of the sample mean, ``sqrt(sigma^2 / n)``."""
    samples = _f64(samples).ravel()
    return math.sqrt(mc_variance(samples) / samples.size)


def variance_standard_error(samples) -> float:
    """Standard error of :func:`mc_variance` from ``n`` i.i.d. samples.

    ``Var[s^2] = (mu4 - sigma^4 (n-3)/(n-1)) / n`` with the central moments
    estimated from the samples; a zero-variance estimator gives 0.
    """
    samples = _f64(samples).ravel()
    n = samples.size
    centred = samples - samples.mean()
    m2 = np.mean(centred**2)
    m4 = np.mean(centred**4)
    return float(math.sqrt(max(m4 - m2**2 * (n - 3) / (n - 1), 0.0) / n))


#: Rec. 709 / linear-sRGB luminance weights (Y of a linear sRGB colour).
LUMINANCE = (0.2126, 0.7152, 0.0722)


def luminance(image: np.ndarray) -> np.ndarray:
    """Y of the last axis' linear sRGB channels (a one-channel image is its own luminance)."""
    if np.shape(image)[-1] == 1:
        return image[..., 0]
    return image[..., 0] * LUMINANCE[0] + image[..., 1] * LUMINANCE[1] + image[..., 2] * LUMINANCE[2]
