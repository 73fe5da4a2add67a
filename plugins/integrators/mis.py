"""``lab_mis``: BSDF sampling and next-event estimation combined by MIS."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins import params
from mitsuba_lab.plugins.integrators.common import LabPathIntegrator, mis_weight


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
    max_depth       int    Longest path in segments, -1 = unbounded, >= 0
                           otherwise (0 renders black) (Default: -1)
    rr_depth        int    Depth at which Russian roulette starts, >= 1 (Default: 5)
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
    #: The path tracer's parameters and heuristic, beta, emitter_samples (``params.LAB_MIS``).
    PARAMETERS = params.LAB_MIS

    def configure(self, values: dict):
        self.heuristic = values["heuristic"]
        self.beta = values["beta"]
        self.emitter_samples = values["emitter_samples"]

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


mi.register_integrator("lab_mis", lambda props: LabMISIntegrator(props))
