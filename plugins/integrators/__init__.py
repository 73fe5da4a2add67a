"""The lab's integrators.

Families: ``path`` (``lab_naive``, ``lab_nee``, ``lab_mis``: one path loop whose weights are the
estimators ``naive``, ``nee``, ``mis``), ``photon`` (``lab_photon``), ``bdpt`` (``lab_bdpt``) and
``vcm`` (``lab_vcm``, built on ``bdpt``). What they share is in ``common``. ``estimator``: the
estimators' base class (what an integrator knows about scenes and sample counts, ``Densities``)
and their registry, needing no Mitsuba variant.
"""
