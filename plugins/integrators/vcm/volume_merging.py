"""Volumetric merging: camera vertices in a medium merge with the light vertices stored in media
within a ball of radius r (point to point: the first estimator of Krivanek et al. 2014's
unified points, beams and paths; SmallUPBP's "point-point" / P-P3D).

**Estimate.** A light vertex y in a medium carries beta_y, its subpath's throughput on arrival
*including the collision there*: the free flight's weight at a collision holds sigma_s(y) (over
the flight's density, whose sigma_t,c is the vertex's g). The camera's throughput beta at its
medium vertex x holds sigma_s(x) likewise. The path's contribution has one scattering
coefficient at the merged vertex, so one of the two is divided out, the camera vertex's:

    L += beta / (sigma_s(x) r^3 N) * sum_y w_merge K3(|x - y| / r) p(x, wo, wi_y) beta_y

with p the phase function at x (its eval, no cosine), K3 a kernel over the unit ball
(``kernels.kernel``, dimension 3: 3 / (4 pi) constant, (15 / (8 pi)) (1 - t^2) Epanechnikov),
N the iteration's light subpaths. As r -> 0, y -> x and sigma_s(y) / sigma_s(x) -> 1.

**MIS** (Georgiev et al. 2012's recursion, as Krivanek et al. 2014 extend it). Merging at x_i
has density p_L(x_0 .. x_i) p_C(x_i .. x_k) eta_i, where eta_i is the probability, per unit of
p_L(x_i), that a light vertex lands in the merging region: pi r^2 N on a surface (p_L an area
density, g = |cos|) and (4/3) pi r_v^3 N in a medium (p_L a volume density, g = sigma_t,c: the
free flight's collision density, ``media_paths``), so the merge technique's density relative to
the connection that ends the light subpath at x_i is eta_i p_C(x_i) in both cases. The running
sums then change in one place: the merge term a vertex folds into ``dvc`` is its own eta_i
(``Recursion._eta_at``), and ``dvm``, kept in units of dvc / eta_surface, gains eta_i /
eta_surface there; a merge at a medium vertex divides its sums by eta_i / eta_surface
(``Recursion.merge``). The brute-force oracle (``weights.brute_force_weights`` with ``medium``)
checks the recursion on random paths (tests/plugins/test_bdpt_weights.py).

**Radius.** Its own schedule, r_v,i = r_v,1 i^((alpha - 1) / 3): the ball's volume shrinks as
i^(alpha - 1), as the disc's area does on surfaces (Knaus & Zwicker 2011's argument in three
dimensions), so the bias vanishes while the expected merges per camera vertex still grow. r_v,1
is ``radius_volume``, by default the surfaces' r_1 (a pixel's width at the first surfaces the
camera sees): a camera vertex in fog lies at distances like those surfaces', so a ball of that
radius blurs the medium's light over about a pixel, as the disc does on surfaces; the mean free
path (1 / sigma_t, 6.7 units in the volumetric caustic's fog) would blur over the whole scene.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitsuba_lab.plugins.integrators.common.subpath_media import phase_reverse_pdf
from mitsuba_lab.plugins.integrators.bdpt.vertices import RECORD, spectrum_at, vector

from .merging import VertexGrid


def volume_radius(r1: float, iteration: int, alpha: float) -> float:
    """r_i = r_1 i^((alpha - 1) / 3): the ball's volume shrinks as i^(alpha - 1)."""
    return r1 * iteration ** ((alpha - 1.0) / 3.0)


class MediumGrid(VertexGrid):
    """The light vertices stored in media, bucketed per iteration at its ball radii; ``merge``
    takes a camera vertex in a medium (``mei``, its ``phase`` function)."""
    DIMENSION = 3
    IN_MEDIUM = True

    def merge(self, cp, mei, phase, beta, mis, depth, iteration, active, u):
        return self.gather(cp, mei.p, (mei, phase), beta, mis, depth, iteration, active, u)

    def accepts(self, site, n_y):
        return True                       # (every vertex of this grid is a medium vertex)

    def evaluate(self, site, record, n_y, ok):
        mei, phase = site
        ctx = mi.PhaseFunctionContext(None, mi.TransportMode.Radiance)
        wi_world = vector(record, RECORD["wi"])
        f, pdf_fwd = phase.eval_pdf(ctx, mei, wi_world, ok)
        pdf_rev = phase_reverse_pdf(phase, ctx, mei, wi_world, ok)
        return mi.Spectrum(f) * spectrum_at(record, RECORD["beta"]), pdf_fwd, pdf_rev

    def finish(self, site, total):
        mei, _ = site
        sigma_s = mi.Spectrum(mei.sigma_s)
        return dr.select(sigma_s > 0, total / dr.maximum(sigma_s, 1e-30), 0.0)
