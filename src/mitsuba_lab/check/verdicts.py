"""What ``mitsuba-lab check`` concludes beyond a z-score (pure numpy, no rendering).

**Bias or heavy tail.** A strategy whose mean luminance is more than ``--z-max`` standard
errors *below* the reference is either biased or unbiased with a tail that the budget does
not resolve: rare samples of huge value (a BSDF ray hitting a tiny light, an emitter sample
inside a near-delta lobe) carry much of the mean, most budgets see none of them, and the
spread of the splits, made of the samples that were seen, is far too small. Such a mean is
low, never high (a rare event that does happen raises the mean and the spread together, so
|z| stays below about sqrt(splits)): a mean *above* the reference is a bias. A low mean is
rendered again at 4 and 16 times the budget per split (``Rung``, 32 splits each), and
``judge`` calls it an unresolved heavy tail (a warning) when at least one of these holds:

* **no events**: pixels where every sample of every budget was exactly 0 carry at least half
  of the deficit (contributions are >= 0, so a zero mean means all-zero samples). A weight
  error scales light that was found; only light never found leaves a pixel at exactly 0. By
  the rule of three, what the estimator misses there comes in events rarer than 3 / samples.
* **creep**: the deficit did not hold as the budget grew: at the largest budget |z| is
  within the bound, or the mean rose by more than ``z_max`` standard errors (the first
  budget's error taken at least as large as the largest budget's spread implies for a light
  tail, since 8 splits can understate it). A bias keeps its deficit, so its |z| grows like
  sqrt(budget) (x4 at x16) until the reference's own error caps it.
* **skew**: the split means at the largest budget have sample skewness >= 2 (``SKEW_MIN``):
  most seeds low, a few very high. A mean of 10^5 light-tailed samples is close to normal,
  and the skewness of 32 normal values has a standard deviation of 0.4, so 2 is 5 of them.

Otherwise the deficit is steady, the seeds symmetric, and the strategy fails as biased.
The numbers behind the verdict are printed (``Verdict.evidence``).

**Consistent, not unbiased.** lab_vcm's merging modes and lab_photon blur the light over a
radius that shrinks as a render's iterations (passes) grow: biased for any finite budget, so a
z-test would fail them for what they are. The bias^2 of their image mean (the squared
difference from the reference's, less its variance) is measured instead, at the first
budget and, when resolved there (above ``BIAS_RESOLVED_Z`` standard errors), at 4 and 16 times
it; ``judge_consistent`` says "converging", with the log-log slope of bias^2 against the
iterations, when it fell by more than ``BIAS_SHRINK_Z`` standard errors of the difference
(about -0.5 for lab_vcm's alpha 0.75 on smooth light, -2/3 for lab_photon's 2/3), and fails
when it did not. A bias below the noise is only that: no convergence is claimed.

**A reference that is wrong.** A scene that is a rescaled copy of another declares it with
``<default name="twin" value="PATH"/>`` (relative to the scene file; the stiff scaled_1e-4
and scaled_1e4 scenes name scenes/cornell_box.xml). Radiance does not depend on scale, so
the two images must agree; when Mitsuba's `path` disagrees with its own render of the twin
(``Twin``), it is off on the scaled scene (floating-point precision: ray offsets), and the
lab strategies are judged against the twin instead (``twin_status``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import metrics

#: Skewness of the split means at the largest budget that marks an unresolved tail.
SKEW_MIN = 2.0
#: Share of the deficit in all-zero pixels that marks events never sampled.
EMPTY_SHARE_MIN = 0.5
#: Splits of each larger budget (enough for a skewness; see SKEW_MIN).
LADDER_SPLITS = 32
#: Seeds of the larger budgets start at rung * LADDER_SEED: apart from the first budget's
#: seeds 0.. and from the reference's (experiment.reference.REFERENCE_SEED_BASE = 2^24).
LADDER_SEED = 1 << 16
#: bias^2 above this many standard errors is resolved (and its shrinking worth measuring).
BIAS_RESOLVED_Z = 3.0
#: A consistent estimator converges when bias^2 fell by more than this many standard errors.
BIAS_SHRINK_Z = 3.0
#: Mitsuba's ray offset for single precision: eps (1 + max_i |p_i|), eps = 1500 * 2^-24.
MITSUBA_RAY_EPSILON = 1500 * 2.0 ** -24

HEAVY_TAIL = "unconverged: heavy-tailed estimator"
REASONS = {"no events": "no sample found the light that the deficit's pixels should get",
           "creep": "the mean crept up towards the reference as the budget grew",
           "skew": "a few seeds carry the sum (skewed split means)"}


def ladder_factors(escalate: int) -> list[int]:
    """Budget factors of the larger renders: 4, 16, 64, ... up to ``escalate``."""
    factors, k = [], 4
    while k <= escalate:
        factors.append(k)
        k *= 4
    return factors


def skewness(values) -> float:
    """Sample skewness g1 = m3 / m2^1.5 (0 for no spread; one outlier among n gives
    (n - 2) / sqrt(n - 1))."""
    x = np.asarray(values, dtype=np.float64)
    centred = x - x.mean()
    m2 = float(np.mean(centred ** 2))
    return float(np.mean(centred ** 3) / m2 ** 1.5) if m2 > 0 else 0.0


def normal_skewness_sd(n: int) -> float:
    """Standard deviation of g1 for n normal values."""
    return math.sqrt(6.0 * (n - 2) / ((n + 1) * (n + 3)))


@dataclass
class Rung:
    """One budget: ``splits`` independent renders of ``spp`` samples per pixel each, kept as
    their mean luminances (one number per split)."""
    factor: int
    spp: int
    means: np.ndarray

    @property
    def splits(self) -> int:
        return len(self.means)

    @property
    def mean(self) -> float:
        return float(np.mean(self.means))

    @property
    def variance(self) -> float:
        """Sample variance of one split's mean."""
        return float(np.var(self.means, ddof=1)) if self.splits > 1 else 0.0

    @property
    def variance_of_mean(self) -> float:
        return self.variance / self.splits

    def z(self, ref_mean: float, ref_variance: float) -> float:
        return metrics.z_score(self.mean, self.variance, self.splits, ref_mean, ref_variance, 1)

    @property
    def skew(self) -> float:
        return skewness(self.means)

    def top_share(self) -> tuple[int, float]:
        """(k, share of the splits' sum carried by the k largest), k = a tenth of the splits."""
        k = max(1, self.splits // 10)
        total = float(np.sum(self.means))
        return k, (float(np.sum(np.sort(self.means)[-k:])) / total if total > 0 else 0.0)


@dataclass
class Empty:
    """Pixels where every sample of every budget was exactly 0 while the reference is not."""
    share: float                   # of the deficit (reference minus strategy, summed over pixels)
    pixels: int
    samples: int                   # samples that fell in them, all 0


def empty_pixels(pixel_sums: np.ndarray, ref_pixels: np.ndarray, lab_mean: float, ref_mean: float,
                 spp_total: int) -> Empty:
    """``pixel_sums``: each pixel's luminance summed over all renders; ``ref_pixels``: the
    reference's luminance image; ``lab_mean``: the strategy's mean luminance over all renders."""
    empty = (pixel_sums == 0) & (ref_pixels > 0)
    deficit = (ref_mean - lab_mean) * ref_pixels.size
    share = float(np.sum(ref_pixels[empty]) / deficit) if deficit > 0 else 0.0
    count = int(np.sum(empty))
    return Empty(min(share, 1.0), count, count * spp_total)


@dataclass
class Verdict:
    kind: str                       # "ok", "converging", "heavy tail" (a warning) or "bias" (a failure)
    summary: str = ""
    evidence: list[str] = field(default_factory=list)


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def ladder_lines(rungs: list[Rung], ref_mean: float, ref_variance: float) -> list[str]:
    """Mean, median and z of each budget, and the shape of the largest budget's split means."""
    top = rungs[-1]
    each = lambda f: ", ".join(f(r) for r in rungs)  # noqa: E731
    lines = [f"budget {each(lambda r: f'x{r.factor}')} ({each(lambda r: str(r.spp))} spp per split, "
             f"{each(lambda r: str(r.splits))} splits): mean {each(lambda r: _fmt(r.mean))} against "
             f"{_fmt(ref_mean)}; median {each(lambda r: _fmt(float(np.median(r.means))))}; "
             f"z {each(lambda r: f'{r.z(ref_mean, ref_variance):+.1f}')}"]
    k, share = top.top_share()
    median = float(np.median(top.means))
    ratio = f"{top.means.max() / median:.3g}" if median > 0 else ("inf" if top.means.max() > 0 else "-")
    lines.append(f"split means at x{top.factor}: skewness {top.skew:+.2f} (normal: 0 +- "
                 f"{normal_skewness_sd(top.splits):.2f}; tail if >= {SKEW_MIN:g}), max/median {ratio}, "
                 f"the top {k} of {top.splits} carry {share:.0%} of their sum, "
                 f"{int(np.sum(top.means < ref_mean))} of {top.splits} below the reference")
    return lines


def judge(rungs: list[Rung], ref_mean: float, ref_variance: float, z_max: float,
          empty: Empty | None = None) -> Verdict:
    """Bias or unresolved heavy tail (module doc). ``rungs[0]`` is the first budget, the others
    the larger ones (rendered only when its mean is low)."""
    base, top = rungs[0], rungs[-1]
    z0 = base.z(ref_mean, ref_variance)
    if not math.isfinite(ref_mean) or abs(z0) <= z_max:
        return Verdict("ok")
    rel = base.mean / ref_mean - 1 if ref_mean else math.inf
    if z0 > z_max:
        return Verdict("bias", f"bias: mean {rel:+.1%} above the reference (z {z0:+.1f}); an "
                               f"unresolved tail only ever leaves a mean low")
    reasons = []
    if empty is not None and empty.share >= EMPTY_SHARE_MIN:
        reasons.append("no events")
    # The first budget's few splits can understate its spread; a light tail's spread shrinks
    # like 1 / sqrt(budget), so the largest budget's spread bounds it from below.
    base_variance = max(base.variance, top.variance * top.factor / base.factor)
    creep = metrics.z_score(top.mean, top.variance, top.splits, base.mean, base_variance, base.splits)
    z_top = top.z(ref_mean, ref_variance)
    if len(rungs) > 1 and (z_top > -z_max or creep > z_max):
        reasons.append("creep")
    if top.splits >= 16 and top.skew >= SKEW_MIN:
        reasons.append("skew")
    evidence = ladder_lines(rungs, ref_mean, ref_variance)
    if len(rungs) > 1:
        # A light-tailed estimator's split variance shrinks like 1 / budget: with a constant
        # bias, |z| grows like sqrt(budget) (until the reference's own error caps it).
        light = base.variance / top.factor
        expected = metrics.z_score(base.mean, light, top.splits, ref_mean, ref_variance, 1)
        spread = (f"the split spread at x{top.factor} is {math.sqrt(top.variance / light):.3g} times a light "
                  f"tail's" if light > 0 else "no split spread at x1")
        evidence.insert(1, f"a light-tailed estimator with a constant bias would reach z {expected:+.1f} at "
                           f"x{top.factor} (measured {z_top:+.1f}); the mean moved {creep:+.1f} standard errors "
                           f"from x1 to x{top.factor}; {spread}")
    if empty is not None and empty.pixels:
        bound = f"rarer than 1 in {empty.samples / 3:.2g} (rule of three)" if empty.samples else "never seen"
        evidence.append(f"{empty.pixels} pixels where every sample was 0 (the reference is not) carry "
                        f"{empty.share:.0%} of the deficit: 0 of {empty.samples:.3g} samples there found "
                        f"light, so what the estimator misses there comes in events {bound}")
    if reasons:
        return Verdict("heavy tail", f"{HEAVY_TAIL}: " + "; ".join(REASONS[r] for r in reasons), evidence)
    return Verdict("bias", f"bias: mean {rel:+.1%} (z {z0:+.1f}); its deficit holds as the budget grows "
                           f"and the split means are not skewed", evidence)


# -- Consistent estimators: bias^2 shrinking as the budget grows ----------------------------------

@dataclass
class BiasRung:
    """One budget of a consistent estimator: its samples per pixel per split and the bias^2 of
    its image mean (luminance), with that estimate's standard error."""
    factor: int
    spp: int
    bias2: float
    se: float

    @property
    def resolved(self) -> bool:
        return self.bias2 > BIAS_RESOLVED_Z * self.se

    def line(self, mean: float) -> str:
        relative = f", relative bias {math.sqrt(self.bias2) / mean:.2%}" if self.bias2 > 0 and mean > 0 else ""
        return f"x{self.factor} ({self.spp} spp per split): bias^2 {_fmt(self.bias2)} +- {_fmt(self.se)}{relative}"


def bias_slope(rungs: list[BiasRung]) -> float:
    """Least-squares slope of log bias^2 against log samples over the rungs with bias^2 > 0
    (nan with fewer than two)."""
    kept = [r for r in rungs if r.bias2 > 0]
    if len(kept) < 2:
        return math.nan
    return float(np.polyfit(np.log([r.spp for r in kept]), np.log([r.bias2 for r in kept]), 1)[0])


def judge_consistent(rungs: list[BiasRung], mean: float) -> Verdict:
    """Converging or not (module doc): ``rungs[0]`` the first budget, the others larger ones
    (rendered only when its bias^2 is resolved); ``mean``: the reference's mean luminance."""
    base, top = rungs[0], rungs[-1]
    evidence = [r.line(mean) for r in rungs]
    if not base.resolved:
        return Verdict("ok", f"consistent estimator: no bias resolved at {base.spp} spp per split (bias^2 "
                             f"{_fmt(base.bias2)} +- {_fmt(base.se)}); convergence not measured", evidence)
    if len(rungs) == 1:
        return Verdict("bias", "biased at this budget and --escalate 1: whether the bias shrinks is not measured",
                       evidence)
    drop = (base.bias2 - top.bias2) / math.hypot(base.se, top.se)
    slope = bias_slope(rungs)
    evidence.append(f"bias^2 fell by {drop:+.1f} standard errors from x1 to x{top.factor}; log-log slope "
                    f"{slope:+.2f} against the samples")
    if drop > BIAS_SHRINK_Z:
        return Verdict("converging", f"converging: bias^2 {_fmt(base.bias2)} -> {_fmt(top.bias2)} from x1 to "
                                     f"x{top.factor} the samples, slope {slope:+.2f}", evidence)
    return Verdict("bias", f"not converging: bias^2 {_fmt(base.bias2)} -> {_fmt(top.bias2)} from x1 to "
                           f"x{top.factor} the samples (a consistent estimator's bias shrinks as they grow)",
                   evidence)


# -- A reference that is wrong: the unscaled twin ------------------------------------------------

@dataclass
class Twin:
    """The scene's reference (Mitsuba's `path`, or `volpathmis` in media) against the same
    integrator on its unscaled twin."""
    name: str                       # as the scene declares it
    mean: float                     # the twin reference's mean luminance
    variance: float                 # and the variance of that mean
    z_path: float                   # the scene's reference against the twin
    rel_path: float                 # (reference mean / twin mean) - 1
    integrator: str = "path"        # the reference integrator

    @staticmethod
    def compare(name: str, twin_mean: float, twin_variance: float, path_mean: float,
                path_variance: float, integrator: str = "path") -> "Twin":
        z = metrics.z_score(path_mean, path_variance, 1, twin_mean, twin_variance, 1)
        return Twin(name, twin_mean, twin_variance, z, path_mean / twin_mean - 1 if twin_mean else math.inf,
                    integrator)

    def path_off(self, z_max: float) -> bool:
        return not abs(self.z_path) <= z_max


def offsets_note(bbox_min, bbox_max) -> str:
    """How large Mitsuba's ray offset is next to the scene (its bounding box)."""
    magnitude = max(abs(v) for v in (*bbox_min, *bbox_max))
    diagonal = math.dist(bbox_min, bbox_max)
    offset = MITSUBA_RAY_EPSILON * (1 + magnitude)
    share = f", {offset / diagonal:.0%} of the scene's diagonal {diagonal:.2g}" if diagonal > 0 else ""
    return f"Mitsuba offsets spawned rays by 8.9e-5 x (1 + max|p|) = {offset:.2g} here{share}"


def path_off_note(twin: Twin, bbox_min, bbox_max) -> str:
    return (f"Mitsuba's {twin.integrator} is off on this scene: {twin.rel_path:+.1%} against its render of the "
            f"unscaled twin {twin.name} (z {twin.z_path:+.1f}); the two differ only in scale, so "
            f"this is floating-point precision: ray offsets at this scale ({offsets_note(bbox_min, bbox_max)}). "
            f"The lab strategies are judged against the twin.")


def twin_status(verdict: Verdict, z_lab_path: float, rel_lab_twin: float, twin: Twin,
                z_max: float) -> tuple[str, str]:
    """(status, note) of a strategy on a scene whose `path` is off (``Twin.path_off``);
    ``verdict`` judges the strategy against the twin."""
    if verdict.kind == "ok":
        return "ok", (f"agrees with the unscaled twin ({rel_lab_twin:+.1%}); Mitsuba's {twin.integrator} is off here "
                      f"({twin.rel_path:+.1%}, ray offsets), not the lab's estimator")
    if verdict.kind == "heavy tail":
        return "WARN: heavy tail", verdict.summary + " (judged against the unscaled twin)"
    if abs(z_lab_path) <= z_max:
        return "FAIL: ray offsets", (f"reference and estimator both disagree with the unscaled twin "
                                     f"(estimator {rel_lab_twin:+.1%}, path {twin.rel_path:+.1%}): "
                                     f"ray offsets at this scale")
    return "FAIL: off the twin", (f"disagrees with the unscaled twin ({rel_lab_twin:+.1%}) and with "
                                  f"Mitsuba's path, itself off by {twin.rel_path:+.1%} (ray offsets)")
