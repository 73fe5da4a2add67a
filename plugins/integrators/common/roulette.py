"""Russian roulette: one survival rule for camera paths and photons.

A path whose throughput beta has fallen is continued with probability q and divided by q
when it survives, so its expectation is unchanged while dim paths stop early (Arvo & Kirk
1990; Veach 1997, sec. 10.4.1). The lab's one rule, for every path it traces, is

    q = min(max(beta) / max(beta_0) * eta^2, RR_MAX_SURVIVAL)

with beta_0 the throughput the path started with and eta the relative index of refraction
accumulated along it:

* camera paths (the path tracers, ``lab_photon``'s camera pass) start with beta_0 = 1 and
  carry radiance, whose BSDF weights include the 1/eta^2 scaling at refractive boundaries;
  multiplying by eta^2 undoes it, so a path inside glass is not culled for a throughput that
  will come back on the way out (as Mitsuba's ``path`` does);
* photons start with their emitted flux beta_0 = Phi_e / (P_e N) (``start``), and importance
  transport has no 1/eta^2 scaling to undo (``eta`` left out, as Mitsuba's ``ptracer`` does).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Survival probability cap: every path stops with probability >= 5% per bounce past
#: rr_depth, so even a closed box of albedo 1 terminates.
RR_MAX_SURVIVAL = 0.95


def survival_probability(beta, eta=None, start=None):
    """q = min(max(beta) / start * eta^2, RR_MAX_SURVIVAL), in [0, RR_MAX_SURVIVAL].

    ``start``: the largest channel of the path's starting throughput (None: 1, a camera
    path); ``eta``: the relative IOR along a radiance path (None: photons). NaN (0 * inf
    throughput) maps to 0, i.e. the path stops.
    """
    m = dr.max(mi.unpolarized_spectrum(beta))
    if start is not None:
        m = m / start
    if eta is not None:
        m = m * dr.square(eta)
    q = dr.minimum(m, RR_MAX_SURVIVAL)
    return dr.select(q > 0, q, 0.0)


def rr_scale(q):
    """1 / q for a surviving path; 0 where q = 0 (such a path never survives)."""
    return dr.select(q > 0, dr.rcp(q), 0.0)


def kept(probability, u):
    """(whether a sample kept with ``probability`` survives the uniform ``u``; the factor it then
    counts: 1 / probability, else 0), so that its expectation is unchanged."""
    taken = u < probability
    return taken, dr.select(taken, rr_scale(probability), 0.0)


def russian_roulette(beta, u, rr_active, eta=None, start=None):
    """(beta, survives) after Russian roulette with the uniform sample ``u``.

    Where ``rr_active`` (the path is at or past rr_depth): it survives with probability
    q = ``survival_probability(beta, eta, start)`` and beta is divided by q. Elsewhere beta
    is unchanged and the path survives. ``u`` is drawn by the caller on every bounce, so the
    sample dimensions do not depend on the path.
    """
    q = survival_probability(beta, eta, start)
    return dr.select(rr_active, beta * rr_scale(q), beta), ~rr_active | (u < q)

