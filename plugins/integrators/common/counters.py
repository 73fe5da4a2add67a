"""Ray counters: rays traced by kind, summed over all lanes of a render."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi


class RayCounters:
    """Rays traced since the last read, by kind (``kinds``, by default ``KINDS``: camera,
    extension (BSDF-sampled) and shadow rays), summed over all lanes.

    Each add is one atomic per SIMD packet (``ReduceMode.Local`` reduces within the packet
    first) into a small array, so counting costs a few instructions per sample: the path
    tracers count in registers inside their loop and add once per lane after it; the
    bidirectional ones add where each kind of ray is traced (``tally``).
    """
    KINDS = ("camera", "extension", "shadow")

    def __init__(self, kinds: tuple[str, ...] = KINDS):
        self.kinds = tuple(kinds)
        self.reset()

    def reset(self):
        self.totals = dr.zeros(mi.UInt64, len(self.kinds))

    def add(self, kind: str, per_lane, active=True):
        """Add each active lane's count ``per_lane`` (a UInt32 or a constant) of rays of ``kind``."""
        dr.scatter_reduce(dr.ReduceOp.Add, self.totals, mi.UInt64(per_lane),
                          self.kinds.index(kind), active, mode=dr.ReduceMode.Local)

    def add_counts(self, counts: dict[str, int]):
        """Add counts read from another integrator (``read``), e.g. one a render delegated to."""
        for kind, value in counts.items():
            if value and kind in self.kinds:
                dr.scatter_reduce(dr.ReduceOp.Add, self.totals, mi.UInt64(value), self.kinds.index(kind))

    def read(self, reset: bool = True) -> dict[str, int]:
        dr.eval(self.totals)
        values = self.totals.numpy().tolist()
        if reset:
            self.reset()
        return {kind: int(v) for kind, v in zip(self.kinds, values)}


def tally(counters: RayCounters | None, kind: str, active, per_lane=1) -> None:
    """``per_lane`` (one, or a UInt32) of ``kind`` for each ``active`` lane, when counting
    (``counters`` not None): nothing is traced into the kernel otherwise."""
    if counters is not None:
        counters.add(kind, mi.UInt32(per_lane), active)
