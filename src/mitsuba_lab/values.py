"""Text back to a value, one rule for the command line's KEY=VALUE options and for the cells of
a sweep's results.csv (``mitsuba_lab.sweep``'s table without pandas)."""
from __future__ import annotations


def parse_value(text: str):
    """'8' -> 8, '0.5' -> 0.5, 'true' -> True, anything else stays a string."""
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text
