"""Light tracing's image: splats into a film block, developed and corrected at the crop's edges.

A camera sample's reconstruction-filter weights are normalised per pixel (each pixel is a
weighted average of the samples near it), so a pixel at the edge of the crop window averages
only what lies inside. A splat has no such normalisation: its value is spread by the filter
over the pixels around it, and the part of the filter that falls outside the crop window is
lost, while no splat arrives from outside (the sensor accepts only directions inside the
window). With Mitsuba's default Gaussian filter the edge row of pixels comes out 16% darker
than Mitsuba's ``path`` renders it, a corner 30% (Mitsuba's ``ptracer`` does this). Dividing
each pixel by the filter mass its samples can reach,

    C(p) = integral over the crop window of f(x - p) dx,

gives both estimators the same expected image (C = 1 inside, and everywhere for a box filter).
C is computed once per film layout by splatting a fine uniform grid through the same block,
so it includes the filter's own discretisation.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Grid points per pixel and axis for C (midpoint rule: error ~1e-4 for Mitsuba's filters).
COVERAGE_GRID = 8

_coverage_cache: dict = {}


def new_block(film: mi.Film) -> mi.ImageBlock:
    """An empty block over the film's crop window for splats (not normalised per pixel)."""
    film.prepare([])
    block = film.create_block(mi.ScalarVector2u(0), True, False)
    block.set_offset(film.crop_offset())
    block.set_coalesce(False)
    return block


def splat(block: mi.ImageBlock, uv, wavelengths, value, active):
    """Add ``value`` at film position ``uv`` (pixels, relative to the crop window)."""
    block.put(uv + mi.Vector2f(block.offset()), wavelengths, value, dr.select(active, 1.0, 0.0), 0.0, active)


def _key(film: mi.Film) -> tuple:
    return (tuple(film.size()), tuple(film.crop_size()), tuple(film.crop_offset()), film.rfilter().radius(),
            film.rfilter().class_name(), mi.variant())


def coverage(film: mi.Film):
    """C(p) of every pixel of the crop window (a developed film image, colour channels 1)."""
    key = _key(film)
    if key not in _coverage_cache:
        w, h = (int(v) for v in film.crop_size())
        n = COVERAGE_GRID
        index = dr.arange(mi.UInt32, w * h * n * n)
        x, y = index % (w * n), index // (w * n)
        uv = mi.Point2f((mi.Float(x) + 0.5) / n, (mi.Float(y) + 0.5) / n)
        block = new_block(film)
        # raw channels (colour 1 / n^2, alpha 1, weight 0 as a splat's): no spectrum to convert
        one = mi.Float(1.0 / (n * n))
        values = [one] * 3 + ([mi.Float(1.0)] if block.channel_count() == 5 else []) + [mi.Float(0.0)]
        block.put(uv + mi.Vector2f(block.offset()), values)
        film.put_block(block)
        _coverage_cache[key] = film.develop()
        dr.eval(_coverage_cache[key])
    return _coverage_cache[key]


def develop(film: mi.Film, block: mi.ImageBlock):
    """The light-tracing image of ``block``, edge-corrected (``C``; pixels with C = 0 stay 0)."""
    c = coverage(film)
    film.prepare([])
    film.put_block(block)
    image = film.develop()
    return dr.select(c > 0, image / dr.maximum(c, 1e-12), 0.0)
