"""What each lab integrator knows about itself, without a Mitsuba variant or a rendering.

Every lab integrator plugin has an estimator class (a subclass of ``Estimator``, named by
``plugin_name``) that the plugin class uses (its ``ESTIMATOR``) and that answers, from a
scene's ``SceneTraits`` and the plugin's resolved parameters:

* ``applicability``: whether it renders the scene's light correctly, with a one-line reason
  when it does not (the experiment planner leaves such strategies out);
* ``equivalence``: a key equal for two strategies only when they are provably the same
  estimator on the scene, with the reason (the planner runs such strategies once);
* ``SAMPLE_COUNT_PARAMETER``: the parameter a sweep's sample count sets (None: samples per
  pixel).

Estimator classes import no Mitsuba variant (their modules are never re-run on a switch), so
the planner, the configuration and the report can ask them without rendering anything.
``lookup(plugin_type)`` finds the class of a lab integrator.

For the path tracers (``PathEstimator``) the estimator is also the part of the path loop
that differs between them: the MIS weights of the two ways a path reaches an emitter,
computed from ``Densities`` (Veach 1997, ch. 9).
"""
from __future__ import annotations

from typing import Any, NamedTuple

from mitsuba_lab.plugins import params as declarations

#: Parameters that do not change an estimator (only what is counted).
NO_EFFECT = ("count_rays",)
#: Parameters that change an estimator only in a scene with participating media.
MEDIUM_PARAMETERS = ("medium_sampling", "equiangular_samples", "transmittance", "majorants", "majorant_resolution", "spectral_mis")
#: Rank of a plugin that is not the lab's among identical estimators.
OTHER_SIMPLICITY = 3

_REGISTRY: dict[str, type["Estimator"]] = {}


def _load() -> None:
    """Import every estimator module (they register their classes; idempotent)."""
    from mitsuba_lab.plugins import import_variant_free

    import_variant_free()


def lookup(plugin_type: str) -> type["Estimator"] | None:
    """The estimator class of a lab integrator, or None for any other plugin name."""
    _load()
    return _REGISTRY.get(plugin_type)


def sample_count_parameters() -> dict[str, str]:
    """{plugin type: the parameter its sample count sets} for the lab integrators whose sample
    count is not samples per pixel (``Estimator.SAMPLE_COUNT_PARAMETER``)."""
    _load()
    return {name: cls.SAMPLE_COUNT_PARAMETER for name, cls in _REGISTRY.items()
            if cls.SAMPLE_COUNT_PARAMETER is not None}


def exact_key(plugin_type: str, params: dict) -> tuple:
    """The equivalence key of a strategy that is the same estimator only as itself."""
    return ("exact", plugin_type, tuple(sorted((k, repr(v)) for k, v in params.items())))


