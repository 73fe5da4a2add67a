"""Film size overrides, the same everywhere (sweep configs, ``check --res``, ``reference --res``,
``invert``'s ``resolution``, the strategy grid).

An override is either a scalar N, which sets the film's *larger* side to N and keeps the
scene's aspect ratio (the other side rounded to the nearest integer, at least 1: a 128x96
scene at N = 16 renders 16x12), or a pair (W, H), which sets both. No override (None) keeps
the scene's own film. Nothing here imports Mitsuba.
"""
from __future__ import annotations

import math

#: What a resolution value must be, for messages.
RESOLUTION_EXPECTED = ("a positive integer (the film's larger side; the scene's aspect ratio is kept) "
                       "or [width, height] of positive integers")


def _positive_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


def is_resolution(value) -> bool:
    """Whether ``value`` is a valid override: a positive integer, or two of them (list or tuple)."""
    if _positive_int(value):
        return True
    return isinstance(value, (list, tuple)) and len(value) == 2 and all(_positive_int(v) for v in value)


def as_resolution(value):
    """A valid override in its normal form: an int, or a (width, height) tuple; None stays None.
    Raises ValueError naming what was expected for anything else."""
    if value is None:
        return None
    if not is_resolution(value):
        raise ValueError(f"expected {RESOLUTION_EXPECTED}, got {value!r}")
    return value if isinstance(value, int) else (int(value[0]), int(value[1]))


def parse_resolution_text(text: str):
    """A command-line resolution: "N" (the larger side) or "WxH"; ValueError otherwise."""
    parts = text.lower().replace(",", "x").split("x")
    try:
        numbers = [int(part) for part in parts]
    except ValueError:
        numbers = None
    if numbers is None or len(numbers) not in (1, 2) or not is_resolution(numbers[0] if len(numbers) == 1 else numbers):
        raise ValueError(f"must be a positive integer N (the film's larger side; the aspect ratio is kept) "
                         f"or WIDTHxHEIGHT, got '{text}'")
    return numbers[0] if len(numbers) == 1 else (numbers[0], numbers[1])


def film_shape(native: tuple[int, int], resolution) -> tuple[int, int]:
    """(width, height) of a film of size ``native`` (width, height) under the override
    ``resolution`` (module doc)."""
    resolution = as_resolution(resolution)
    if resolution is None:
        return int(native[0]), int(native[1])
    if isinstance(resolution, tuple):
        return resolution
    width, height = native
    shorter = lambda long, short: max(1, math.floor(resolution * short / long + 0.5))
    if width >= height:
        return resolution, shorter(width, height)
    return shorter(height, width), resolution


def film_key(native: tuple[int, int], resolution):
    """The override as cache keys and run identities record it: None (the scene's own film), the
    side N of a square film (as keys recorded square overrides before aspect ratios were kept, so
    their cached references stay valid), else [width, height]."""
    if resolution is None:
        return None
    width, height = film_shape(native, resolution)
    return width if width == height else [width, height]


def resolution_text(resolution) -> str:
    """An override as the command line writes it: "16" (the larger side), "16x12", or "the scene's"."""
    resolution = as_resolution(resolution)
    if resolution is None:
        return "the scene's"
    return f"{resolution[0]}x{resolution[1]}" if isinstance(resolution, tuple) else str(resolution)
