"""The techniques of a bidirectional estimator as flags, and a strategy (s, t) as a tuple.

Users name techniques in strings (``strategies = "hit+nee"``, lab_vcm's modes) and one strategy
as ``only_strategy = "s,t"``; those strings are parsed here once, where the parameters are read,
and the integrators work with ``Technique`` flags and ``Strategy`` tuples. Needs no Mitsuba
variant.
"""
from __future__ import annotations

import enum
from typing import NamedTuple


class Technique(enum.Flag):
    """The kinds of strategy that build a path of a light subpath (s vertices) and a camera
    subpath (t vertices), and vertex merging; a set of them is their union (``HIT | NEE``)."""
    HIT = enum.auto()        #: s = 0: the camera subpath hits an emitter
    NEE = enum.auto()        #: s = 1, t >= 2: emitter sampling (next-event estimation)
    LIGHT = enum.auto()      #: t = 1: a light vertex joined to the sensor (light tracing)
    CONNECT = enum.auto()    #: s >= 2, t >= 2: a connection between two subpath vertices
    MERGE = enum.auto()      #: vertex merging (lab_vcm): a light and a camera vertex close together

    @property
    def label(self) -> str:
        """The name users write: a kind's (``"nee"``), or the kinds of a set joined by '+'."""
        return "+".join(NAMES[kind] for kind in ORDER if kind in self)


#: Every kind, in the order users list them.
ORDER = (Technique.HIT, Technique.NEE, Technique.LIGHT, Technique.CONNECT, Technique.MERGE)
#: The name users write for each kind.
NAMES = {Technique.HIT: "hit", Technique.NEE: "nee", Technique.LIGHT: "light", Technique.CONNECT: "connect",
         Technique.MERGE: "merge"}
BY_NAME = {name: kind for kind, name in NAMES.items()}
#: lab_bdpt's techniques: every one but merging.
CONNECTIONS = Technique.HIT | Technique.NEE | Technique.LIGHT | Technique.CONNECT
#: The named sets of lab_bdpt's ``strategies``.
PRESETS = {"all": CONNECTIONS, "camera": Technique.HIT | Technique.NEE, "light": Technique.LIGHT}
#: No technique.
NONE = Technique(0)


def parse_techniques(value: str, allowed: Technique = CONNECTIONS) -> Technique | None:
    """The techniques a ``strategies`` value names (a preset, or kinds of ``allowed`` joined by
    '+', each once), or None."""
    if value in PRESETS:
        return PRESETS[value]
    names = [name.strip() for name in value.split("+")]
    kinds = [BY_NAME.get(name) for name in names]
    if not names or None in kinds or len(set(kinds)) != len(kinds) or any(k not in allowed for k in kinds):
        return None
    found = NONE
    for kind in kinds:
        found |= kind
    return found


def techniques_of(names) -> Technique | None:
    """The union of kinds named in an iterable (``("hit", "nee")``), or None if one is unknown."""
    found = NONE
    for name in names:
        if name not in BY_NAME:
            return None
        found |= BY_NAME[name]
    return found


class Strategy(NamedTuple):
    """One strategy of bidirectional path tracing: s light-subpath and t camera-subpath vertices."""
    s: int
    t: int

    @classmethod
    def parse(cls, value: str) -> Strategy | None:
        """The strategy an ``only_strategy`` value "s,t" names (s >= 0, t >= 1, s + t >= 2), or None."""
        parts = value.split(",")
        if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
            return None
        s, t = (int(p) for p in parts)
        return cls(s, t) if t >= 1 and s + t >= 2 else None

    @property
    def technique(self) -> Technique:
        """The kind of technique this strategy is."""
        if self.s == 0:
            return Technique.HIT
        if self.t == 1:
            return Technique.LIGHT
        return Technique.NEE if self.s == 1 else Technique.CONNECT
