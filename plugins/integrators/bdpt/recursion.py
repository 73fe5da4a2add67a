"""Georgiev's recursion for the MIS weights of vertex connection and merging, as SmallVCM writes it.

A path x_0 .. x_k (x_0 on an emitter, x_k on the sensor) can be built by k + 1 strategies:
s light-subpath vertices x_0 .. x_{s-1} joined to t = k + 1 - s camera-subpath vertices
x_s .. x_k, s = 0 .. k (t = 0, a light subpath hitting the lens, is not a strategy here), and,
with merging, by merging a light and a camera vertex at any interior vertex x_i. The power
heuristic (exponent beta; beta = 1 is the balance heuristic) gives each technique the weight
p^beta / sum_j p_j^beta over the path's densities. Rather than summing them per connection, each
subpath carries three running quantities, updated per vertex in O(1) (Georgiev, "Implementing
Vertex Connection and Merging", 2012; SmallVCM's ``dVCM``, ``dVC``, ``dVM``):

* ``dvcm``: 1 / p^beta of the vertex's own density from its subpath (times, at the subpath's
  first vertex, the sample-count or emitter-sampling ratio that the next strategy carries);
* ``dvc``: the sum over the strategies that would build more of the path from the other side,
  up to the factors known only once the connection is made;
* ``dvm``: the same for the merges, relative to merging at the current vertex.

Merging at a vertex has density p_light(x_0 .. x_i) p_camera(x_i .. x_k) eta, eta = pi r^2
N_light (SmallVCM's ``mMisVmWeightFactor``; ``inv_eta`` its ``mMisVcWeightFactor``); without
merging eta = 0 and ``dvm`` is not carried. t = 1 (light tracing) counts ``light_paths`` light
subpaths per camera subpath (SmallVCM's light-subpath count).

Densities are named by measure: ``_A`` per unit area, ``_W`` per unit solid angle (SmallVCM's
``PdfA``, ``PdfW``); ``pdf_emit_W`` is an emitted ray's joint density, position times direction
(SmallVCM's ``emissionPdfW``). Delta vertices are exact: a strategy that would hit a delta
emitter, or connect at a delta-lobe vertex, has density 0 and drops out of every sum; so does
t = 1 when the sensor's direction is a delta (orthographic). A delta lobe's forward and reverse
probabilities are taken equal, so they cancel; delta densities are passed with the delta
stripped. Infinite emitters: the vertex at infinity is a direction; pass ``cos_light`` = 1 and
``dist2`` = 1 for the segment that touches it (densities there are in solid angle).

``Recursion`` is the textbook: every technique enabled, one sample of each, merging at every
interior vertex. Its hooks (the methods and attributes marked so) are where the lab's
extensions, in ``weights``, change a term; here they have Georgiev's values. Every function
works on numpy arrays (or floats) and on Dr.Jit arrays, element-wise, with arithmetic
operators, ``select`` and ``power``; this module imports no Mitsuba, Dr.Jit or numpy at load.
"""
from __future__ import annotations

from typing import NamedTuple

from .techniques import Technique


class SubpathMis(NamedTuple):
    """The MIS quantities a subpath carries at its current vertex (stored per light vertex);
    ``dvm`` only with merging. ``first``, ``merges`` and ``pending`` belong to the lab's
    extensions (``weights``): whether ``dvcm`` still comes from the subpath's start, and the
    caustic-merge rule's state."""
    dvcm: object
    dvc: object
    first: object
    dvm: object = 0.0
    #: light side, with ``caustic_merges``: 1.0 where merging at the current vertex is a technique
    merges: object = 1.0
    #: camera side, with ``caustic_merges``: the last vertex's merge term (in dvm's units), counted
    #: once the next vertex turns out to be a delta lobe
    pending: object = 0.0


