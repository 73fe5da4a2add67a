"""Ray counters: rays traced by kind, summed over all lanes of a render."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi


class RayCounters:
    """Rays traced since the last read, by kind (``KINDS``: camera, extension (BSDF-sampled)
    and shadow rays), summed over all lanes.

    Each lane counts in registers inside its loop; after the loop one atomic add per lane and
    kind (reduced within each SIMD packet first, ``ReduceMode.Local``) keeps the cost to a few
    instructions per sample.
    """
    KINDS = ("camera", "extension", "shadow")

    def __init__(self):
        self.reset()

    def reset(self):
        self.totals = dr.zeros(mi.UInt64, len(self.KINDS))

    def add(self, kind: str, per_lane, active=True):
        """Add each active lane's count ``per_lane`` (a UInt32 or a constant) of rays of ``kind``."""
        dr.scatter_reduce(dr.ReduceOp.Add, self.totals, mi.UInt64(per_lane),
                          self.KINDS.index(kind), active, mode=dr.ReduceMode.Local)

    def read(self, reset: bool = True) -> dict[str, int]:
        dr.eval(self.totals)
        values = self.totals.numpy().tolist()
        if reset:
            self.reset()
        return {kind: int(v) for kind, v in zip(self.KINDS, values)}


class WorkCounters(RayCounters):
    """lab_bdpt's and lab_vcm's camera-side work, by kind: camera rays, extension rays, next-event
    estimation's shadow rays, connections (each with its shadow ray) and merge lookups (light
    vertices read by a merge). lab_vcm's pilot prices a render by them (``selection.PilotCosts``);
    the light side's work is read from what the light passes already return (``BdptStats``)."""
    KINDS = ("camera", "extension", "shadow", "connection", "merge")


def count(counters: RayCounters | None, kind: str, per_lane=1, active=True):
    """``counters.add(kind, per_lane, active)``, or nothing without counters (a render that is
    not counted compiles the same kernels as before counting existed)."""
    if counters is not None:
        counters.add(kind, per_lane, active)
