"""Agreement in expectation between two renderers, by z-scores of pixel-block means.

Each estimator is rendered with R independent seeds (disjoint seed ranges, so
the two are independent of each other). For every BLOCK x BLOCK pixel block and
channel, and for the whole image per channel, the difference of the two means
is divided by its standard error estimated from the spread across seeds
(Welch). Under agreement each z is approximately standard normal.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from mitsuba_lab.metrics import luminance, z_score
from mitsuba_lab.render import render

BLOCK = 8
#: The one bound on |z| of every agreement test (block means, image means, region means). Under
#: agreement a z from 16 + 16 seeds is close to Student's t with about 30 degrees of freedom:
#: P(|z| > 5) = 2.3e-5 per z (5.7e-7 were it normal), so a correct estimator fails a case of 100
#: z-scores with probability about 2e-3; seeds are fixed, so a run is deterministic. Each test file
#: proves its power once with a deliberate bias that must exceed it.
Z_BOUND = 5.0
#: Disjoint seed ranges of the two sides.
SEEDS_LAB = range(16)
SEEDS_REF = range(1000, 1016)
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def scene_path(name: str) -> str:
    """A scene of the project's scenes/ folder."""
    return os.path.join(ROOT, "scenes", name)


@dataclass
class Agreement:
    block_z: np.ndarray      # (blocks_y, blocks_x, channels)
    image_z: np.ndarray      # (channels,)
    rel_diff: np.ndarray     # (channels,) relative difference of the image means

    @property
    def max_abs_z(self) -> float:
        return float(max(np.abs(self.block_z).max(), np.abs(self.image_z).max()))