def select(mask, a, b):
    """``mask ? a : b`` on numpy values or Dr.Jit arrays (Python bools select directly)."""
    if isinstance(mask, bool):
        return a if mask else b
    if type(mask).__module__.startswith("drjit"):
        import drjit as dr

        return dr.select(mask, a, b)
    import numpy as np

    return np.where(mask, a, b)


class Recursion:
    """The textbook weights for one exponent ``beta``, ``light_paths`` light subpaths per camera
    subpath, and merging when ``merging`` (``merge_area`` = pi r^2 N_light)."""
    #: hook: a connection technique's sample count, to the power beta (``weights``: fewer)
    connect_weight = 1.0

    def __init__(self, beta: float = 2.0, light_paths: float = 1.0, merging: bool = False,
                 merge_area: float = 0.0, merge_volume: float = 0.0):
        self.beta = float(beta)
        self.light_paths = float(light_paths)
        self.merging = merging
        # eta = pi r^2 N_light: merging at a vertex over connecting there (Georgiev 2012's eta_VCM);
        # the merge terms are left out entirely without merging (as if eta = 0)
        self.eta = self._m(float(merge_area)) if merging else 0.0
        self.inv_eta = self._m(1.0 / float(merge_area)) if merging else 0.0
        # at a medium vertex: 4/3 pi r_v^3 N_light, the ball's volume (Krivanek et al. 2014's point-point
        # estimator); 0: no medium vertex merges (``merge_volume`` unknown, scenes without media)
        self.eta_volume = self._m(float(merge_volume)) if merging else 0.0

    def _eta_at(self, medium):
        """eta of merging at a vertex: the ball's where ``medium`` (a mask; None: a surface vertex)."""
        if medium is None or not self.merging:
            return self.eta
        return select(medium, self.eta_volume, self.eta)

    def _volume_ratio(self, medium):
        """eta at the vertex over the surfaces' eta: ``dvm`` counts every term in units of
        ``dvc`` / (surface eta), so a merge at a medium vertex rescales its sums by this."""
        if medium is None or not self.merging:
            return 1.0
        return select(medium, self.eta_volume * self.inv_eta, 1.0)

    def _m(self, x):
        """x^beta (the heuristic applied to a density ratio)."""
        if self.beta == 1.0:
            return x
        if self.beta == 2.0:
            return x * x
        if type(x).__module__.startswith("drjit"):
            import drjit as dr

            return dr.power(x, self.beta)
        import numpy as np

        return np.power(x, self.beta)

    # -- hooks: Georgiev's terms, which the lab's extensions change (``weights``) ----------

    def _own(self, kind: Technique):
        """hook: a technique's own term in its weight's numerator."""
        return 1.0

    def _term(self, kind: Technique, x):
        """hook: ``x``, a term of technique ``kind`` in another technique's sum."""
        return x

    def _inner(self, state: SubpathMis, start_kind: Technique):
        """hook: ``state.dvcm``, the term of the strategy with one vertex more on the other side
        (``start_kind``: its kind while ``dvcm`` still comes from the subpath's start)."""
        return state.dvcm

    def _hit_inner(self, camera: SubpathMis, pdf_pos_A, pdf_direct_A, eq=1.0):
        """hook: the emitter hit's sum over the light side's strategies but connections: light
        tracing at the camera's first vertex, next-event estimation after it (``eq``: its factor
        1 + rho^beta, ``nee``)."""
        first = camera.first
        return (first * self._m(pdf_pos_A) + (1.0 - first) * self._m(pdf_direct_A) * eq) * camera.dvcm

    def start_merges(self):
        """hook: ``merges`` at a light subpath's first vertex."""
        return 1.0

    def _light_merges(self, light: SubpathMis):
        """hook: merging at a light vertex, as a factor."""
        return 1.0

    def _camera_merges(self, depth):
        """hook: merging at a camera vertex ``depth`` segments from the sensor, as a factor."""
        return 1.0

    def _joined_merges(self, depth):
        """hook: merging at a camera vertex that NEE or a connection joins to a light vertex."""
        return 1.0

    def _sensor_merges(self, light: SubpathMis):
        """hook: merging at a light vertex that light tracing joins to the sensor (the camera's
        first vertex)."""
        return 1.0

    def _pending_after_hit(self, pending, inv_cos):
        """hook: ``pending`` carried to a new vertex."""
        return pending

    # -- starting and extending subpaths ---------------------------------------------------

    def start_light(self, pdf_emit_W, pdf_direct_A, cos_light, delta=False) -> SubpathMis:
        """State at x_0 after sampling an emitted ray.

        ``pdf_emit_W``: joint density of the ray (position, area, times direction, solid angle;
        infinite emitter: direction times the position on its disc); ``pdf_direct_A``: density
        with which emitter sampling picks x_0 (solid angle for an infinite emitter), selection
        probability included in both; ``cos_light``: |cos| at x_0 of the emitted direction (1 for
        an infinite emitter); ``delta``: the emitter is a delta (point, spot, directional), so no
        camera subpath can hit it.
        """
        dvcm = self._m(pdf_direct_A / pdf_emit_W)
        dvc = select(delta, 0.0 * dvcm, self._term(Technique.HIT, self._m(cos_light / pdf_emit_W)))
        return SubpathMis(dvcm, dvc, 1.0, dvc * self.inv_eta, self.start_merges())

    def start_camera(self, pdf_cam_W, delta=False) -> SubpathMis:
        """State at the sensor after sampling a ray; ``pdf_cam_W``: the sensor's direction density
        of it (per unit film area, as the t = 1 strategy's splat uses it).

        ``delta``: the sensor's direction is a delta given its sampled position (orthographic:
        the film point is the sampled quantity, the direction follows). No light vertex can then
        be joined to the sensor, so t = 1 has density 0 relative to every other strategy, as a
        connection at a delta lobe has: ``dvcm``, the t = 1 term that the camera side carries
        into every other strategy's sum, starts at 0 (``pdf_cam_W`` then only gives its shape)."""
        dvcm = select(delta, 0.0 * pdf_cam_W, self._m(self.light_paths / pdf_cam_W))
        return SubpathMis(dvcm, 0.0 * pdf_cam_W, 1.0, 0.0 * pdf_cam_W)

    def after_hit(self, state: SubpathMis, dist2, cos_in, transmittance=None, forward=None,
                  backward=None) -> SubpathMis:
        """State at a new vertex: ``dist2`` the squared segment length, ``cos_in`` |cos| at the new
        vertex (both 1 on a segment to or from an infinite emitter).

        In participating media (``transmittance`` given) the new vertex's forward density is
        p_W g T / d^2: ``cos_in`` is then g, |cos| at a surface vertex and sigma_t at a medium
        vertex (the density of a collision there per unit length), and ``transmittance`` T the
        probability with which the sampling passed the segment (the free flights' escape
        probabilities, and a mask's null-lobe probability, in the path's sampling channel). T
        enters ``dvcm`` (1 / p_A) only: ``dvc`` and ``dvm`` hold ratios of a vertex's reverse
        density to the next vertex's forward density, which cross the same segment and share
        its T (it cancels); the T of a connection's own segment is passed with its cosines.

        Where the two directions sample the segment with different distance densities (lab_bdpt's
        camera subpaths mix in equi-angular sampling, ``camera_flight``), ``forward`` is the
        factor by which this subpath's distance density of the new vertex exceeds g T, and
        ``backward`` the factor of the other direction's density of the previous vertex over the
        segment: the new vertex's p_A gains ``forward``, the previous vertex's reverse density
        ``backward``, so ``dvc`` and ``dvm`` (their ratio) gain backward / forward."""
        inv_cos = self._m(1.0 / cos_in)
        pending = self._pending_after_hit(state.pending, inv_cos)
        dvcm = state.dvcm * self._m(dist2) * inv_cos
        if transmittance is not None:
            dvcm = dvcm * self._m(1.0 / transmittance)
        dvc, dvm = state.dvc * inv_cos, state.dvm * inv_cos
        if forward is not None or backward is not None:
            ratio = self._m((1.0 if backward is None else backward) / (1.0 if forward is None else forward))
            if forward is not None:
                dvcm = dvcm * self._m(1.0 / forward)
            dvc, dvm, pending = dvc * ratio, dvm * ratio, pending * ratio
        return SubpathMis(dvcm, dvc, state.first, dvm, state.merges, pending)

    # -- equi-angular NEE (``camera_flight``): a second s = 1 technique --------------------
    # It builds x_1 on the camera's side by equi-angular sampling along the segment from x_2
    # (not by the subpath's own flight), with rho = p_E(x_1) / p_camera(x_1) times s = 1's
    # density; every sum that holds s = 1's term holds it times 1 + rho^beta (``nee``, ``hit``,
    # ``connect`` and ``light_to_camera`` at a light subpath's first vertex, and deeper on the
    # light side ``equiangular_term`` and ``add_equiangular``). rho = 0: the textbook weights.
    def _eq(self, rho):
        return 1.0 if rho is None else 1.0 + self._m(rho)

    def equiangular_term(self, state: SubpathMis, pdf_fwd_W, cos_out, delta=False) -> SubpathMis:
        """The part of ``scatter_light``'s new ``dvc`` and ``dvm`` that is s = 1's term, at a
        light subpath's first vertex (``state``: after ``after_hit`` there; none at a delta lobe):
        carried to the next vertex (``after_hit`` it as the state), where rho is known
        (``add_equiangular``)."""
        inner = self._m(cos_out / pdf_fwd_W) * self._inner(state, Technique.NEE)
        inner = select(delta, 0.0 * inner, inner)
        return SubpathMis(0.0 * inner, inner, state.first, inner * self.inv_eta)

    def add_equiangular(self, state: SubpathMis, carried: SubpathMis, rho) -> SubpathMis:
        """``state`` at a light subpath's second vertex with s = 1's term, ``carried`` (after
        ``after_hit``), counted 1 + rho^beta times."""
        extra = self._m(rho)
        return state._replace(dvc=state.dvc + extra * carried.dvc, dvm=state.dvm + extra * carried.dvm)

    def _scatter(self, state, pdf_fwd_W, pdf_rev_W, cos_out, delta, start_kind, merges=1.0, medium=None):
        """Shared by both sides; only the kind of the subpath's first ratio differs (``merges``:
        merging at this vertex, as a factor; ``medium``: where this vertex is a medium vertex)."""
        ratio, rev, inner = self._m(cos_out / pdf_fwd_W), self._m(pdf_rev_W), self._inner(state, start_kind)
        merges = merges * self._volume_ratio(medium)                    # (in units of the surfaces' eta)
        folded = ratio * (state.dvc * rev + inner + self.eta * merges)   # eta: merging at this vertex
        cos_m = self._m(cos_out)
        dvc = select(delta, state.dvc * cos_m, folded)          # (a delta lobe passes dvc, dvm on)
        dvcm = select(delta, 0.0 * folded, self._m(1.0 / pdf_fwd_W))
        dvm = state.dvm
        if self.merging:
            folded_vm = ratio * (state.dvm * rev + inner * self.inv_eta + merges)
            dvm = select(delta, state.dvm * cos_m, folded_vm)
        return SubpathMis(dvcm, dvc, 0.0 * state.first, dvm, 1.0, 0.0)

    def scatter_light(self, state, pdf_fwd_W, pdf_rev_W, cos_out, delta=False, medium=None) -> SubpathMis:
        """State after sampling the next direction at a light-subpath vertex: ``pdf_fwd_W`` the
        sampled direction's density (adjoint BSDF), ``pdf_rev_W`` the density of sampling the
        reverse (towards the previous vertex, coming from the new direction), ``cos_out`` |cos|
        of the new direction at this vertex, ``delta`` a delta lobe sampled; ``medium``: a
        medium vertex (phase function; cos_out is then sigma_t), whose merge counts the ball."""
        return self._scatter(state, pdf_fwd_W, pdf_rev_W, cos_out, delta, Technique.NEE, self._light_merges(state),
                             medium)

    def scatter_camera(self, state, pdf_fwd_W, pdf_rev_W, cos_out, delta=False, depth=None,
                       medium=None) -> SubpathMis:
        """``scatter_light`` for a camera-subpath vertex ``depth`` segments from the sensor."""
        return self._scatter(state, pdf_fwd_W, pdf_rev_W, cos_out, delta, Technique.LIGHT, self._camera_merges(depth),
                             medium)

    # -- the weights of each technique ------------------------------------------------------

    def hit(self, camera: SubpathMis, pdf_direct_A, pdf_emit_W, pdf_pos_A, rho=None):
        """s = 0: the camera subpath (state after ``after_hit`` at the emitter) hit a non-delta
        emitter. ``pdf_direct_A``, ``pdf_emit_W`` as in ``start_light`` for this point and the ray
        back along the segment; ``pdf_pos_A``: the emission position density of the point (used
        when the emitter is the first camera vertex, where the competitor is light tracing); ``rho``:
        equi-angular NEE's at the camera's vertex before the emitter)."""
        w_camera = self._hit_inner(camera, pdf_pos_A, pdf_direct_A, self._eq(rho)) + self._m(pdf_emit_W) * camera.dvc
        return self._own(Technique.HIT) / (1.0 + w_camera)

    def nee(self, camera: SubpathMis, pdf_direct_A, pdf_emit_W, cos_light, cos_cam, dist2,
            pdf_cam_fwd_W, pdf_cam_rev_W, delta=False, depth=None, medium=None, rho=None):
        """s = 1, t >= 2: emitter sampling at a camera vertex. ``cos_light``, ``cos_cam``: |cos|
        at the emitter point and at the camera vertex along the segment, ``dist2`` its squared
        length (1, 1 for an infinite emitter); ``pdf_cam_fwd_W``: BSDF density at the camera
        vertex of the direction to the emitter, ``pdf_cam_rev_W``: of the direction back along
        the camera subpath given the emitter's; ``delta``: delta emitter (it cannot be hit);
        ``depth``: the camera vertex's, in segments from the sensor; ``medium``: a medium vertex;
        ``rho``: equi-angular NEE's there (its weight: this one times rho^beta)."""
        p_cam0 = pdf_cam_fwd_W * cos_light / dist2
        w_light = select(delta, 0.0 * p_cam0, self._term(Technique.HIT, self._m(p_cam0 / pdf_direct_A)))
        inner = (self._eta_at(medium) * self._joined_merges(depth) + self._inner(camera, Technique.LIGHT)
                 + camera.dvc * self._m(pdf_cam_rev_W))
        w_camera = self._m(pdf_emit_W * cos_cam / (dist2 * pdf_direct_A)) * inner
        return self._own(Technique.NEE) / (w_light + self._eq(rho) + w_camera)

    def connect(self, light: SubpathMis, camera: SubpathMis, pdf_light_fwd_W, pdf_light_rev_W,
                pdf_cam_fwd_W, pdf_cam_rev_W, cos_light, cos_cam, dist2, depth=None, light_medium=None,
                camera_medium=None, rho=None):
        """s >= 2, t >= 2: a connection between a light vertex and a camera vertex (neither a
        delta lobe). ``pdf_light_fwd_W``: density at the light vertex of the direction to the
        camera vertex, ``pdf_light_rev_W``: of the direction back along the light subpath given
        that one; ``pdf_cam_*`` likewise; ``cos_*``: |cos| at each end; ``dist2``; ``depth``:
        the camera vertex's, in segments from the sensor; ``*_medium``: each end a medium vertex."""
        w_light = self._m(pdf_cam_fwd_W * cos_light / dist2) * (
            self._eta_at(light_medium) * self._light_merges(light) + self._inner(light, Technique.NEE) * self._eq(rho)
            + light.dvc * self._m(pdf_light_rev_W))
        w_camera = self._m(pdf_light_fwd_W * cos_cam / dist2) * (
            self._eta_at(camera_medium) * self._joined_merges(depth) + self._inner(camera, Technique.LIGHT)
            + camera.dvc * self._m(pdf_cam_rev_W))
        if not self._own(Technique.CONNECT):
            return 0.0 * w_light
        # (this technique's term is its count n_c^beta, as each term of the sums carries its own)
        return self.connect_weight / (w_light + self.connect_weight + w_camera)

    def light_to_camera(self, light: SubpathMis, pdf_cam_W, cos_light, dist2, pdf_light_rev_W, medium=None,
                        rho=None):
        """t = 1, s >= 2: a light vertex (not a delta lobe) joined to the sensor. ``pdf_cam_W``:
        the sensor's direction density towards it (as in ``start_camera``), ``cos_light`` |cos|
        at the light vertex, ``pdf_light_rev_W``: density at the light vertex of the direction
        back along the light subpath given the sensor's. (The light vertex is the camera's
        first; ``medium``: a medium vertex.)"""
        w_light = self._m(pdf_cam_W * cos_light / (dist2 * self.light_paths)) * (
            self._eta_at(medium) * self._sensor_merges(light) + self._inner(light, Technique.NEE) * self._eq(rho)
            + light.dvc * self._m(pdf_light_rev_W))
        return self._own(Technique.LIGHT) / (1.0 + w_light)

    def emitter_to_camera(self, pdf_cam_W, cos_light, dist2, pdf_pos_A, delta=False):
        """t = 1, s = 1: an emitted point joined to the sensor directly (``pdf_pos_A``: its
        emission position density; infinite emitter: its direction density, with cos_light =
        dist2 = 1)."""
        ratio = pdf_cam_W * cos_light / (dist2 * self.light_paths * pdf_pos_A)
        w_light = select(delta, 0.0 * ratio, self._term(Technique.HIT, self._m(ratio)))
        return self._own(Technique.LIGHT) / (1.0 + w_light)

    def merge_bound(self, camera: SubpathMis, medium=None):
        """An upper bound on ``merge`` at a camera vertex, whatever light vertex it merges with:
        its weight without the terms that depend on the light vertex (all of them >= 0)."""
        return self._own(Technique.MERGE) / (
            1.0 + self._inner(camera, Technique.LIGHT) * self.inv_eta / self._volume_ratio(medium))

    def merge(self, light: SubpathMis, camera: SubpathMis, pdf_cam_fwd_W, pdf_cam_rev_W, medium=None):
        """Merging a light vertex with a camera vertex at (about) the same point x_i, neither a
        delta lobe (``light`` and ``camera``: their states after ``after_hit``). The camera
        vertex's BSDF (phase function at a medium vertex, ``medium``) stands for both:
        ``pdf_cam_fwd_W`` its density of the light vertex's incoming direction (towards x_{i-1})
        given the camera's, ``pdf_cam_rev_W`` the reverse. Every other technique's term is
        relative to the surfaces' eta in ``dvm``; a merge in a ball divides them by its own."""
        w_light = self._inner(light, Technique.NEE) * self.inv_eta + light.dvm * self._m(pdf_cam_fwd_W)
        w_camera = self._inner(camera, Technique.LIGHT) * self.inv_eta + camera.dvm * self._m(pdf_cam_rev_W)
        return self._own(Technique.MERGE) / ((w_light + w_camera) / self._volume_ratio(medium) + 1.0)
