"""``lab_naive``: path tracing with BSDF sampling only."""
from __future__ import annotations

import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import LabPathIntegrator


class LabNaiveIntegrator(LabPathIntegrator):
    r"""Naive path tracer (:monosp:`lab_naive`)

    Each vertex samples one direction from the BSDF; emitted radiance is added,
    with weight 1, wherever a path happens to hit an emitter. This is the plain
    Neumann-series estimator of the rendering equation (seed text, "Path
    tracing"): unbiased for every emitter a BSDF-sampled ray can hit, and very
    noisy when emitters are small.

    It never samples emitters, so it **cannot reach delta lights** (point, spot,
    directional): in scenes lit by them its image lacks that light (biased).

    Parameters: ``max_depth`` (default -1, unbounded), ``rr_depth`` (5),
    ``hide_emitters`` (false), ``count_rays`` (true); see ``LabPathIntegrator``.

    .. code-block:: python

        {'type': 'lab_naive', 'max_depth': 8}
    """
    plugin_name = "lab_naive"

    # ----------------------- Direct emission -----------------------
    def emitter_hit_weight(self, scene, prev_it, ds, prev_bsdf_pdf, prev_bsdf_delta):
        return mi.Float(1.0)   # the only way this estimator finds light


mi.register_integrator("lab_naive", lambda props: LabNaiveIntegrator(props))
