"""Direct lighting: emitter sampling (next-event estimation) and emitter hits, each with the
densities of both techniques, so that an estimator's weight can be applied (Veach 1997, ch. 9;
pbrt-v4's ``SampleLd``; Mitsuba's ``path.cpp``). Shared by the path loop (``path.py``) and
``lab_photon``'s camera pass (``photon/gather.py``).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.estimator import Densities
from mitsuba_lab.plugins.integrators.common.spawn import sample_visible_emitter


def spectrum_or_zero(value):
    """A spectrum ``value`` where all its channels are finite, else 0 in every channel (a guard
    against 0 * inf). ``bdpt.light_subpath.float_or_zero`` is the same guard on one float."""
    return dr.select(dr.isfinite(dr.max(mi.unpolarized_spectrum(value))), value, 0.0)


def hit_densities(scene, ref, ds, pdf_bsdf, bsdf_delta, n_L: int = 1, active=True) -> Densities:
    """The densities of emission found by a BSDF-sampled ray from the vertex ``ref``: p_B is
    ``pdf_bsdf`` (the BSDF sample's pdf), n_L p_L the density with which emitter sampling at
    ``ref`` would have chosen the point that ``ds`` (built from the hit and ``ref``) describes.
    After a delta lobe (``bsdf_delta``) emitter sampling cannot produce the path: no lookup."""
    pdf_emitter = scene.pdf_emitter_direction(ref, ds, active & ~bsdf_delta)
    return Densities(bsdf=pdf_bsdf, emitter=n_L * pdf_emitter, delta=bsdf_delta)


def emitter_sample_contribution(beta, ds, em_weight, bsdf_val, w, active):
    """beta w f L_e G / p_L for one emitter sample (``em_weight`` = L_e G / p_L, ``w`` the
    sample's weight, already divided by n_L). A sample with a zero, negative or NaN pdf, or a
    non-finite value (a degenerate emitter, e.g. of zero area), contributes 0."""
    sampled = active & (ds.pdf > 0)
    return dr.select(sampled, spectrum_or_zero(beta * w * bsdf_val * em_weight), 0)


def emitter_sampling(scene, sampler, ctx, si, bsdf, beta, L, sample_weight, n_L: int, active_em,
                     active_bsdf, offset_floor: float = 1.0):
    """Next-event estimation at ``si`` with n_L emitter samples, and the vertex's BSDF sample.

    Adds to ``L`` the n_L emitter samples' contributions, each weighted by
    ``sample_weight(Densities)`` / n_L (Veach's multi-sample estimator), where ``active_em``
    (the vertex has a smooth BSDF component). The first sample's BSDF evaluation and the BSDF
    sample for the path's next direction (where ``active_bsdf``) are one call, as in Mitsuba's
    ``path.cpp``. Returns (L, BSDF sample, its weight f cos / p_B). Sampler dimensions, in this
    order: 2 (emitter), 1 + 2 (BSDF), then 2 for each further emitter sample. Shadow rays start
    at the scale-robust offset for a scene of coordinate scale ``offset_floor``
    (``spawn.offset_floor``; 1 gives Mitsuba's offsets).
    """
    bs = bsdf_weight = None
    for k in range(n_L):
        ds, em_weight = sample_visible_emitter(scene, si, sampler.next_2d(), offset_floor, active_em)
        wo = si.to_local(ds.d)
        if k == 0:
            bsdf_val, bsdf_pdf, bs, bsdf_weight = bsdf.eval_pdf_sample(
                ctx, si, wo, sampler.next_1d(), sampler.next_2d(), active_bsdf)
        else:
            bsdf_val, bsdf_pdf = bsdf.eval_pdf(ctx, si, wo, active_em)
        w = sample_weight(Densities(bsdf=bsdf_pdf, emitter=n_L * ds.pdf, delta=ds.delta))
        L = L + emitter_sample_contribution(beta, ds, em_weight, bsdf_val, w / n_L, active_em)
    return L, bs, bsdf_weight
