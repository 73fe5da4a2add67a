"""``lab_nee``: next-event estimation only."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common import LabPathIntegrator


class LabNEEIntegrator(LabPathIntegrator):
    r"""Next-event estimation (:monosp:`lab_nee`)

    At every vertex whose BSDF has a non-delta (smooth) component, sample a
    point on an emitter and trace a shadow ray (the three-point form's direct
    term, seed text "The algorithm and next-event estimation"). BSDF sampling
    only extends the path: emission it finds counts for camera rays and after
    delta (specular) bounces, which NEE cannot produce, and nowhere else, so
    no light is counted twice.

    Unbiased for area, environment and delta emitters. Near-specular
    reflections of large emitters are noisy here (a point sampled on the
    emitter rarely falls in a sharp BSDF lobe): that is what ``lab_mis`` fixes.

    Parameters: ``max_depth`` (default -1, unbounded), ``rr_depth`` (5),
    ``hide_emitters`` (false), ``count_rays`` (true); see ``LabPathIntegrator``.

    .. code-block:: python

        {'type': 'lab_nee', 'max_depth': 8}
    """
    plugin_name = "lab_nee"
    samples_emitters = True

    # ----------------------- Direct emission -----------------------
    def emitter_hit_weight(self, scene, prev_it, ds, prev_bsdf_pdf, prev_bsdf_delta):
        return dr.select(prev_bsdf_delta, 1.0, 0.0)

    # ----------------------- Emitter sampling ----------------------
    def emitter_sample_weight(self, ds, bsdf_pdf):
        return mi.Float(1.0)


mi.register_integrator("lab_nee", lambda props: LabNEEIntegrator(props))
