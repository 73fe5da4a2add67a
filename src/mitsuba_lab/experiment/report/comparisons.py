"""Which stored renders are shown side by side: the comparison sets of one scene.

Shared by the report's comparison viewer (``viewer``) and the publication figure
(``figure``). A set holds one point per strategy (a (strategy, sampler) group):

* equal time: with ``time_budgets``, the points of one budget (each calibrated to about that
  wall time; named by the budget and the measured range, and not called equal time when a point
  is off its budget, ``budget_set_name``); with an spp ladder only, each strategy's point
  nearest in log time to a budget that every curve covers (``analysis.equal_time_budgets``),
  so the times differ somewhat and are always shown;
* equal spp: the ladder points of one sample count.

Each shown image is one seed's render (the point's first stored image); numbers under it are
either that image's own (its relMSE) or the point's mean over seeds, and say which.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ... import metrics
from .analysis import PointStats, curve, equal_time_budgets, run_image
from ..pipeline.budget import measured_range, missed_budget


@dataclass
class ComparisonSet:
    name: str                       # "equal time 0.5 s (0.48-0.55 s measured)", "budget 2 s, not equal
                                    # time (...; off budget: ...)", "about equal time 0.31 s", "equal spp 16"
    kind: str                       # "time" or "spp"
    entries: list = field(default_factory=list)      # [(label, PointStats)], in the groups' order
    budget_s: float | None = None   # the time budget of a budget's set


def group_points(stats: list[PointStats]) -> tuple[dict, callable]:
    """{(strategy, sampler): [PointStats]} in a stable order, and the label of a group: the
    strategy's name, with the sampler added when the scene has more than one."""
    groups: dict = {}
    for p in sorted(stats, key=lambda s: (s.strategy, s.sampler, s.time_s)):
        groups.setdefault((p.strategy, p.sampler), []).append(p)
    samplers = {k[1] for k in groups}
    return groups, (lambda key: key[0] if len(samplers) == 1 else f"{key[0]} / {key[1]}")


def comparison_sets(groups: dict, label) -> list[ComparisonSet]:
    """Equal-time sets (by budget, ascending) then equal-spp sets (ascending); a set needs
    at least one strategy, and a nearest-point set identical to an earlier one is dropped."""
    sets = []
    budgets = sorted({p.budget_s for points in groups.values() for p in points if p.budget_s is not None})
    for b in budgets:
        entries = [(label(k), p) for k, points in groups.items() for p in points if p.budget_s == b]
        sets.append(ComparisonSet(budget_set_name(b, entries), "time", entries, b))
    ladder = {k: [p for p in points if p.budget_s is None] for k, points in groups.items()}
    if not budgets:
        targets = equal_time_budgets({k: curve(points) for k, points in ladder.items() if points})
        seen = set()
        for t in targets:
            entries = [(label(k), min(points, key=lambda p: abs(math.log(max(p.time_s, 1e-9) / t))))
                       for k, points in ladder.items() if points]
            ids = tuple(p.point for _, p in entries)
            if ids not in seen:
                seen.add(ids)
                sets.append(ComparisonSet(f"about equal time {t:.2g} s", "time", entries))
    for spp in sorted({p.spp for points in ladder.values() for p in points}):
        entries = [(label(k), p) for k, points in ladder.items() for p in points if p.spp == spp]
        sets.append(ComparisonSet(f"equal spp {spp}", "spp", entries))
    return [s for s in sets if s.entries]


def budget_set_name(budget_s: float, entries) -> str:
    """A budget's set name: "equal time 2 s (1.9-2.3 s measured)" when every point is at the budget
    (``budget.missed_budget``), else "budget 2 s, not equal time (1.1-2.3 s measured; off budget:
    lab_vcm 1.1 s)": a set with a point off its budget is not an equal-time comparison."""
    times = [p.time_s for _, p in entries] or [math.nan]
    measured = measured_range(min(times), max(times))
    off = [f"{name} {p.time_s:.2g} s" for name, p in entries if missed_budget(p)]
    if not off:
        return f"equal time {budget_s:g} s ({measured})"
    return f"budget {budget_s:g} s, not equal time ({measured}; off budget: {', '.join(off)})"


def default_set(sets: list[ComparisonSet]) -> int:
    """Index of the set shown first: the middle equal-time set (as the report's image strip),
    else the middle one."""
    timed = [i for i, s in enumerate(sets) if s.kind == "time"]
    pool = timed or list(range(len(sets)))
    return pool[len(pool) // 2] if pool else 0


def shown_image(folder: str, point: PointStats) -> np.ndarray:
    """The render a comparison shows for a point: its first stored seed."""
    return run_image(folder, point.images[0])


def relative_error(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per-pixel relative error sqrt(mean_c (x - ref)^2 / (ref^2 + 0.01)): its square
    averaged over the image is the image's relMSE."""
    ref = reference.astype(np.float64)
    return np.sqrt(np.mean((image.astype(np.float64) - ref) ** 2 / (ref ** 2 + 1e-2), axis=-1))


def relative_variance(folder: str, point: PointStats, reference: np.ndarray) -> np.ndarray:
    """Per-pixel variance of one render across the point's seeds, in relMSE's units
    (divided by ref^2 + 0.01, channels averaged); zeros with a single seed."""
    if len(point.images) < 2:
        return np.zeros(reference.shape[:2])
    stack = np.stack([run_image(folder, p) for p in point.images])
    ref = reference.astype(np.float64)
    return np.mean(metrics.per_pixel_variance(stack) / (ref ** 2 + 1e-2), axis=-1)


def region_rel_mse(image: np.ndarray, reference: np.ndarray, rect) -> float:
    """relMSE of ``image`` inside ``rect`` (x0, y0, x1, y1 in pixels)."""
    return metrics.rel_mse(metrics.region(image, rect), metrics.region(reference, rect))
