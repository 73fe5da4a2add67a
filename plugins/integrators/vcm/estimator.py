"""What ``lab_vcm`` knows about itself without a Mitsuba variant (``estimator.Estimator``)."""
from __future__ import annotations

from mitsuba_lab.plugins import params as declarations
from mitsuba_lab.plugins.integrators.bdpt.estimator import Bidirectional, reachable
from mitsuba_lab.plugins.integrators.bdpt.techniques import CONNECTIONS, Technique

#: The techniques of each of lab_vcm's modes (``params.VCM_MODES``; SmallVCM's estimators behind
#: one MIS).
MODES = {
    "vcm": CONNECTIONS | Technique.MERGE,                # vertex connection and merging: every technique
    "bpt": CONNECTIONS,                                  # connections only: lab_bdpt
    "bpm": Technique.HIT | Technique.MERGE,              # bidirectional photon mapping: merges at every vertex
    "ppm": Technique.HIT | Technique.MERGE,              # progressive photon mapping: the first smooth vertex only
    "lt": Technique.LIGHT,                               # light tracing
    "pt": Technique.HIT | Technique.NEE,                 # camera side only: lab_mis's estimator
}


def merges_first(params: dict) -> bool:
    """Whether lab_vcm with these (resolved) parameters merges at the camera's first vertex:
    ``merge_first``, and always in mode ppm (its one merge is at the first smooth vertex)."""
    return params.get("mode", "vcm") == "ppm" or bool(params.get("merge_first", False))


class VertexMerging(Bidirectional):
    """lab_vcm's estimator: the techniques of its ``mode`` (``MODES``) under one MIS."""
    plugin_name = "lab_vcm"
    #: Every mode scatters in media through lab_bdpt's media loops, merging at medium vertices too
    #: (``volume_merging``)
    RENDERS_MEDIA = True
    PARAMETERS = declarations.LAB_VCM
    OWN_PARAMETERS = ("mode", "radius", "radius_volume", "alpha", "light_paths", "kernel", "merge_first", "merge_vertices", "connections", "pilot", "light_paths_max", "heuristic", "beta",
                      "max_vertices")

    def techniques(self) -> Technique:
        return MODES[self.mode]

    @classmethod
    def separate_reason(cls, params: dict) -> str:
        mode = params.get("mode", "vcm")
        if Technique.MERGE in MODES.get(mode, Technique.MERGE):
            return (f"lab_vcm mode={mode} merges with a radius that shrinks from sample to sample within a "
                    f"render: averaged renders would each restart the schedule")
        return ""

    @classmethod
    def media_settings_problem(cls, traits, params: dict) -> str:
        """Why these settings cannot render the scene's participating media ('' if they can):
        lab_bdpt's media loops connect to every light vertex and keep no caustic-merge state."""
        if not traits.media:
            return ""
        if params.get("connections", "all") == "one":
            return ("lab_vcm: connections = 'one' is not supported in scenes with participating media yet "
                    "(use connections = 'all')")
        if params.get("merge_vertices", "all") == "caustic":
            return ("lab_vcm: merge_vertices = 'caustic' is not supported in scenes with participating media "
                    "yet (use merge_vertices = 'all')")
        return ""

    @classmethod
    def applicability(cls, traits, params: dict) -> tuple[bool, str]:
        """As lab_bdpt's (unknown emitters and sensors, light a mode cannot reach, light
        tracing, mode lt, on an orthographic sensor);
        merging reaches any light that arrives at a smooth surface the camera sees."""
        mode = params.get("mode", "vcm")
        problem = cls.media_settings_problem(traits, params) or cls.unsupported(traits)
        if problem:
            return False, problem
        techniques = MODES[mode]
        missing = cls._subset_problem(traits, techniques)
        if missing:
            return False, f"lab_vcm with mode={mode} {missing}"
        if (not merges_first(params) and traits.emits_light and traits.delta_emitters
                and not reachable(traits, techniques) & (Technique.NEE | Technique.LIGHT)):
            return False, (f"lab_vcm with mode={mode} and merge_first=false cannot render direct light from "
                           f"delta emitters on what the camera sees (that needs merging at the first vertex, "
                           f"'nee' or 'light')")
        return True, ""

    @classmethod
    def unsupported(cls, traits) -> str:
        return super().unsupported(traits).replace("lab_bdpt", "lab_vcm")
