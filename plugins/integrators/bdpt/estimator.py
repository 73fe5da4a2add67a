"""What ``lab_bdpt`` knows about itself without a Mitsuba variant (``estimator.Estimator``)."""
from __future__ import annotations

from mitsuba_lab.plugins import params as declarations
from mitsuba_lab.plugins.integrators.estimator import Estimator
from mitsuba_lab.plugins.integrators.bdpt.techniques import NONE, Technique, parse_techniques

#: Delta emitters whose densities ``endpoints.py`` knows (plugin names, as users write them).
SUPPORTED_DELTA_EMITTERS = ("point", "spot", "projector", "directional")


#: Sensors whose direction density (and a lens position density, the same for every strategy)
#: the weights know: the pinhole and the thin lens, 1 / (A' cos^3) from the point on the lens;
#: and the orthographic sensor, whose direction is a delta: every strategy but light tracing.
SUPPORTED_SENSORS = ("PerspectiveCamera", "ThinLensCamera", "OrthographicCamera")
#: Sensors light tracing cannot reach (a delta direction): t = 1 has no weight, nothing splats.
UNREACHABLE_SENSORS = ("OrthographicCamera",)


def reachable(traits, techniques: Technique) -> Technique:
    """The techniques that can contribute on the scene's sensor: all of ``techniques`` but light
    tracing where the sensor's direction is a delta (orthographic)."""
    if traits.sensor_kinds and traits.sensor_kinds[0] in UNREACHABLE_SENSORS:
        return techniques & ~Technique.LIGHT
    return techniques


class Bidirectional(Estimator):
    """lab_bdpt's estimator: bidirectional path tracing with MIS over the enabled strategies."""
    plugin_name = "lab_bdpt"
    PARAMETERS = declarations.LAB_BDPT
    OWN_PARAMETERS = ("heuristic", "beta", "strategies", "max_vertices", "only_strategy")
    #: Both subpaths scatter in media, homogeneous and heterogeneous (``media_paths``).
    RENDERS_MEDIA = True

    def techniques(self) -> Technique:
        """The techniques this estimator's parameters enable."""
        return parse_techniques(self.strategies)

    @classmethod
    def applicability(cls, traits, params: dict) -> tuple[bool, str]:
        """Left out of scenes it cannot render correctly, with the reason:

        * emitters whose emission densities ``endpoints.py`` does not know (any plugin of
          unknown kind);
        * sensors other than ``perspective``, ``thinlens`` and ``orthographic`` (on an
          orthographic sensor light tracing, t = 1, contributes nothing: its direction is a
          delta, so the strategies left must reach the light);
        * a ``strategies`` subset without the strategies some light of the scene needs: an
          emitter seen directly needs ``hit`` or ``light`` (an environment: ``hit``), light
          from delta emitters ``nee`` or ``light`` for its direct part, a scene whose BSDFs
          are all delta ``hit`` (every other strategy joins at a smooth vertex), and what the
          camera sees through a delta lobe a camera-side strategy (light tracing alone
          cannot reach the sensor through one). Within
          what it can reach a subset is unbiased (the weights are renormalised over it).
        """
        problem = cls.media_problem(traits) or cls.unsupported(traits)
        if problem:
            return False, problem
        missing = cls._subset_problem(traits, parse_techniques(params.get("strategies", "all")) or NONE)
        if missing:
            return False, f"lab_bdpt with strategies={params['strategies']} {missing}"
        return True, ""

    @classmethod
    def unsupported(cls, traits) -> str:
        """Why lab_bdpt cannot run on the scene at all ('' if it can): an emitter or sensor
        whose densities it does not know. (Strategy subsets only leave light out.)"""
        if traits.other_emitters:
            return ("lab_bdpt does not support emitters of unknown kind (only area, point, spot, "
                    "projector, directional, constant and envmap)")
        unsupported = sorted(set(traits.delta_emitters) - set(SUPPORTED_DELTA_EMITTERS))
        if unsupported:
            return f"lab_bdpt does not support {', '.join(unsupported)} emitters yet"
        sensors = traits.sensor_kinds
        if sensors and sensors[0] not in SUPPORTED_SENSORS:
            return (f"lab_bdpt supports perspective, thinlens and orthographic sensors only so far, not "
                    f"{sensors[0]} (its densities are not known)")
        return ""

    @staticmethod
    def _subset_problem(traits, techniques: Technique) -> str:
        """What light of the scene the enabled techniques cannot reach ('' if none)."""
        T = Technique
        kinds = reachable(traits, techniques)
        if not traits.emits_light:
            return ""
        if not kinds:                                  # (light tracing alone, on an orthographic sensor)
            return ("cannot render through an orthographic sensor (light tracing cannot reach a sensor "
                    "whose direction is a delta; that needs 'hit', 'nee' or 'connect')")
        if traits.environment_emitters and T.HIT not in kinds:
            return "cannot render the environment seen directly (that needs 'hit')"
        if traits.area_emitters and not kinds & (T.HIT | T.LIGHT):
            return "cannot render emitters seen directly (that needs 'hit' or 'light')"
        if traits.delta_emitters and not kinds & (T.NEE | T.LIGHT | T.MERGE):
            return "cannot render direct light from delta emitters (that needs 'nee' or 'light')"
        if not traits.smooth_bsdf and T.HIT not in kinds:
            return "cannot render a scene whose BSDFs are all delta (that needs 'hit')"
        if traits.delta_bsdf and not kinds & (T.HIT | T.NEE | T.CONNECT | T.MERGE):
            return ("cannot render what the camera sees in mirrors or through glass (light "
                    "tracing cannot reach the sensor through a delta lobe; that needs 'hit', 'nee' "
                    "or 'connect')")
        return ""
