"""What a declared parameter is (``Param``): its name, type, default, constraint and one-line doc,
and how a given value is checked and converted (``Param.convert``), with the one-line
``ParameterError`` a user sees. The declarations themselves are ``params.py``'s.

No Mitsuba import (variant-free)."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Callable


class ParameterError(ValueError):
    """A lab plugin parameter with a wrong name, type or value (one-line message)."""


def _show(value) -> str:
    """A value as the messages show it: strings quoted, numbers plain."""
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return repr(value)
    if isinstance(value, numbers.Integral):
        return repr(int(value))
    return repr(float(value))


def _is_bool(value) -> bool:
    return isinstance(value, bool) or (type(value).__module__ == "numpy" and type(value).__name__ in ("bool_", "bool"))


@dataclass(frozen=True)
class Param:
    """One declared parameter.

    ``kind``: int, float, bool or str. ``check``: a predicate on the converted value,
    with ``expected`` the text after "must be" when it fails ("an integer >= 1");
    ``choices``: the allowed strings. ``doc``: one line for tables and messages.
    """
    name: str
    kind: type
    default: Any
    doc: str = ""
    check: Callable[[Any], bool] | None = None
    expected: str = ""
    choices: tuple[str, ...] = ()

    def convert(self, plugin: str, value):
        """``value`` checked and normalised to ``kind``; ParameterError otherwise."""
        def fail(text):
            raise ParameterError(f"{plugin}: parameter '{self.name}' {text}")

        if self.kind is int:
            if _is_bool(value) or not isinstance(value, numbers.Real):
                fail(f"expects an integer, got {_show(value)}")
            if not isinstance(value, numbers.Integral):
                f = float(value)
                if not (math.isfinite(f) and f.is_integer()):
                    fail(f"expects an integer, got {_show(value)}")
            value = int(value)
        elif self.kind is float:
            if _is_bool(value) or not isinstance(value, numbers.Real):
                fail(f"expects a number, got {_show(value)}")
            value = float(value)
        elif self.kind is bool:
            if not _is_bool(value):
                fail(f"expects a boolean, got {_show(value)}")
            value = bool(value)
        elif self.kind is str:
            if not isinstance(value, str):
                fail(f"expects a string, got {_show(value)}")
            value = str(value)
        else:  # pragma: no cover - a declaration error
            raise TypeError(f"{plugin}: parameter '{self.name}' has unsupported kind {self.kind!r}")
        if self.choices and value not in self.choices:
            fail(f"must be one of {', '.join(self.choices)}, got {_show(value)}")
        if self.check is not None and not self.check(value):
            fail(f"must be {self.expected or 'valid'}, got {_show(value)}")
        return value


def _int_at_least(lo: int) -> dict:
    return {"check": lambda v: v >= lo, "expected": f"an integer >= {lo}"}


#: The check of a length in scene units whose 0 means "automatic" (the merging and gathering radii).
AUTOMATIC_LENGTH = {"check": lambda v: v >= 0.0 and math.isfinite(v), "expected": "0 (automatic) or a finite number > 0"}


def _override(parameters: tuple[Param, ...], *replacements: Param) -> tuple[Param, ...]:
    """``parameters`` with the entries of the same names replaced, order kept."""
    by_name = {p.name: p for p in replacements}
    return tuple(by_name.get(p.name, p) for p in parameters)
