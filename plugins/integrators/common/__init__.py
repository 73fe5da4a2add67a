"""The pieces of light transport that several integrator families use.

The families (``path.py`` with ``naive``, ``nee``, ``mis``; ``photon``; ``bdpt``; ``vcm``) import
these, never each other's insides (``vcm`` builds on ``bdpt`` as a whole):

* ``adjoint``: light carried from the emitters, with Veach's shading-normal correction;
* ``grid`` and ``kernels``: the hashed grid (counting sort) and the density-estimation kernels
  of photon mapping and merging; ``footprint``: the automatic radius (a pixel's width);
* ``spectral``: one set of wavelengths per pass for light and camera paths;
* ``direct``: emitter sampling and emitter hits with the densities of both techniques;
* ``mis_weight``: the MIS heuristics (no Mitsuba variant needed); ``roulette``: Russian
  roulette; ``spawn``: scale-robust ray offsets; ``counters``: ray counts;
* ``aim``: area lights' directions aimed at chosen shapes; ``support``: what every plugin's
  render does (Ctrl-C, unsupported-scene warnings, ``render``'s arguments).
"""
