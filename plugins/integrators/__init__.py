"""The lab's integrators, and the pieces of light transport they share.

Plugins: ``path`` (``lab_naive``, ``lab_nee``, ``lab_mis``: one path loop), ``photon``
(``lab_photon``) and ``bdpt`` (``lab_bdpt``). Estimators, which need no Mitsuba variant:
``estimator`` (the base class: what an integrator knows about scenes and sample counts,
``Densities``), ``naive``, ``nee``, ``mis`` (the path tracers' weights), ``photon.estimator``,
``bdpt.estimator``. Shared pieces: ``mis_weight`` (the MIS heuristics, on Dr.Jit or numpy
arrays), ``direct`` (emitter sampling and emitter hits with the densities of both techniques),
``roulette`` (Russian roulette), ``counters`` (ray counts), ``spawn`` (ray offsets), ``spectral``
(spectral variants: one set of wavelengths per pass for light and camera paths).
"""
