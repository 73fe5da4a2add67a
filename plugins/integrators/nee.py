"""``lab_nee``: next-event estimation only (the plugin class is in ``path.py``)."""
from __future__ import annotations

import drjit as dr

from mitsuba_lab.plugins import params as declarations
from mitsuba_lab.plugins.integrators.common.mis_weight import mis_weight
from mitsuba_lab.plugins.integrators.estimator import Densities, PathEstimator


class NEE(PathEstimator):
    """lab_nee's estimator: emitter sampling at every smooth vertex, w_L = 1; emission found by
    BSDF sampling counts only where emitter sampling cannot produce it (w_B = 1 after a camera
    ray or a delta bounce, else 0), so no light is counted twice (Veach 1997, sec. 9.1)."""
    plugin_name = "lab_nee"
    SIMPLICITY = 1
    samples_emitters = True
    #: The path tracer's and the medium sampling (``params.LAB_NEE``).
    PARAMETERS = declarations.LAB_NEE

    # ----------------------- Direct emission -----------------------
    def hit_weight(self, d: Densities):
        return dr.select(d.delta, 1.0, 0.0)   # elsewhere emitter sampling finds this light

    # ----------------------- Emitter sampling ----------------------
    def sample_weight(self, d: Densities):
        if d.equiangular is None:
            return 1.0
        return mis_weight(d.emitter, d.equiangular, "balance")    # two ways to sample the light

    def equiangular_weight(self, d: Densities):
        return mis_weight(d.equiangular, d.emitter, "balance")

    # -- Knowledge ------------------------------------------------------------------------
    @classmethod
    def technique_key(cls, traits, own: dict, shared: tuple) -> tuple[tuple, str]:
        return cls.nee_key(traits, 1, shared)
