"""``lab_mis``: BSDF sampling and next-event estimation combined by MIS (the plugin class is in
``path.py``)."""
from __future__ import annotations

from mitsuba_lab.plugins import params as declarations
from mitsuba_lab.plugins.integrators.estimator import Densities, PathEstimator
from mitsuba_lab.plugins.integrators.common.mis_weight import equiangular_weight, hit_weight, sample_weight


class MIS(PathEstimator):
    """lab_mis's estimator: Veach's multi-sample MIS of BSDF sampling and n_L emitter samples,

        w_B(x) = h(p_B(x), n_L p_L(x)),  w_L(x) = h(n_L p_L(x), p_B(x)),

    h the heuristic (``common.mis_weight``), 1 for a sample only its own technique can produce.
    """
    plugin_name = "lab_mis"
    SIMPLICITY = 2
    samples_emitters = True
    #: The path tracer's parameters and heuristic, beta, emitter_samples (``params.LAB_MIS``).
    PARAMETERS = declarations.LAB_MIS
    OWN_PARAMETERS = ("heuristic", "beta", "emitter_samples")

    # ----------------------- Direct emission -----------------------
    def hit_weight(self, d: Densities):
        return hit_weight(d, self.heuristic, self.beta)

    # ----------------------- Emitter sampling ----------------------
    def sample_weight(self, d: Densities):
        return sample_weight(d, self.heuristic, self.beta)

    # ---------------- Equi-angular sampling in a medium ----------------
    def equiangular_weight(self, d: Densities):
        return equiangular_weight(d, self.heuristic, self.beta)

    # -- Knowledge ------------------------------------------------------------------------
    @staticmethod
    def weighting(heuristic: str, beta: float) -> tuple[str, float | None]:
        """(heuristic, beta) as the weights they give: the power heuristic with beta = 1 is the
        balance heuristic, and beta (None here) enters no other heuristic."""
        if heuristic == "power" and beta == 1.0:
            heuristic = "balance"
        return heuristic, (beta if heuristic == "power" else None)

    @classmethod
    def technique_key(cls, traits, own: dict, shared: tuple) -> tuple[tuple, str]:
        """With only delta emitters every weight is 1 whatever the heuristic: lab_mis with n_L
        shadow rays is NEE with n_L (lab_nee when n_L = 1). Otherwise the power heuristic with
        beta = 1 is the balance heuristic, and beta does not enter balance, max or average. (Not
        with ``medium_sampling = mis`` in a medium: there the heuristic weighs NEE against
        equi-angular sampling, delta lights included.)"""
        n_L = own["emitter_samples"]
        if not traits.hittable_emitters and own.get("medium_sampling", "distance") != "mis":
            return cls.nee_key(traits, n_L, shared)
        heuristic, beta = cls.weighting(own["heuristic"], own["beta"])
        if heuristic == "power":
            return ("MIS", heuristic, beta, n_L, shared), "same parameters (MIS)"
        return (("MIS", heuristic, None, n_L, shared),
                "the power heuristic with beta = 1 is the balance heuristic, and beta does not enter the "
                "balance, max or average heuristics")
