"""``mitsuba-lab check [SCENES...]``: every lab strategy on stiff scenes, against `path`.

For each scene: its traits (``scene.SceneTraits``) and warnings (geometry beyond
far_clip, emitters that emit nothing, participating media), then every strategy that
applies to it (``scene.strategy_applicability``; the others are listed with the
reason), each class of provably identical strategies rendered once
(``scene.equivalent_strategies``), and Mitsuba's `path` as the reference at more
samples per pixel (``volpathmis`` on a scene with participating media, which `path` ignores:
``features.default_reference``). Each strategy is rendered as ``--splits`` independent renders
(seeds 0..), whose spread gives the standard error of its image mean. The reference
comes from the sweep runner's content-addressed reference cache (``--cache``, shared
with ``mitsuba-lab reference`` and sweeps): rendered once in ``--splits`` independent
chunks, it keeps its mean image and the per-pixel variance of that mean, and is reused
by every later check with the same scene, settings and versions.

Resolution: ``--res N`` is given to a scene that declares ``<default name="res" .../>`` (the
shipped ones do, for a square film) as its ``res`` parameter; any other scene gets its first
sensor's film edited (``scene_xml.load_scene_variant``): N sets the larger side and keeps the
aspect ratio. ``--res WxH`` sets the film's width and height on every scene.

Strategies: lab_naive, lab_nee, lab_mis (power and balance), lab_bdpt, lab_vcm in modes bpt,
vcm and ppm, lab_photon (its sample count is its passes), and lab_pssmlt and lab_mmlt (their
sample count is mutations per pixel; each split its own bootstrap and chains; unbiased, so the
z-test).

Columns: finite fraction (of pixel channels), negative pixels, max value, fireflies,
mean luminance, its z-score against the reference, rays per pixel by kind (camera,
extension, shadow, and the bidirectional integrators' other kinds summed: connections,
light subpaths, rays to the sensor, merge lookups, photon segments), time.

Firefly rule: with luminance Y = 0.2126 R + 0.7152 G + 0.0722 B of the combined
image, a pixel is a firefly when Y > k * max(median of Y over the 5 x 5 pixels around
it (edges replicated), 0.01 * mean Y of the reference image); k = ``--firefly-k``
(default 10). The floor keeps black regions from turning every speck into a firefly.

z-score: z = (m - m_ref) / sqrt(s^2 / R + se_ref^2), with m the mean luminance over
the R splits, s^2 their sample variance, m_ref the reference's mean luminance and
se_ref its standard error, from the reference's per-pixel variance of the mean: pixels
are independent (box filter, as in the shipped scenes; a wider filter shares samples
between neighbours, and se_ref comes out somewhat small), and a pixel's luminance
variance is taken as (sum_c w_c sd_c)^2 over its channels c, exact when the channels
move together (as they do along one light path) and an upper bound otherwise
(``reference_mean_variance``).

Verdicts (``check.verdicts``): lab_vcm's merging modes (vcm, ppm) and lab_photon are
consistent, not unbiased: their row says "converging" with the measured log-log slope of bias^2
against the samples (bias^2 at 1, 4 and 16 times the budget per split), fails when a resolved
bias^2 does not shrink, and claims nothing when no bias is resolved. Every other lab strategy
that applies is unbiased by design, so
|z| > ``--z-max`` is a failure, with two exceptions that are told apart, not assumed. A mean
too *low* may be an unbiased estimator whose rare, huge samples the budget does not resolve
(a BSDF ray hitting a tiny light, an emitter sample inside a near-delta lobe): the strategy
is rendered again at 4 and 16 times the budget per split (``--escalate``), and when the
deficit sits in pixels where no sample ever found light, or shrinks as the budget grows, or
the split means are strongly skewed, the row is a warning, "unconverged: heavy-tailed
estimator", with those numbers; a deficit that holds, with symmetric split means, fails as a
bias (and so does any mean too *high*). A scene that declares an unscaled twin
(``<default name="twin" value="PATH"/>``) has `path` rendered on the twin as well; when the
scene's `path` disagrees with it, Mitsuba's reference is off there (ray offsets at this
scale) and the strategies are judged against the twin.

Exit status: 0 when every strategy is finite, non-negative and within the bound or only
warned about (heavy tail); 1 when any fails; 2 for bad input (raised as LabError).
"""
from __future__ import annotations

from ..metrics import luminance
from .measure import firefly_count, measure, reference_mean_variance, reference_summary
from .run import BIDIRECTIONAL_STRATEGIES, CHAIN_STRATEGIES, PATH_STRATEGIES, STRATEGIES, check_scene, settings_text
from .scenes import check_reference, load_check_scene

__all__ = ["STRATEGIES", "PATH_STRATEGIES", "BIDIRECTIONAL_STRATEGIES", "CHAIN_STRATEGIES", "check_scene", "settings_text",
           "check_reference", "load_check_scene", "firefly_count", "measure", "reference_mean_variance",
           "reference_summary", "luminance"]
