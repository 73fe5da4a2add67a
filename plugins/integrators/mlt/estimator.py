"""``lab_pssmlt``'s and ``lab_mmlt``'s estimator classes: what the planner knows of them without a
Mitsuba variant."""
from __future__ import annotations

from mitsuba_lab.plugins import params as declarations
from mitsuba_lab.plugins.integrators.bdpt.estimator import Bidirectional
from mitsuba_lab.plugins.integrators.bdpt.techniques import CONNECTIONS
from mitsuba_lab.plugins.integrators.estimator import exact_key
from mitsuba_lab.plugins.integrators.mis import MIS

#: The parameters of the chains (the rest are lab_mis's, or lab_bdpt's).
CHAIN_PARAMETERS = ("chains", "bootstrap", "bootstrap_share", "large_step", "small_step", "sigma")


def chain_equivalence(cls, traits, params: dict) -> tuple[tuple, str]:
    """A chain estimator is equivalent only to itself with the same parameters (its pixels are
    correlated, its distribution its own), or black where nothing emits or max_depth is 0."""
    if params.get("max_depth") == 0 or not traits.emits_light:
        extras = tuple(sorted((k, repr(v)) for k, v in params.items()
                              if k not in {p.name for p in cls.PARAMETERS}))
        return ("black", extras), "every pixel is 0 (max_depth 0, or no emitter emits)"
    return exact_key(cls.plugin_name, {k: v for k, v in params.items() if k != "count_rays"}), \
        f"same parameters ({cls.plugin_name})"


class PSSMLT(MIS):
    """lab_pssmlt: lab_mis's path tracer (its two MIS weights) driven by Markov chains in primary
    sample space. A different estimator from lab_mis on every scene that has light (its pixels
    are correlated, its distribution not lab_mis's), so it is equivalent only to itself."""
    plugin_name = "lab_pssmlt"
    PARAMETERS = declarations.LAB_PSSMLT
    OWN_PARAMETERS = MIS.OWN_PARAMETERS + CHAIN_PARAMETERS
    SIMPLICITY = 4
    #: A progressive run's later passes continue the first pass's chains (the runner's
    #: ``progressive.run_passes``; ``LabPSSMLTIntegrator._continue``).
    CONTINUES_PASSES = True

    @classmethod
    def equivalence(cls, traits, params: dict) -> tuple[tuple, str]:
        return chain_equivalence(cls, traits, params)


class MMLT(Bidirectional):
    """lab_mmlt: lab_bdpt's strategies, one per mutation, picked by Markov chains whose state holds
    the path's length and strategy (Hachisuka et al. 2014). Surfaces only (scenes with media are
    left out); equivalent only to itself."""
    plugin_name = "lab_mmlt"
    PARAMETERS = declarations.LAB_MMLT
    OWN_PARAMETERS = ("heuristic", "beta") + CHAIN_PARAMETERS
    RENDERS_MEDIA = False
    SIMPLICITY = 4
    CONTINUES_PASSES = True

    def techniques(self):
        return CONNECTIONS

    @classmethod
    def unsupported(cls, traits) -> str:
        """lab_bdpt's refusals, and media: its chains' subpaths are surface ones, and its render
        refuses a scene with a medium rather than leave the medium out."""
        return cls.media_problem(traits) or super().unsupported(traits)

    @classmethod
    def applicability(cls, traits, params: dict) -> tuple[bool, str]:
        problem = cls.unsupported(traits)
        return (False, problem) if problem else (True, "")

    @classmethod
    def equivalence(cls, traits, params: dict) -> tuple[tuple, str]:
        return chain_equivalence(cls, traits, params)
