"""Number formatting shared by every report (sweep, inverse rendering, check).

One rule everywhere: floats to a few significant digits, a missing value (None or NaN) as
"n/a" (or the caller's placeholder), infinity as "inf"; anything else as ``str``.
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
        return f"{value:.{digits}g}"
    return str(value)