def block_means(image: np.ndarray, block: int = BLOCK) -> np.ndarray:
    h, w, c = image.shape
    return image[: h - h % block, : w - w % block].reshape(h // block, block, w // block, block, c).mean(axis=(1, 3))


def renders(scene, integrator, spp, seeds):
    return np.stack([render(scene, integrator, spp=spp, seed=s)[0] for s in seeds])


#: Reference stacks already rendered in this process (numpy only, no Mitsuba object), by
#: (variant, scene key, integrator, parameters, spp, seeds): see ``cached_renders``.
_STACKS: dict = {}


def cached_renders(scene_key, scene, integrator: str, params: dict, spp: int, seeds) -> np.ndarray:
    """``renders(scene, make_integrator(integrator, params), spp, seeds)``, rendered once per
    process for each (variant, ``scene_key``, integrator, params, spp, seeds) and shared by every
    test (and test file) that asks again: with fixed seeds a render is deterministic, so a second
    render of the same key is the same stack, and only time. ``scene_key`` must name the scene
    exactly (file and every load parameter); ``scene`` may be a callable that loads it, called
    only when the key is new. The stack is returned read-only."""
    import mitsuba as mi

    from mitsuba_lab.scene import make_integrator

    key = (mi.variant(), scene_key, integrator, tuple(sorted(params.items())), spp, tuple(seeds))
    if key not in _STACKS:
        the_scene = scene() if callable(scene) else scene
        stack = renders(the_scene, make_integrator(integrator, dict(params)), spp, seeds)
        stack.flags.writeable = False
        _STACKS[key] = stack
    return _STACKS[key]


def path_reference(name: str, res: int, spp: int = 64, max_depth: int = 8, seeds=None, **params) -> np.ndarray:
    """Mitsuba's `path` on scenes/``name`` loaded at ``res``: ``spp`` x ``seeds`` (default
    SEEDS_REF), through ``cached_renders`` (the same reference in test_bdpt, test_vcm, test_aim,
    test_vcm_choices is rendered once per run)."""
    from mitsuba_lab.scene import load_scene

    return cached_renders(("file", name, res), lambda: load_scene(scene_path(name), res=res), "path",
                          {"max_depth": max_depth, **params}, spp, SEEDS_REF if seeds is None else seeds)


def z_scores(stack_a: np.ndarray, stack_b: np.ndarray) -> Agreement:
    def stats(stack, reducer):
        values = np.stack([reducer(img) for img in stack])
        return values.mean(axis=0), values.var(axis=0, ddof=1) / len(values)

    def z(reducer):
        mean_a, var_a = stats(stack_a, reducer)
        mean_b, var_b = stats(stack_b, reducer)
        # identical constant blocks (e.g. black background) have no spread: z = 0
        return z_score(mean_a, var_a, 1, mean_b, var_b, 1), mean_a, mean_b

    block_z, _, _ = z(block_means)
    image_z, mean_a, mean_b = z(lambda img: img.mean(axis=(0, 1)))
    return Agreement(block_z, image_z, (mean_a - mean_b) / np.maximum(np.abs(mean_b), 1e-12))


def pixel_problem(stack: np.ndarray, spectral: bool) -> str:
    """'' when every pixel is finite and non-negative, else what is wrong. In a spectral variant
    the RGB film turns each sample's wavelengths into XYZ and then linear sRGB, which is negative
    outside the sRGB gamut (Mitsuba's `path` does it too); its luminance Y is a non-negative
    integral of the spectrum, so there Y is checked instead (down to float rounding)."""
    if not np.all(np.isfinite(stack)):
        return f"{int(np.sum(~np.isfinite(stack)))} NaN/Inf pixel values"
    values = luminance(stack) if spectral else stack
    floor = -1e-6 * max(float(np.abs(values).max()), 1.0) if spectral else 0.0   # Y: float rounding
    if values.min() < floor:
        return (f"negative {'luminance' if spectral else 'pixels'} (min {values.min():.3g}, "
                f"{int(np.sum(values < floor))} values)")
    return ""


def assert_agrees(lab: np.ndarray, ref: np.ndarray, what: str, bound: float = Z_BOUND) -> Agreement:
    """Every pixel of ``lab`` finite and non-negative, and max |z| against ``ref`` within ``bound``
    (printed, with the relative difference of the image means)."""
    assert pixel_problem(lab, False) == "", f"{what}: {pixel_problem(lab, False)}"
    result = z_scores(lab, ref)
    print(f"{what}: max |z| {result.max_abs_z:.2f}, relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z <= bound, (f"{what}: max |z| {result.max_abs_z:.2f}, image z {result.image_z}, "
                                       f"relative difference {result.rel_diff}")
    return result


# ---------------------------------------------------------------------------- block test
#: The block test's defaults: renders a side, block size in pixels, family-wise alpha.
BLOCK_SEEDS = 64
BLOCK_SIZE = 6
BLOCK_ALPHA = 0.01


@dataclass
class BlockTest:
    """Welch z of every block mean over the seeds (colour channels averaged), against a Sidak
    bound: each of the n blocks is tested two-sided at 1 - (1 - alpha)^(1/n), so under agreement
    the chance that any block passes the bound is alpha."""
    z: np.ndarray            # (blocks_y, blocks_x)
    ratio: np.ndarray        # block means, lab over reference (nan where the reference is 0)
    bound: float

    @property
    def failing(self) -> list[tuple[int, int]]:
        return [tuple(int(i) for i in b) for b in np.argwhere(np.abs(self.z) > self.bound)]

    @property
    def max_abs_z(self) -> float:
        return float(np.abs(self.z).max())

    def summary(self) -> str:
        worst = [f"({y},{x}) ratio {self.ratio[y, x]:.4f} z {self.z[y, x]:+.1f}" for y, x in self.failing[:6]]
        return (f"max |z| {self.max_abs_z:.2f}, bound {self.bound:.2f}, {len(self.failing)} of {self.z.size} "
                f"blocks past it" + (": " + "; ".join(worst) if worst else ""))


def sidak_bound(blocks: int, alpha: float = BLOCK_ALPHA) -> float:
    """|z| bound of one of ``blocks`` two-sided tests whose family-wise error rate is ``alpha``."""
    from statistics import NormalDist

    per_block = 1.0 - (1.0 - alpha) ** (1.0 / blocks)
    return NormalDist().inv_cdf(1.0 - per_block / 2.0)


def grey_block_means(stack: np.ndarray, block: int = BLOCK_SIZE) -> np.ndarray:
    """(seeds, blocks_y, blocks_x): each render's block means, its colour channels averaged."""
    grey = stack[..., : min(3, stack.shape[-1])].mean(axis=-1)[..., None]
    return np.stack([block_means(img, block)[..., 0] for img in grey])


def block_test(lab: np.ndarray, ref: np.ndarray, block: int = BLOCK_SIZE, alpha: float = BLOCK_ALPHA) -> BlockTest:
    """The block test of two stacks of renders (seeds, height, width, channels); blocks whose
    reference and lab images are both constant over the seeds (black background) have z = 0."""
    a, b = grey_block_means(lab, block), grey_block_means(ref, block)
    ma, mb = a.mean(axis=0), b.mean(axis=0)
    z = z_score(ma, a.var(axis=0, ddof=1) / len(a), 1, mb, b.var(axis=0, ddof=1) / len(b), 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(mb != 0, ma / mb, np.nan)
    return BlockTest(z, ratio, sidak_bound(z.size, alpha))


def assert_blocks_agree(lab: np.ndarray, ref: np.ndarray, what: str, block: int = BLOCK_SIZE) -> BlockTest:
    """Every pixel of ``lab`` finite and non-negative, and no block past the Sidak bound."""
    assert pixel_problem(lab, False) == "", f"{what}: {pixel_problem(lab, False)}"
    result = block_test(lab, ref, block)
    print(f"{what}: {result.summary()}")
    assert not result.failing, f"{what}: {result.summary()}"
    return result
