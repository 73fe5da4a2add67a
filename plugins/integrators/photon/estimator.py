"""What ``lab_photon`` knows about itself without a Mitsuba variant (``estimator.Estimator``)."""
from __future__ import annotations

from mitsuba_lab.plugins import params as declarations
from mitsuba_lab.plugins.integrators.estimator import Estimator


class PhotonMapping(Estimator):
    """lab_photon's estimator: progressive photon mapping (Knaus & Zwicker 2011), averaged over
    passes, each with its own photon map (see ``integrator.LabPhotonIntegrator``)."""
    plugin_name = "lab_photon"
    PARAMETERS = declarations.LAB_PHOTON
    RENDERS_MEDIA = True

    @classmethod
    def separate_reason(cls, params: dict) -> str:
        return ("lab_photon shrinks its radius from one of its passes to the next: averaged renders "
                "would each restart the schedule (another, more biased estimator)")
    #: A sweep's sample count N renders N passes of one camera sample per pixel each, like
    #: SPPM's one eye ray per pixel per pass (Hachisuka & Jensen 2009): more time buys more
    #: photon maps and a smaller final radius, which is what makes the estimator converge;
    #: more camera samples over one fixed set of passes would only average the same maps'
    #: bias and noise.
    SAMPLE_COUNT_PARAMETER = "passes"

    @classmethod
    def applicability(cls, traits, params: dict) -> tuple[bool, str]:
        """Left out (in either ``direct`` mode) on scenes whose light it cannot estimate:

        * no emitter (no photon to trace);
        * participating media with ``hide_emitters`` (refused by the plugin too).

        Participating media, homogeneous and heterogeneous, are rendered: volumetric photons
        gathered in a ball at the camera paths' collisions (``media_camera``).

        BSDFs that mix delta and smooth lobes (``plastic``, ``mask``, ``blendbsdf``, ...) are
        rendered: camera paths follow their delta lobes stochastically (``gather``).
        """
        if traits.media and params.get("hide_emitters"):
            return False, "lab_photon does not support hide_emitters in scenes with participating media yet"
        if traits.emitters == 0:
            return False, "lab_photon needs an emitter to trace photons from, and the scene has none"
        return True, ""
