"""Full lock-step rounds recorded once and replayed with Dr.Jit's ``dr.freeze``.

A round of lab_mmlt's chains is about 50 kernels whose Python tracing (the BDPT subpath loops,
the lazy proposal, the acceptance) costs as much as the kernels themselves on a small image.
Every full round of a render traces the same code on arrays of the same sizes; only the step's
number and the arrays' contents change. ``FrozenRounds`` records a round the first time (in
practice twice per render: the second call finds some of the first call's literals changed) and
replays its kernels afterwards.
The step's number is an input array, so a replayed round draws the same random numbers as a
traced one: the images are the same (to the order of the splats' float atomics).

Everything a round reads must be an input of the frozen function: the chains' arrays
(``MarkovChains.STATE``) and ``captured``, the other Dr.Jit values that ``evaluate`` and ``splat``
read (the scene, the sensor, the film block, ...). A value read to Python during a round, or an
array left out of ``captured``, makes the recording fail, and the render with it (after the round
ran: it cannot be stepped again without splatting twice). lab_mmlt does not freeze scenes with a
projector, whose emission tables are not traversable.
"""
from __future__ import annotations

import gc

import drjit as dr

from . import chain


def _nothing(index):
    return index + 1


class _Holder:
    """Holds the chains out of dr.freeze's sight: a plain object is keyed by its identity, not
    traversed, so the chains' Python counters do not force a new recording every round."""

    def __init__(self, chains):
        self.chains = chains


class FrozenRounds:
    """``full_step`` for ``chain.run_mutations``: one full round of ``chains``, frozen."""

    def __init__(self, chains: chain.MarkovChains, evaluate, splat, captured: list, plugin: str):
        self.chains, self.evaluate, self.splat, self.plugin = chains, evaluate, splat, plugin
        holder = _Holder(chains)

        def body(state, index):
            held = holder.chains
            held.set_state(state)
            chain.step(held, evaluate, splat, index=index)
            return held.state()

        self._frozen = dr.freeze(body, state_fn=lambda *args: captured)
        # A recording keys on the kind of each input (a literal or an array in memory), and a round
        # turns the chains' zeros and the film block's and the scene's literals into arrays, so the
        # second round recorded anew. Made arrays first (a frozen no-op with auto_opaque off writes
        # them back into the objects it traverses), one recording serves every round.
        dr.make_opaque(chains.state())
        dr.freeze(_nothing, state_fn=lambda *args: captured, auto_opaque=False)(chains.step_index())

    @property
    def recordings(self) -> int:
        return self._frozen.n_recordings

    def __call__(self) -> None:
        chains = self.chains
        steps = chains.steps
        # (no cyclic garbage collection inside: one that frees arrays of earlier rounds or renders
        # while a round is recorded queues the release, which a recording cannot hold, and the
        # process aborts, as it did in a sweep on the Cornell box)
        collecting = gc.isenabled()
        gc.disable()
        try:
            chains.set_state(self._frozen(chains.state(), chains.step_index()))
        except RuntimeError as err:
            # (no fallback: a failed recording has run the round, splats included, so stepping it
            # again would splat it twice)
            raise RuntimeError(f"{self.plugin}: its lock-step round could not be frozen (a value it reads is "
                               f"not among the frozen function's inputs): set mlt.mmlt.FREEZE_ROUNDS = False "
                               f"to trace every round") from err
        finally:
            if collecting:
                gc.enable()
        chains.steps = steps + 1
