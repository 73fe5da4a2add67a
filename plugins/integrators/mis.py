"""``lab_mis``: BSDF sampling and next-event estimation combined by MIS."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import HEURISTICS, LabPathIntegrator, mis_weight


class LabMISIntegrator(LabPathIntegrator):
    r"""Multiple importance sampling path tracer (:monosp:`lab_mis`)

    Every vertex with a smooth BSDF component takes ``emitter_samples`` (n_L)
    emitter samples and one BSDF sample; each sample that reaches an emitter is
    weighted by Veach's multi-sample MIS estimator (Veach & Guibas 1995):

        w_L(x) = h(n_L p_L(x), p_B(x)),  w_B(x) = h(p_B(x), n_L p_L(x)),

    with both densities in solid angle and the emitter-sample contributions
    divided by n_L. Delta emitters (only NEE reaches them) and delta BSDF lobes
    (only BSDF sampling reaches their emitters) get weight 1, which keeps the
    estimator unbiased.

    =============== ====== =====================================================
    heuristic       string ``balance`` | ``power`` | ``max`` | ``average``
                           (Default: ``power``). ``average`` weights 1/2 each
                           wherever both techniques can sample x: the plain
                           average the seed text warns about, kept for study.
    beta            float  Exponent of the power heuristic, > 0; 1 = balance.
                           (Default: 2)
    emitter_samples int    Shadow rays per vertex, n_L >= 1. The kernel holds
                           n_L copies of the emitter-sampling code. (Default: 1)
    max_depth       int    Longest path in segments, -1 = unbounded (Default: -1)
    rr_depth        int    Depth at which Russian roulette starts (Default: 5)
    hide_emitters   bool   Camera rays pass through area emitters; the bare
                           environment is invalid (Default: false)
    count_rays      bool   Count camera / extension / shadow rays (Default: true)
    =============== ====== =====================================================

    All weights are computed from pdf ratios (``common.mis_weight``), so pdfs
    of 0, 1e-30, 1e30 or inf give the right limit and never NaN.

    .. code-block:: python

        {'type': 'lab_mis', 'heuristic': 'power', 'beta': 2.0, 'emitter_samples': 1}
    """
    plugin_name = "lab_mis"
    samples_emitters = True

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        self.heuristic = str(props.get("heuristic", "power"))
        if self.heuristic not in HEURISTICS:
            raise ValueError(f"lab_mis: parameter 'heuristic' must be one of {', '.join(HEURISTICS)}, "
                             f"got '{self.heuristic}'")
        self.beta = float(props.get("beta", 2.0))
        if not (self.beta > 0 and dr.isfinite(self.beta)):
            raise ValueError(f"lab_mis: parameter 'beta' must be a finite number > 0, got {self.beta}")
        self.emitter_samples = int(props.get("emitter_samples", 1))
        if self.emitter_samples < 1:
            raise ValueError(f"lab_mis: parameter 'emitter_samples' must be >= 1, "
                             f"got {self.emitter_samples}")

    def weight(self, pdf_self, pdf_other):
        return mis_weight(pdf_self, pdf_other, self.heuristic, self.beta)

    # ----------------------- Direct emission -----------------------
    def emitter_hit_weight(self, scene, prev_it, ds, prev_bsdf_pdf, prev_bsdf_delta):
        pdf_em = scene.pdf_emitter_direction(prev_it, ds, ~prev_bsdf_delta)
        return dr.select(prev_bsdf_delta, 1.0,
                         self.weight(prev_bsdf_pdf, self.emitter_samples * pdf_em))

    # ----------------------- Emitter sampling ----------------------
    def emitter_sample_weight(self, ds, bsdf_pdf):
        return dr.select(ds.delta, 1.0, self.weight(self.emitter_samples * ds.pdf, bsdf_pdf))

    def settings(self) -> dict:
        return {"heuristic": self.heuristic, "beta": self.beta,
                "emitter_samples": self.emitter_samples, **super().settings()}


mi.register_integrator("lab_mis", lambda props: LabMISIntegrator(props))
