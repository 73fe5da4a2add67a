"""Error spectra and convergence slopes for the sampler report.

Small pure functions (the first three) and two report helpers built on them:

* ``radial_power_spectrum``: radially averaged power spectrum of an error image
  (Ulichney 1987's tool for judging dither and blue noise; Heitz & Belcour 2019
  and Ahmed & Wonka 2020 use it for Monte Carlo error images);
* ``low_frequency_fraction``: the share of the error's power at radial
  frequencies below ``cutoff`` x Nyquist (blue-noise error has less there than
  white-noise error of the same MSE);
* ``bright_mask``, ``rows_below_bright``: where a reference image shows an
  emitter directly. On the Cornell box at 64 spp, the 1% of pixels on and around
  the light carry 40-50% of a QMC sampler's MSE (over 90% with direct lighting only):
  anti-aliasing a 30:1 step. Those errors line up along the edge and swamp the
  spectrum, so the benchmarks report MSE and spectra without them as well;
* ``mse_slope``: least-squares slope of log MSE against log spp (-1 for plain
  Monte Carlo, steeper for stratified / QMC samplers on smooth integrands);
* ``fit_slope``: the same fit with its standard error and a word on whether it can be
  trusted (``slope_cell``, ``slope_note`` print it in the report's tables);
* ``slope_table``, ``plot_error_spectra``: Markdown table and PNG for the report,
  given the report's groups {(strategy, sampler): [PointStats]}.
"""
from __future__ import annotations

import math
import os
from typing import NamedTuple

import numpy as np

from ...reporting import markdown_table
from ...reporting.figures import legend_outside, pyplot, save_figure, series_styles


def _luminance_error(err: np.ndarray) -> np.ndarray:
    err = np.asarray(err, dtype=np.float64)
    if err.ndim == 3:
        err = err.mean(axis=-1)
    if err.ndim != 2:
        raise ValueError(f"expected an error image of shape (H, W) or (H, W, C), got {err.shape}")
    return err


