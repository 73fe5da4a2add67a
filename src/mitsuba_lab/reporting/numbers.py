"""Number formatting shared by every report (sweep, inverse rendering, check).

One rule everywhere: floats to a few significant digits, a missing value (None or NaN) as
"n/a" (or the caller's placeholder), infinity as "inf"; anything else as ``str``. Whole numbers
below a million print whole (1004, not 1e+03). Numbers that carry an error, or that are
compared in a column, get the digits that tell apart any two of them differing by more than
their error (``fmt_pm``, ``fmt_column``): 998.95 and 1003.78 never print alike.
"""
from __future__ import annotations

import math


def fmt(value, digits: int = 3, missing: str = "n/a") -> str:
    """``value`` for a table cell: a float with ``digits`` significant digits (``%g``), NaN as
    "n/a", +inf as "inf"; None and "" (no value at all, e.g. a skipped row) as ``missing``;
    integers, strings and the rest as ``str(value)``."""
    if value is None or (isinstance(value, str) and value == ""):
        return missing
    if isinstance(value, float):
        if math.isnan(value):
            return "n/a"
        if value == math.inf:
            return "inf"
        return _significant(value, digits)
    return str(value)


#: Below this magnitude a number that %g would write with an exponent of digits or more
#: (1e+03 for 998.95 at 3 digits) prints as a whole number instead.
WHOLE_BELOW = 1e6
#: The most significant digits any rule here asks for.
MOST_DIGITS = 9


def _significant(value: float, digits: int) -> str:
    text = f"{value:.{digits}g}"
    if "e+" in text and abs(value) < WHOLE_BELOW:
        return f"{value:.0f}"
    return text


def _usable(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)


def _exponent(x: float) -> int:
    return math.floor(math.log10(abs(x))) if x else 0


def digits_for_error(value: float, error: float, digits: int = 3) -> int:
    """Significant digits of ``value`` that reach its error's second significant digit (at
    least ``digits``, at most MOST_DIGITS): 1003.78 +- 0.05 needs 6, 0.5 +- 0.1 keeps 3."""
    if not (_usable(value) and _usable(error)) or error <= 0 or value == 0:
        return digits
    return max(digits, min(MOST_DIGITS, _exponent(value) - _exponent(error) + 2))


def separating_digits(values, errors=None, digits: int = 3) -> int:
    """The fewest significant digits (at least ``digits``) at which every two of ``values``
    that differ by more than their combined error (``errors``, one per value; None: exact
    values, any difference counts) print differently."""
    errors = [0.0] * len(values) if errors is None else list(errors)
    pairs = [(v, e if _usable(e) else 0.0) for v, e in zip(values, errors) if _usable(v)]
    best = digits
    for i, (a, ea) in enumerate(pairs):
        for b, eb in pairs[i + 1:]:
            if a == b or abs(a - b) <= math.hypot(ea, eb):
                continue
            n = best
            while n < MOST_DIGITS and _significant(float(a), n) == _significant(float(b), n):
                n += 1
            best = max(best, n)
    return best


def fmt_column(values, errors=None, digits: int = 3, missing: str = "n/a") -> list[str]:
    """``values`` as one column's cells, all with the digits ``separating_digits`` gives."""
    n = separating_digits(values, errors, digits)
    return [fmt(float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v, n, missing)
            for v in values]


def fmt_pm(value, error, digits: int = 3, others=(), missing: str = "n/a", separation: float | None = None) -> str:
    """"value +- error": the value to its error's second significant digit (``digits_for_error``)
    and apart from ``others``, (value, error) pairs it is compared with (``separating_digits``);
    the error to two significant digits. The bare value where the error is missing.

    ``separation``: the number of errors at which a verdict is given on this value (2 for a
    bias^2); both are then printed with the digits that put the printed |value| / error on the
    same side of it as the exact one (-3.207e-4 +- 1.639e-4 is 1.96 errors: "-0.000321 +- 0.000164",
    not "-0.000321 +- 0.00016", which reads as 2.006)."""
    if not _usable(error):
        return fmt(value, digits, missing)
    n = digits_for_error(value, error, digits)
    if others:
        pairs = [(value, error), *others]
        n = max(n, separating_digits([v for v, _ in pairs], [e for _, e in pairs], digits))
    error_digits = 2
    if separation is not None and _usable(value) and error > 0:
        side = abs(value) > separation * error
        while error_digits < MOST_DIGITS:
            shown_value, shown_error = float(fmt(value, n)), float(fmt(error, error_digits))
            if shown_error > 0 and (abs(shown_value) > separation * shown_error) == side:
                break
            error_digits += 1
            n = min(MOST_DIGITS, max(n, _exponent(value) - _exponent(error) + error_digits))
    return f"{fmt(value, n, missing)} +- {fmt(error, error_digits)}"


def fmt_pm_column(values, errors, digits: int = 3, missing: str = "n/a") -> list[str]:
    """One column of "value +- error" cells (``fmt_pm``), each value with the digits that also
    tell it apart from every other value of the column it differs from by more than their
    errors combined."""
    n = separating_digits(values, errors, digits)
    return [fmt_pm(v, e, n, missing=missing) for v, e in zip(values, errors)]
