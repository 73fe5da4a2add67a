"""When the data carry a verdict.

A verdict (the best or most efficient strategy, biased, resolved, a slope) is given only
when its uncertainty separates it: the estimate lies more than ``separation_factor`` standard errors from what it is told
apart from (2 for an error taken over pixels; Student's t at 97.5% for one taken over the
seeds, 12.7 with 2 seeds). Otherwise it reads "not resolved with N seeds (needs about M)", M
from the standard error's 1/sqrt(N) scaling (``seeds_needed``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass


#: A verdict from an error taken over pixels needs its estimate this many standard errors away.
SEPARATION = 2.0
#: ... and a "biased" bias^2 (``bias_verdict``) this many: a report's bias table holds a row per point,
#: and at two (one-sided 2.3% each) fifteen rows of unbiased estimators showed one "biased" about
#: every third report (README's walk-through: lab_nee and lab_mis at 16 spp, 2.3 and 2.4 standard
#: errors); at three, 0.13% each.
BIAS_SEPARATION = 3.0
#: The most seeds a "needs about" names; past it, "more than" this.
MOST_SEEDS = 100_000


def separation_factor(seeds: int | None = None, quantile: float = 0.975) -> float:
    """How many standard errors separate a verdict: SEPARATION for an error taken over many
    pixels (``seeds`` None), Student's t at ``quantile`` (97.5%: a two-sided 5% test) with seeds - 1
    degrees of freedom for one taken over the seeds (12.7 with 2 seeds, 4.3 with 3, 2.1 with 20);
    NaN with one seed."""
    if seeds is None:
        return SEPARATION
    if seeds < 2:
        return math.nan
    from scipy.stats import t

    return float(t.ppf(quantile, seeds - 1))


def separated(gap: float, se: float, seeds: int | None = None) -> bool:
    """Whether ``gap`` (an estimate's distance from what it is told apart from) exceeds its
    ``separation_factor`` standard errors; False where either is missing."""
    return bool(gap > separation_factor(seeds) * se) if math.isfinite(gap) and math.isfinite(se) else False


def seeds_needed(seeds: int, gap: float, se: float, over_seeds: bool = True, quantile: float = 0.975,
                 separation: float = SEPARATION) -> int | None:
    """About how many seeds would separate ``gap`` when the standard error ``se`` (measured
    with ``seeds``) falls as 1/sqrt(seeds), at ``separation_factor``'s ``quantile``; None where no
    number of seeds would (no gap, no error), MOST_SEEDS + 1 past MOST_SEEDS. ``separation``: the
    factor of an error over pixels (``over_seeds`` False)."""
    if not (math.isfinite(gap) and math.isfinite(se)) or gap <= 0 or se <= 0 or seeds < 1:
        return None
    factor = (lambda m: separation_factor(m, quantile)) if over_seeds else (lambda m: separation)  # noqa: E731
    m = max(seeds + 1, math.ceil(seeds * ((SEPARATION if over_seeds else separation) * se / gap) ** 2))
    while m <= MOST_SEEDS and not factor(m) * se * math.sqrt(seeds / m) < gap:
        m = max(m + 1, math.ceil(m * 1.05))
    return m if m <= MOST_SEEDS else MOST_SEEDS + 1


def not_resolved(seeds: int, needed: int | None) -> str:
    """The verdict where the uncertainty does not separate one: "not resolved with N seeds
    (needs about M)"."""
    if needed is None:
        return f"not resolved with {seeds} seeds"
    if needed > MOST_SEEDS:
        return f"not resolved with {seeds} seeds (needs more than {MOST_SEEDS})"
    rounded = needed if needed < 100 else int(float(f"{needed:.2g}"))
    return f"not resolved with {seeds} seeds (needs about {rounded})"


@dataclass
class Best:
    """The least costly of a set of strategies (``best_of``), and whether that is resolved."""
    winner: str | None              # the least costly (None: nothing measured)
    runner: str | None = None       # the next; None when the winner is alone
    ratio: float = math.nan         # the runner's cost over the winner's
    low: float = math.nan           # that ratio's interval at the separation used
    high: float = math.nan
    seeds: int = 0
    resolved: bool = False
    needed: int | None = None

    def text(self) -> str:
        """"bdpt (mis costs 2.7x, 1.6 to 4.5)", or "not resolved with 2 seeds (needs about 40):
        bdpt and mis within 1.03x (0.21 to 5.1)"."""
        from ...reporting import fmt

        if self.winner is None:
            return "n/a"
        if self.runner is None:
            return f"{self.winner} (the only one measured)"
        ratio = f"{fmt(self.ratio, 3)}x, {fmt(self.low, 2)} to {fmt(self.high, 2)}"
        if self.resolved:
            return f"{self.winner} ({self.runner} costs {ratio})"
        return f"{not_resolved(self.seeds, self.needed)}: {self.winner} and {self.runner} within {ratio}"


def best_of(costs: dict, seeds: int) -> Best:
    """The least costly of ``costs`` {name: (cost, its standard error over the seeds)} (NaN
    costs left out), resolved when the next one's cost ratio to it lies outside Student's-t
    standard errors of the log ratio (both costs' relative errors combined, the seeds
    independent); ``seeds``: the fewest any of them has."""
    measured = sorted((c, se, name) for name, (c, se) in costs.items() if math.isfinite(c) and c > 0)
    if not measured:
        return Best(None, seeds=seeds)
    (c1, se1, first), rest = measured[0], measured[1:]
    if not rest:
        return Best(first, seeds=seeds, resolved=True)
    c2, se2, second = rest[0]
    gap = math.log(c2 / c1)
    log_se = math.hypot(se1 / c1, se2 / c2)
    half = separation_factor(seeds) * log_se
    resolved = separated(gap, log_se, seeds)
    return Best(first, second, c2 / c1, c2 / c1 * math.exp(-half), c2 / c1 * math.exp(half), seeds, resolved,
                None if resolved else seeds_needed(seeds, gap, log_se))


#: The verdict on a bias^2 estimate more than BIAS_SEPARATION standard errors below zero.
UNRELIABLE = "unreliable variance estimate (heavy tails)"
#: Why a bias^2 estimate below zero (within BIAS_SEPARATION standard errors) names no number of seeds.
BELOW_ZERO = "below zero: more seeds would not show a bias"


def bias_verdict(bias2: float, se: float, seeds: int) -> tuple[str, int | None]:
    """(verdict, seeds needed) on a bias^2 estimate +- its standard error (an error over
    pixels): "biased" more than BIAS_SEPARATION standard errors above zero; UNRELIABLE more than
    that below, where bias^2 cannot be (the seeds' variance estimate is off: heavy tails, a few
    fireflies); else ``not_resolved``, with the seeds at which an estimate of this size would
    be BIAS_SEPARATION standard errors from zero; without a seed count for a negative estimate
    (BELOW_ZERO): with more seeds it would be flagged UNRELIABLE, never resolved as a bias."""
    if bias2 > BIAS_SEPARATION * se:
        return "biased", None
    if -bias2 > BIAS_SEPARATION * se:
        return UNRELIABLE, None
    if bias2 < 0:
        return f"{not_resolved(seeds, None)} ({BELOW_ZERO})", None
    needed = seeds_needed(seeds, abs(bias2), se, over_seeds=False, separation=BIAS_SEPARATION)
    return not_resolved(seeds, needed), needed
