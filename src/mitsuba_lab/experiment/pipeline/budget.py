"""Whether a time-budget point was rendered at its budget, and the count that should be.

A budget point's sample count is calibrated from pilot renders (``worker.calibrate``), but a
calibration taken under another load, or of an integrator whose cost per sample changes with
the count, can miss by 2x: a "2 s" point rendered in 1.06 and 1.18 s beside another
strategy's 2.3-2.6 s, and the report called them equal time. So the measured time (the median
over the point's seeds) is checked against the budget: the runner rescales and renders again
up to ``BUDGET_RETRIES`` times (``worker.keep_to_budget``), and the report marks a point that
still misses everywhere it shows it (``missed_budget``).
"""
from __future__ import annotations

import math
import statistics

#: A budget point is at its budget when its median render time is within this fraction of it
#: either way (0.25: a 2 s point rendered in 1.5 to 2.5 s).
BUDGET_TOLERANCE = 0.25
#: Renders of a point's seeds again, at a rescaled count, after the first renders missed.
BUDGET_RETRIES = 2


def within_budget(seconds: float, budget_s: float) -> bool:
    """Whether ``seconds`` lies within BUDGET_TOLERANCE of ``budget_s`` either way."""
    return abs(seconds - budget_s) <= BUDGET_TOLERANCE * budget_s


def measured_time(times) -> float:
    """A point's measured time: the median of its seeds' render times (NaN without any)."""
    times = list(times)
    return float(statistics.median(times)) if times else math.nan


def missed_budget(point) -> bool:
    """Whether a point (anything with ``budget_s`` and ``time_s``, e.g. ``analysis.PointStats``)
    has a time budget and its median time is outside BUDGET_TOLERANCE of it."""
    budget = getattr(point, "budget_s", None)
    return budget is not None and not within_budget(point.time_s, budget)


def rescaled_count(count: int, seconds: float, budget_s: float, fixed_s: float = 0.0) -> int:
    """The sample count that fills ``budget_s``, from a render of ``count`` that took ``seconds``:
    the part above the calibration's fixed cost ``fixed_s`` scales with the count (all of it
    when the render was no slower than that fixed cost). At least 1."""
    seconds = max(seconds, 1e-6)
    scale = budget_s / seconds if seconds <= fixed_s else (budget_s - fixed_s) / (seconds - fixed_s)
    return max(1, int(round(count * max(scale, 0.0))))


#: A progressive budget point keeps its passes while their fixed cost (per pass, fitted) takes at
#: most this part of the budget; past it, passes are dropped until it does. Every pass pays the
#: fixed part again, where one render of the budget pays it once: at a tenth, the point's
#: efficiency is the estimator's, not its passes' (a 1 s point of 5 passes of 0.125 s had half
#: its time in them).
FIXED_SHARE = 0.1


def pass_times(runs, first: bool = True) -> list[tuple[int, float]]:
    """(spp, seconds) of every pass of progressive run rows (each row's ``checkpoints``: the
    elapsed time after each pass, so a pass's time is the difference); ``first=False``: the
    passes after each run's first."""
    out = []
    for row in runs:
        spp, wall = 0, 0.0
        for i, cp in enumerate(row.get("checkpoints", [])):
            if first or i:
                out.append((cp["spp"] - spp, cp["wall_s"] - wall))
            spp, wall = cp["spp"], cp["wall_s"]
    return out


def too_many_passes(times, count: int, budget_s: float) -> bool:
    """Whether ``count`` passes whose (spp, seconds) are ``times`` pay, in their fixed part
    (``progressive.fit_pass_time``), more than FIXED_SHARE of ``budget_s``."""
    from ..execution.progressive import fit_pass_time

    return count > 1 and bool(times) and fit_pass_time(list(times))[0] * count > FIXED_SHARE * budget_s


def once_cost(runs, times) -> float:
    """A continued run's one-off cost (``progressive.run_passes(continues=True)``: a chain
    estimator's bootstrap, paid by its first pass alone): the median first pass's time above
    what ``times`` (its later passes, ``pass_times(first=False)``) predict for its size. 0
    without later passes."""
    from ..execution.progressive import fit_pass_time

    firsts = [row["checkpoints"][0] for row in runs if row.get("checkpoints")]
    if not firsts or not times:
        return 0.0
    fixed, per = fit_pass_time(list(times))
    return max(0.0, statistics.median(cp["wall_s"] - fixed - per * cp["spp"] for cp in firsts))


def rescaled_passes(sizes, seconds: float, budget_s: float, times=(), once_s: float = 0.0) -> tuple[int, ...]:
    """A progressive budget point's pass sizes that fill ``budget_s``, from a run of ``sizes``
    whose measured time (median over seeds) was ``seconds``. ``times``: (spp, seconds) of the
    passes rendered (``pass_times``), fitted to fixed seconds per pass + seconds per spp
    (``progressive.fit_pass_time``) and scaled to ``seconds``; without them all the time is per
    spp. Every pass pays the fixed part, so fewer samples cannot bring the time under it: while
    the passes' fixed part exceeds FIXED_SHARE of the budget, passes are dropped (the last ones;
    the first one always stays), then the spp that fill the rest of the budget are shared out in
    the proportions of the passes kept (each at least 1 spp). ``once_s``: a one-off cost of the
    run that ``times`` leave out (``once_cost``: a chain estimator's bootstrap), taken off the
    budget before the passes share it. Deterministic given the times."""
    from ..execution.progressive import fit_pass_time

    sizes = list(sizes)
    fixed, per = fit_pass_time(list(times)) if times else (0.0, 1.0)
    predicted = fixed * len(sizes) + per * sum(sizes)
    if predicted > 0 and seconds > once_s:           # the fit scaled to the measured median
        fixed, per = fixed * (seconds - once_s) / predicted, per * (seconds - once_s) / predicted
    budget_s = max(budget_s - once_s, 1e-6)
    count = len(sizes)
    while count > 1 and fixed * count > FIXED_SHARE * budget_s:
        count -= 1
    kept = sizes[:count]
    total = max(count, int(round((budget_s - fixed * count) / per))) if per > 0 else sum(kept)
    out = [max(1, int(round(size * total / sum(kept)))) for size in kept]
    out[-1] = max(1, out[-1] + total - sum(out))     # rounding: the last pass takes the rest
    return tuple(out)


def tolerance_text() -> str:
    """The tolerance as the report and the log state it, "+-25%"."""
    return f"+-{BUDGET_TOLERANCE * 100:g}%"


def measured_range(low: float, high: float) -> str:
    """The range of a budget's measured times, "1.9-2.3 s measured" ("2 s measured" when equal
    at two digits)."""
    low_text, high_text = f"{low:.2g}", f"{high:.2g}"
    return (low_text if low_text == high_text else f"{low_text}-{high_text}") + " s measured"


def budget_label(budget_s: float, low: float, high: float) -> str:
    """An equal-time column's header: the budget and the measured range of its points' median
    times, "2 s (1.9-2.3 s measured)"."""
    return f"{budget_s:g} s ({measured_range(low, high)})"


def off_budget_text(point) -> str:
    """How a point off its budget is marked: "off its 2 s budget: 1.1 s" ("" when it is not)."""
    return f"off its {point.budget_s:g} s budget: {point.time_s:.2g} s" if missed_budget(point) else ""
