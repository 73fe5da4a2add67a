"""Metropolis light transport: ``lab_pssmlt`` (Kelemen et al. 2002), Markov chains in primary sample
space over lab_mis's path tracer, many chains in lock-step (one per lane).

``chain`` holds the chains (state, mutations, acceptance, expected-value weights, bootstrap and
start) and knows nothing of rendering, so a toy target can drive it (tests/plugins/test_pssmlt_chain.py);
``sampler`` hands a chain's primary samples to the path loop as an ``mi.Sampler``; ``integrator`` is
the driver and the plugin; ``estimator`` is what the planner knows without a variant; ``mmlt`` is
``lab_mmlt`` (Hachisuka et al. 2014): the same chains and driver over lab_bdpt's subpaths, one
strategy per mutation.
"""