class Estimator:
    """Base of the lab integrators' estimator classes (see the module docstring).

    An instance holds the estimator's own parameters, taken from the plugin's resolved
    values (``params.resolve``): ``Estimator(values)``.
    """
    #: Plugin name (``lab_mis``); a subclass that sets it is registered under it.
    plugin_name = ""
    #: Declared parameters (``plugins/params.py``).
    PARAMETERS: tuple = ()
    #: The parameter a sweep's sample count sets instead of samples per pixel, or None.
    SAMPLE_COUNT_PARAMETER: str | None = None
    #: Among provably identical strategies the simplest (lowest) runs; others rank OTHER_SIMPLICITY.
    SIMPLICITY = OTHER_SIMPLICITY
    #: The estimator's own parameters (kept by an instance as attributes of the same name).
    OWN_PARAMETERS: tuple[str, ...] = ()
    #: Whether it simulates participating media (else it renders a scene as if they were absent).
    RENDERS_MEDIA = False

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "plugin_name" in cls.__dict__ and cls.plugin_name:
            _REGISTRY[cls.plugin_name] = cls

    def __init__(self, values: dict):
        for name in self.OWN_PARAMETERS:
            setattr(self, name, values[name])

    def settings(self) -> dict[str, Any]:
        """The estimator's own parameters, as plain values."""
        return {name: getattr(self, name) for name in self.OWN_PARAMETERS}

    @classmethod
    def applicability(cls, traits, params: dict) -> tuple[bool, str]:
        """(True, '') when the strategy renders the scene correctly, else (False, one-line
        reason). ``traits``: the scene's ``SceneTraits``; ``params``: resolved parameters."""
        return True, ""

    @classmethod
    def unsupported(cls, traits) -> str:
        """Why the integrator cannot render the scene at all ('' when it can, perhaps leaving
        some light out, which ``applicability`` says): ``mitsuba-lab render`` then refuses it
        even with ``--allow-unsupported``."""
        return ""

    @classmethod
    def separate_reason(cls, params: dict) -> str:
        """Why renders of different seeds, averaged weighted by their spp, are not this estimator
        at the total spp ('' when they are, as for every unbiased estimator: the runner's
        progressive runs accumulate such renders)."""
        return ""

    @classmethod
    def equivalence(cls, traits, params: dict) -> tuple[tuple, str]:
        """(key, reason): strategies with equal keys are provably the same estimator on a scene
        with these traits (same distribution of every pixel); ``reason`` says why."""
        key = (cls.plugin_name, tuple(sorted((k, repr(v)) for k, v in params.items()
                                             if k not in NO_EFFECT)))
        return key, f"same parameters ({cls.plugin_name})"

    @classmethod
    def media_problem(cls, traits) -> str:
        """The reason a strategy that ignores participating media is left out, or ''."""
        if traits.media and not cls.RENDERS_MEDIA:
            return (f"{cls.plugin_name} does not support participating media (the scene has a medium): "
                    f"use lab_mis or Mitsuba's volpath")
        return ""


# ---------------------------------------------------------------------------
# Path tracers: the MIS weights of the two techniques
# ---------------------------------------------------------------------------
class Densities(NamedTuple):
    """What the path loop knows about a path x that reached an emitter, in solid angle at the
    vertex x was sampled from, for both techniques (Veach's multi-sample estimator):

    * ``bsdf``: p_B(x), the density of BSDF sampling;
    * ``emitter``: n_L p_L(x), n_L (shadow rays per vertex) times the density of emitter sampling;
    * ``delta``: x was drawn from a delta component (a delta BSDF lobe for an emitter hit, a
      delta emitter for an emitter sample), which the other technique cannot produce;
    * ``equiangular``: at a medium vertex where equi-angular sampling runs, the density of that
      third technique (``equiangular.equiangular_density``), and then all three are densities per unit
      distance along the ray and solid angle at the vertex; None elsewhere (two techniques).
    """
    bsdf: Any
    emitter: Any
    delta: Any
    equiangular: Any = None