def _radius(shape) -> np.ndarray:
    """Radial frequency of each bin of an unshifted 2D FFT, in cycles per pixel."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.fftfreq(shape[1])[None, :]
    return np.hypot(fy, fx)


def radial_power_spectrum(err: np.ndarray, n_bins: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Radially averaged power spectrum of an error image (channels averaged first).

    Returns (frequency, power): bin centres in cycles per pixel on (0, 0.5] and
    the mean of |FFT|^2 / (H W) over the frequencies in each annulus. The mean
    is removed first (the DC bin is excluded), so for white noise of variance
    s^2 every bin is about s^2 (Parseval). ``n_bins`` defaults to min(H, W) // 2.
    """
    e = _luminance_error(err)
    e = e - e.mean()
    power = np.abs(np.fft.fft2(e)) ** 2 / e.size
    radius = _radius(e.shape)
    n_bins = n_bins or max(1, min(e.shape) // 2)
    edges = np.linspace(0.0, 0.5, n_bins + 1)
    which = np.digitize(radius.ravel(), edges[1:-1], right=True)
    keep = (radius.ravel() > 0) & (radius.ravel() <= 0.5)
    sums = np.bincount(which[keep], weights=power.ravel()[keep], minlength=n_bins)
    counts = np.bincount(which[keep], minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    return 0.5 * (edges[:-1] + edges[1:]), mean


def low_frequency_fraction(err: np.ndarray, cutoff: float = 0.25) -> float:
    """Share of the error power at radial frequency < cutoff x Nyquist, among all
    frequencies within the Nyquist circle (DC excluded). White noise gives about
    the area share, pi (cutoff/2)^2 / (pi/4) = cutoff^2; blue noise gives less."""
    if not 0 < cutoff <= 1:
        raise ValueError(f"cutoff must be in (0, 1], got {cutoff}")
    e = _luminance_error(err)
    power = np.abs(np.fft.fft2(e - e.mean())) ** 2
    radius = _radius(e.shape)
    inside = (radius > 0) & (radius <= 0.5)
    total = power[inside].sum()
    if total == 0:
        return math.nan
    return float(power[inside & (radius < 0.5 * cutoff)].sum() / total)


def bright_mask(reference: np.ndarray, threshold: float, grow: int = 1) -> np.ndarray:
    """Pixels whose reference luminance (channel mean) exceeds ``threshold``, grown
    by ``grow`` pixels in the 8-neighbourhood (the edge pixels half on the emitter)."""
    mask = _luminance_error(reference) > threshold
    for _ in range(grow):
        padded = np.pad(mask, 1)
        mask = np.logical_or.reduce([padded[1 + dy:padded.shape[0] - 1 + dy, 1 + dx:padded.shape[1] - 1 + dx]
                                     for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    return mask


def rows_below_bright(reference: np.ndarray, threshold: float, margin: int = 2) -> int:
    """First image row that starts ``margin`` rows below the last row holding a pixel
    brighter than ``threshold``: ``err[row:]`` is a rectangle free of the emitter, as a
    spectrum needs (0 when nothing is that bright; the height when all rows are)."""
    rows = np.flatnonzero(bright_mask(reference, threshold, grow=0).any(axis=1))
    return 0 if rows.size == 0 else min(int(rows.max()) + 1 + margin, reference.shape[0])


#: A pixel brighter than this many times the median reference luminance sees an emitter.
EMITTER_OVER_MEDIAN = 10.0


def spectrum_rows(reference: np.ndarray) -> int:
    """First row of the error images a report's spectrum uses: below the pixels brighter
    than EMITTER_OVER_MEDIAN x the median luminance (a directly visible emitter) when at
    least half the rows remain, else 0 (the whole image)."""
    lum = _luminance_error(reference)
    median = float(np.median(lum))
    if not median > 0:
        return 0
    row0 = rows_below_bright(reference, EMITTER_OVER_MEDIAN * median)
    return row0 if row0 <= lum.shape[0] // 2 else 0


def mse_slope(spp, mse) -> float:
    """Least-squares slope of log(MSE) against log(spp); needs >= 2 distinct spp and MSE > 0."""
    spp = np.asarray(spp, dtype=np.float64)
    mse = np.asarray(mse, dtype=np.float64)
    if spp.shape != mse.shape or len(np.unique(spp)) < 2:
        raise ValueError("mse_slope needs matching spp and MSE arrays with at least two distinct spp")
    if np.any(spp <= 0) or np.any(~np.isfinite(mse)) or np.any(mse <= 0):
        raise ValueError("mse_slope needs positive spp and positive, finite MSE values")
    return float(np.polyfit(np.log(spp), np.log(mse), 1)[0])


#: A fitted slope is not trusted with a standard error above this ...
SLOPE_SE_LIMIT = 0.5
#: ... nor when it lies more than two standard errors outside this range: MSE against effort
#: falls as -1 for unbiased Monte Carlo, about as -2/3 for progressive photon mapping, and
#: steeper than -1 only where stratification or QMC helps (-2 to -3 on smooth integrands).
SLOPE_RANGE = (-3.0, 0.0)


#: ... nor from points whose x (time, spp) spans less than this factor.
SLOPE_MIN_SPREAD = 2.0


class SlopeFit(NamedTuple):
    slope: float
    se: float                       # NaN when neither the scatter nor the points' errors give one
    points: int
    problem: str                    # why it cannot be trusted; "" when it can


def fit_slope(x, y, y_se=None, axis: str | None = None) -> SlopeFit:
    """Least-squares slope of log y against log x, with a standard error and a verdict.

    The standard error is the larger of two: from the scatter about the line (3 points or
    more) and from the points' own standard errors ``y_se`` (propagated through the fit,
    sigma(log y) = se / y, the points taken as independent). Not trusted (``problem``): fewer
    than 3 points (a line through 2 always fits: "too few to check the line"), a standard
    error above SLOPE_SE_LIMIT, a slope more than two standard errors outside SLOPE_RANGE, or
    points whose largest x is less than SLOPE_MIN_SPREAD times their smallest ("too short a
    time range", ``axis`` naming x: 2 points 1.2x apart in time give a slope that is mostly
    noise). Pairs with x or y <= 0 are left out (log axes); under 2 distinct x the slope is NaN."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    s = np.full(x.shape, np.nan) if y_se is None else np.asarray(y_se, np.float64)
    keep = (x > 0) & (y > 0) & np.isfinite(y)
    lx, ly, sigma = np.log(x[keep]), np.log(y[keep]), s[keep] / y[keep]
    n = int(lx.size)
    if n < 2 or np.ptp(lx) == 0:
        return SlopeFit(math.nan, math.nan, n, "fewer than 2 points")
    dx = lx - lx.mean()
    sxx = float(dx @ dx)
    slope = float(dx @ (ly - ly.mean()) / sxx)
    candidates = []
    if n >= 3:
        residual = ly - ly.mean() - slope * dx
        candidates.append(math.sqrt(float(residual @ residual) / (n - 2) / sxx))
    if np.all(np.isfinite(sigma)):
        candidates.append(math.sqrt(float(((dx / sxx) ** 2) @ sigma ** 2)))
    se = max(candidates) if candidates else math.nan
    reach = 2 * se if not math.isnan(se) else 0.0
    problems = []
    spread = math.exp(float(np.ptp(lx)))
    if spread < SLOPE_MIN_SPREAD * (1 - 1e-9):        # (2x exactly is enough: log round-off aside)
        problems.append(f"too short a{f' {axis}' if axis else ''} range ({spread:.2g}x from first to last)")
    if n < 3:
        problems.append("too few to check the line")
    if se > SLOPE_SE_LIMIT:
        problems.append(f"standard error {se:.2g} > {SLOPE_SE_LIMIT:g}")
    if slope - reach > SLOPE_RANGE[1] or slope + reach < SLOPE_RANGE[0]:
        problems.append(f"outside [{SLOPE_RANGE[0]:g}, {SLOPE_RANGE[1]:g}]")
    return SlopeFit(slope, se, n, ", ".join(problems))


def slope_cell(fit: SlopeFit) -> str:
    """A table cell: slope +- standard error, "*" when it cannot be trusted, "n/a" without one."""
    if math.isnan(fit.slope):
        return "n/a"
    text = f"{fit.slope:.2f}" + ("" if math.isnan(fit.se) else f" +- {fit.se:.2f}")
    return text + (" *" if fit.problem else "")


#: What a slope of MSE against spp or time should be (the sentence under a slope table).
MSE_THEORY = ("theory: -1 for unbiased Monte Carlo, about -2/3 for progressive photon mapping, steeper than -1 "
              "only where stratification or QMC helps")


def slope_note(fits: list[tuple[str, SlopeFit]], where: str, theory: str = MSE_THEORY) -> list[str]:
    """Markdown lines under a slope table: which slopes are marked and why, and what
    ``theory`` expects (nothing when every slope is trusted)."""
    flagged = [(name, fit) for name, fit in fits if fit.problem and not math.isnan(fit.slope)]
    if not flagged:
        return []
    return ["", f"Slopes marked * ({where}) cannot be trusted: " +
            "; ".join(f"{name} ({fit.points} points: {fit.problem})" for name, fit in flagged) +
            f". A slope comes from a few noisy points (+- one standard error: from the scatter about the "
            f"line or the seeds' spread, whichever is larger); {theory}. A positive slope means the error "
            f"did not fall: noise, or a floor."]


# ----------------------------------------------------------------------------
# Report helpers: groups = {(strategy, sampler): [PointStats, ...]}
# ----------------------------------------------------------------------------

def _ladder(points):
    """The spp-ladder points (not time-budget ones) of a group, by spp."""
    return sorted((p for p in points if getattr(p, "budget_s", None) is None), key=lambda p: p.spp)


def slope_table(groups, label) -> list[str]:
    """Markdown lines: slope of log MSE (reference floor subtracted) against log spp per group,
    with its standard error and, for one that cannot be trusted (``fit_slope``), a mark."""
    rows = []
    for key, points in groups.items():
        pts = [p for p in _ladder(points) if p.mse_corrected > 0]
        if len({p.spp for p in pts}) < 2:
            continue
        fit = fit_slope([p.spp for p in pts], [p.mse_corrected for p in pts],
                        [getattr(p, "mse_std", math.nan) / math.sqrt(getattr(p, "seeds", 1)) for p in pts], axis="spp")
        rows.append((fit.slope, label(key), f"{pts[0].spp}-{pts[-1].spp}", len(pts), fit))
    if not rows:
        return []
    rows.sort(key=lambda r: r[:4])
    body = [[name, f"{slope:.2f}", rng, n, "n/a" if math.isnan(fit.se) else f"{fit.se:.2f}",
             f"* {fit.problem}" if fit.problem else ""] for slope, name, rng, n, fit in rows]
    return ["", "### MSE against spp", "",
            "Slope of log MSE (reference floor subtracted) against log spp: -1 for independent "
            "samples; steeper where stratification or QMC helps.", "",
            *markdown_table(["strategy / sampler", "slope", "spp range", "points", "standard error", "trust"], body),
            *slope_note([(name, fit) for _, name, _, _, fit in rows], "in the trust column")]


def plot_error_spectra(groups, label, reference: np.ndarray, folder: str, path: str,
                       read_image=None) -> str | None:
    """PNG of the radially averaged error spectrum of each group at its lowest spp
    (blue noise shows at low spp), averaged over the stored seeds; the legend gives
    the low-frequency fraction. Returns the path, or None when there is nothing.

    The spectra are taken on ``spectrum_rows(reference)``: below a directly visible
    emitter when that keeps at least half the image (its edge errors line up along
    the edge and would dominate every spectrum), else the whole image; the title
    says which."""
    if read_image is None:
        from ... import images
        read_image = lambda p: images.read_exr(p)[0]   # noqa: E731
    row0 = spectrum_rows(reference)
    curves = []
    for key, points in groups.items():
        ladder = _ladder(points)
        if not ladder or not ladder[0].images:
            continue
        p = ladder[0]
        errors = [(read_image(os.path.join(folder, rel)) - reference)[row0:] for rel in p.images]
        spectra = [radial_power_spectrum(e) for e in errors]
        freq = spectra[0][0]
        power = np.nanmean([s[1] for s in spectra], axis=0)
        low = float(np.mean([low_frequency_fraction(e) for e in errors]))
        curves.append((key, label(key), p.spp, freq, power, low))
    if not curves:
        return None
    fig, ax = pyplot().subplots(figsize=(6.4, 4.2), dpi=100)
    styles, how = series_styles(groups, ("strategy", "sampler"))          # as in the report's other plots
    for key, name, spp, freq, power, low in curves:
        ax.plot(freq, power, ms=3, lw=1.0, markevery=max(1, len(freq) // 8), **styles[key].kwargs(),
                label=f"{name} ({spp} spp, low-freq. share {low:.3f})")
    ax.set_yscale("log")
    ax.set_xlabel("radial frequency (cycles / pixel)")
    ax.set_ylabel("error power")
    where = f"rows {row0}.. (below the emitter)" if row0 else "whole image"
    ax.set_title(f"radially averaged power spectrum of the error (mean over seeds; {where})", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    legend_outside(ax, 7, how)
    return save_figure(fig, path)
