"""check's row values: finite fraction, negative pixels, max, fireflies, mean and its z-score,
rays per pixel (pure numpy; the rule of each is in the package doc)."""
from __future__ import annotations

import math

import numpy as np

from .. import metrics
from ..metrics import luminance

#: Ray kinds with a column of their own (the path tracers'); the bidirectional integrators'
#: other kinds are summed in ``other_rays_per_pixel``.
RAY_COLUMNS = ("camera", "extension", "shadow")
#: The firefly rule's neighbourhood (pixels a side) and its floor (a fraction of the mean).
FIREFLY_WINDOW = 5
FIREFLY_FLOOR = 0.01


def firefly_count(image: np.ndarray, k: float, floor: float) -> int:
    """Pixels whose luminance exceeds k * max(5x5 local median, floor) (module doc)."""
    y = np.nan_to_num(luminance(image), nan=0.0, posinf=np.finfo(np.float32).max)
    pad = FIREFLY_WINDOW // 2
    windows = np.lib.stride_tricks.sliding_window_view(np.pad(y, pad, mode="edge"),
                                                       (FIREFLY_WINDOW, FIREFLY_WINDOW))
    local = np.median(windows, axis=(-2, -1))
    return int(np.sum(y > k * np.maximum(local, floor)))


def reference_mean_variance(variance: np.ndarray) -> float:
    """Variance of a reference's mean luminance, from the per-pixel, per-channel variance of
    its mean image (H x W x C). Pixels are taken as independent (a box filter: each sample
    lands in one pixel); a pixel's luminance variance is (sum_c w_c sd_c)^2, the largest the
    channels' variances allow, reached when they move together, as the channels of one light
    path do (module doc)."""
    sd = np.sqrt(np.asarray(variance, dtype=np.float64)[..., :3])
    pixels = sd.shape[0] * sd.shape[1]
    return float(np.sum(luminance(sd) ** 2) / pixels ** 2)


def measure(stack: np.ndarray, rays: dict, seconds: float, ref: dict, k: float) -> dict:
    """Row values for one strategy's splits (R x H x W x C) against the reference's summary
    (``reference_summary``)."""
    finite = np.isfinite(stack)
    image = stack.mean(axis=0)
    pixels = image.shape[0] * image.shape[1]
    negative = int(np.sum(np.any(stack < 0, axis=-1)))
    means = luminance(stack).mean(axis=(1, 2))
    row = {"finite_fraction": float(finite.mean()), "negative_pixels": negative,
           "max_value": float(stack[finite].max()) if finite.any() else math.nan,
           "mean": float(means.mean()), "time_s": seconds,
           **rays_per_pixel(rays, pixels)}
    row["fireflies"] = firefly_count(image, k, max(FIREFLY_FLOOR * ref["mean"], 1e-12))
    row["ref_mean"] = ref["mean"]
    row["z"] = (metrics.z_score(means.mean(), means.var(ddof=1), len(means), ref["mean"], ref["mean_variance"], 1)
                if ref["finite"] else math.nan)
    row["split_means"] = means
    return row


def rays_per_pixel(rays: dict, pixels: int) -> dict:
    """Row values: rays per pixel of each kind in ``RAY_COLUMNS``, and of every other kind summed
    (lab_bdpt's connection, light subpath and sensor rays, lab_vcm's merge lookups, lab_photon's
    photon segments)."""
    row = {f"{kind}_rays_per_pixel": rays.get(kind, 0) / pixels for kind in RAY_COLUMNS}
    row["other_rays_per_pixel"] = sum(v for k, v in rays.items() if k not in RAY_COLUMNS) / pixels
    return row


def reference_summary(reference, k: float) -> tuple[dict, dict]:
    """(summary for ``measure``, the reference's own row values) of a cached reference
    (``experiment.reference.Reference``): its mean image stands in for the combined image of
    the splits, so finite fraction, negative pixels, max value and fireflies are those of the
    mean image."""
    image, variance = reference.image.astype(np.float64), reference.variance
    finite = np.isfinite(image)
    pixels = luminance(image)
    mean = float(pixels.mean())
    summary = {"mean": mean, "mean_variance": reference_mean_variance(variance), "pixels": pixels,
               "finite": bool(finite.all() and np.isfinite(variance).all()),
               "image": image[..., :3], "variance": np.asarray(variance, dtype=np.float64)[..., :3]}
    row = {"finite_fraction": float(finite.mean()), "negative_pixels": int(np.sum(np.any(image < 0, axis=-1))),
           "max_value": float(image[finite].max()) if finite.any() else math.nan, "mean": mean,
           "time_s": float(reference.meta.get("seconds", 0.0)),
           **rays_per_pixel({}, 1)}
    floor = FIREFLY_FLOOR * float(np.nanmean(pixels))
    row["fireflies"] = firefly_count(image, k, max(floor, 1e-12))
    return summary, row