class PathEstimator(Estimator):
    """A unidirectional path tracer (``lab_naive``, ``lab_nee``, ``lab_mis``): the one path loop
    (``path.py``) with the estimator's two weights.

    The loop adds ``beta * hit_weight(d) * L_e`` for emission found by a BSDF-sampled ray and
    ``beta * sample_weight(d) * f * L_e G / (n_L p_L)`` for each of n_L emitter samples at a
    vertex with a smooth BSDF. Unbiased when w_B(x) + w_L(x) = 1 wherever either technique can
    produce x, so a sample only its own technique can produce (``d.delta``) has weight 1: the
    loop relies on that where every sample of a kind is delta (``path.KernelPlan``).
    """
    PARAMETERS = declarations.PATH_TRACER
    RENDERS_MEDIA = True
    #: Whether the estimator samples emitters (next-event estimation) at all.
    samples_emitters = False
    #: Shadow rays per vertex, n_L.
    emitter_samples = 1

    def hit_weight(self, d: Densities):
        """w_B: the weight of emission found by a BSDF-sampled ray (camera rays arrive with
        ``d.delta`` True: no emitter sample can produce what a camera ray sees)."""
        raise NotImplementedError

    def sample_weight(self, d: Densities):
        """w_L: the weight of one emitter sample (only called when ``samples_emitters``)."""
        raise NotImplementedError

    def equiangular_weight(self, d: Densities):
        """w_E: the weight of an equi-angular sample in a medium (``d.equiangular`` its density;
        only called when ``samples_emitters``)."""
        raise NotImplementedError

    # -- Knowledge ------------------------------------------------------------------------


    @classmethod
    def equivalence(cls, traits, params: dict) -> tuple[tuple, str]:
        """The classes of identical path tracers, case by case:

        * max_depth 0, or no emitter emits: every pixel is exactly 0.
        * max_depth 1: only emitters seen directly; no vertex samples anything, every estimator
          returns the emission its camera ray hits, with weight 1.
        * All BSDFs delta and no medium: NEE runs only at vertices with a smooth BSDF component,
          so lab_nee and lab_mis never sample an emitter (any heuristic, any n_L), and every
          emitter hit follows a camera ray or a delta bounce, where all three weight it 1. So
          lab_naive, lab_nee and lab_mis are one estimator, *whatever the emitters*: delta lights
          contribute nothing to any of them (nor to Mitsuba's path). (A medium's phase function is
          smooth: NEE runs at its vertices.)
        * Otherwise each estimator's own key (``technique_key``). Parameters that are not the
          estimator's (Mitsuba's own, e.g. ``timeout``) must match; count_rays is ignored.
        """
        p = {k: v for k, v in params.items() if k not in NO_EFFECT}
        # they act only in media, and only where vertices sample emitters
        medium = {k: p.pop(k) for k in MEDIUM_PARAMETERS if k in p} if traits.media else {}
        p = {k: v for k, v in p.items() if k not in MEDIUM_PARAMETERS}
        max_depth, rr_depth = p.pop("max_depth"), p.pop("rr_depth")
        hide = p.pop("hide_emitters") and traits.hittable_emitters         # nothing to hide otherwise
        own = {name: p.pop(name) for name in cls.OWN_PARAMETERS}
        extras = tuple(sorted((k, repr(v)) for k, v in p.items()))
        if max_depth == 0 or not traits.emits_light:
            return ("black", extras), "every pixel is 0 (max_depth 0, or no emitter emits)"
        if max_depth == 1:
            return (("emitters seen directly", hide, extras),
                    "max_depth 1: every strategy returns the emission its camera ray hits")
        shared = (max_depth, rr_depth, hide, extras, tuple(sorted(medium.items())))
        if not traits.smooth_bsdf and not traits.media:
            return (("BSDF sampling only (all BSDFs delta)", shared),
                    "all BSDFs are delta: no vertex can sample an emitter, so every strategy is BSDF "
                    "sampling with weight 1")
        return cls.technique_key(traits, {**own, **medium}, shared)

    @classmethod
    def technique_key(cls, traits, own: dict, shared: tuple) -> tuple[tuple, str]:
        """(key, reason) on a scene where vertices can sample emitters and max_depth >= 2;
        ``own``: the estimator's own parameters (and in a scene with media the medium ones),
        ``shared``: the rest, which must match."""
        return (cls.plugin_name, shared), f"same parameters ({cls.plugin_name})"

    @staticmethod
    def nee_key(traits, n_L: int, shared: tuple) -> tuple[tuple, str]:
        """Next-event estimation with n_L shadow rays per vertex and weight 1 for emission found
        by BSDF sampling only after a delta bounce: lab_nee (n_L = 1), and lab_mis with every
        weight 1 (only delta emitters, which BSDF-sampled rays never hit)."""
        reason = ("only delta emitters: BSDF-sampled rays never hit one and every MIS weight is 1, "
                  "so MIS is NEE" if not traits.hittable_emitters else "same parameters (NEE)")
        return ("NEE", n_L, shared), reason
