"""``lab_naive``: path tracing with BSDF sampling only (the plugin class is in ``path.py``)."""
from __future__ import annotations

from mitsuba_lab.plugins.integrators.estimator import Densities, PathEstimator


class Naive(PathEstimator):
    """lab_naive's estimator: BSDF sampling only, w_B = 1 for every emitter hit (Kajiya 1986's
    Neumann series); no emitter sampling, so delta lights are never reached."""
    plugin_name = "lab_naive"
    SIMPLICITY = 0

    # ----------------------- Direct emission -----------------------
    def hit_weight(self, d: Densities):
        return 1.0   # the only way this estimator finds light

    # -- Knowledge ------------------------------------------------------------------------
    @classmethod
    def applicability(cls, traits, params: dict) -> tuple[bool, str]:
        """Left out where delta lights light a vertex it could shade: BSDF-sampled rays never
        reach a delta light. (With only delta BSDFs and no medium no estimator can use a delta
        light, so there lab_naive is not worse than the others; a medium's phase functions are
        smooth.)"""
        ok, reason = super().applicability(traits, params)
        if ok and traits.delta_emitters and (traits.smooth_bsdf or traits.media):
            kinds = ", ".join(dict.fromkeys(traits.delta_emitters))
            if not traits.hittable_emitters:
                return False, (f"lab_naive cannot reach delta lights ({kinds}): the scene has no other "
                               f"emitter")
            return False, f"lab_naive cannot reach delta lights ({kinds}): it would miss their light (biased)"
        return ok, reason
