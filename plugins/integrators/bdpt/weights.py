"""MIS weights of bidirectional path tracing over all (s, t) strategies, in O(1) per connection.

A path x_0 .. x_k (x_0 on an emitter, x_k on the sensor) can be built by k + 1 strategies:
s light-subpath vertices x_0 .. x_{s-1} joined to t = k + 1 - s camera-subpath vertices
x_s .. x_k, s = 0 .. k (t = 0, a light subpath hitting the lens, is not a strategy here). Each
strategy is one of four kinds:

* ``hit``: s = 0, the camera subpath hits the emitter;
* ``nee``: s = 1 and t >= 2, emitter sampling (next-event estimation);
* ``light``: t = 1, a light vertex joined to the sensor (light tracing; s = 1 is an emitter
  point seen directly);
* ``connect``: s >= 2 and t >= 2, a connection between two subpath vertices.

The power heuristic (exponent beta; beta = 1 is the balance heuristic) gives strategy s the
weight p_s^beta / sum_j p_j^beta, p_j being the area-measure density of the whole path under
strategy j (the light-tracing kind's density times ``light_paths``, its sample count relative
to camera subpaths). Rather than summing k + 1 products per connection, each subpath carries two
running quantities and a flag (Georgiev, "Implementing Vertex Connection and Merging", 2012, with merging
off; SmallVCM's ``dVCM`` and ``dVC``), updated per vertex in O(1):

* ``dvcm``: 1 / p^beta of the vertex's own density from its subpath (times, at the subpath's
  first vertex, the sample-count or emitter-sampling ratio that the next strategy carries);
* ``dvc``: the sum over the strategies that would build more of the path from the other side,
  up to the factors that are known only once the connection is made;
* ``first``: 1.0 while ``dvcm`` still comes from the subpath's start, else 0.0 (it tells which
  kind the innermost ratio belongs to, so a ``strategies`` subset can switch it off).

Delta vertices are exact: a strategy that would join a delta emitter's point by a camera hit, or
that would connect at a delta-lobe vertex, has density 0 and drops out of every sum; so does
t = 1 when the sensor's direction is a delta (orthographic: ``start_camera``). A delta
lobe's forward and reverse selection probabilities are taken equal (Fresnel reflection and
transmission are reciprocal), so they cancel. Delta densities are passed with the delta
stripped (e.g. a point light's position density is its selection probability), the same way on
every call. Infinite emitters: the vertex at infinity is a direction; pass ``cos_light`` = 1 and
``dist2`` = 1 for the segment that touches it (densities there are in solid angle).

``strategies`` restricts the sums to a subset of kinds (``techniques.Technique`` flags, e.g.
``LIGHT``, light tracing alone, or ``HIT | NEE``, which is unidirectional path tracing with MIS). Disabled kinds get weight
0 and leave the sums, so the enabled ones still sum to 1 over any path they can build: the
subset is unbiased for the light it can reach. The flags are folded into the running sums as the
kinds become known: a ratio's kind depends only on whether it is its subpath's first one
(light side: nee, camera side: light tracing) or not (connect); only the emitter hit needs the
nee flag for a ratio the camera subpath carries, which ``first`` tells apart.

**Merging** (vertex merging, for lab_vcm; Georgiev, Krivanek, Davidovic & Slusallek 2012):
with ``merge`` among the strategies and ``merge_area`` = eta = pi r^2 N_light, merging a light
vertex with a camera vertex at an interior path vertex x_i is one more technique, of density
p_light(x_0 .. x_i) p_camera(x_i .. x_k) eta. Each subpath then carries a third quantity,
``dvm`` (SmallVCM's ``dVM``: the techniques with fewer vertices on its side, relative to
merging at its current vertex), every connection's sums gain eta (merging at the vertices it
joins), and ``merge`` gives the merging weight. Without ``merge`` nothing changes.
``caustic_merges`` makes merging at x_i a technique only where x_{i-1}, the vertex before it on
the light's side, is an interior delta-lobe vertex (the light vertex arrived through a specular
bounce: Jensen's caustic photons). The rule is a property of the path, so the weights of the
techniques left still sum to 1; a light subpath knows it at each vertex (``merges``, from its
last lobe), a camera subpath only once it reaches x_{i-1}, so its merge term waits in
``pending`` until then.
``merge_from`` = 2 leaves merging out at the camera's first vertex (one segment from the
sensor), as a technique and from every other technique's sums: the camera-side calls
(``scatter_camera``, ``nee``, ``connect``) take the camera vertex's ``depth``, and
``light_to_camera``'s light vertex is the camera's first.

Every function works on numpy arrays (or floats) and on Dr.Jit arrays, element-wise; it uses
arithmetic operators, ``select`` and ``power``, and imports no Mitsuba, Dr.Jit or numpy at load.
"""
from __future__ import annotations

from typing import NamedTuple

from .techniques import (CONNECTIONS, NAMES, ORDER, PRESETS, Strategy, Technique, parse_techniques,
                         techniques_of)

#: The names of lab_bdpt's techniques, as users write them.
KINDS = tuple(NAMES[kind] for kind in ORDER if kind in CONNECTIONS)


def iteration_sizes(lanes: int, iterations: int) -> list[int]:
    """How many of ``lanes`` lanes each iteration holds: lane i belongs to iteration i mod K
    (``BdptWeights.lane_iteration``)."""
    size, rest = divmod(lanes, iterations)
    return [size + (k < rest) for k in range(iterations)]


class SubpathMis(NamedTuple):
    """The MIS quantities a subpath carries at its current vertex (store them per light vertex);
    ``dvm`` only with merging (SmallVCM's ``dVM``: the sum over the techniques with fewer
    vertices on this side, relative to merging at the current vertex)."""
    dvcm: object
    dvc: object
    first: object
    dvm: object = 0.0
    #: light side, with ``caustic_merges``: 1.0 where merging at the current vertex is a technique
    merges: object = 1.0
    #: camera side, with ``caustic_merges``: the last vertex's merge term (in dvm's units), counted
    #: once the next vertex turns out to be a delta lobe
    pending: object = 0.0


def _select(mask, a, b):
    """``mask ? a : b`` on numpy values or Dr.Jit arrays (Python bools select directly)."""
    if isinstance(mask, bool):
        return a if mask else b
    if type(mask).__module__.startswith("drjit"):
        import drjit as dr

        return dr.select(mask, a, b)
    import numpy as np

    return np.where(mask, a, b)


def _gate(flag, x):
    """flag * x, and exactly 0 where flag is 0 even if x is inf or NaN there (a density only a
    disabled strategy needs may be unusable, and must not spoil the enabled ones' weights)."""
    if isinstance(flag, (int, float)):
        return flag * x if flag else 0.0
    return _select(flag != 0, flag * x, 0.0 * flag)


def strategy_kind(s: int, t: int) -> str:
    """The name of strategy (s, t)'s kind (see the module docstring)."""
    return NAMES[Strategy(s, t).technique]


class BdptWeights:
    """The recursive MIS weights for one heuristic, one exponent and one set of strategies.

    ``heuristic``: ``balance`` or ``power`` (exponent ``beta``); ``strategies``: ``Technique``
    flags, or what users write (a preset name, ``all``, ``camera`` = hit + nee, ``light``, or
    kinds joined by '+'; or an iterable of kind names), parsed once here; ``light_paths``: the
    number of light subpaths each camera subpath competes with in the t = 1 strategy (SmallVCM's
    light-subpath count: light tracing splats one light subpath into many pixels);
    ``connect_count``: each connection technique's sample count per camera vertex, in (0, 1]
    (lab_vcm's ``connections = one``: a camera vertex connects to one light vertex of its
    subpath, picked uniformly, so a technique with s >= 2, t >= 2 is sampled about once per
    L light vertices; the weights use 1 / L, L the mean stored vertices per light subpath).
    Any counts > 0 give weights that sum to 1, so the estimate is unbiased whatever the count;
    the closer it is to the true sampling rate, the lower the variance. ``caustic_merges``:
    merging only after a delta lobe on the light's side (the module docstring).
    """

    def __init__(self, heuristic: str = "power", beta: float = 2.0, strategies="all",
                 light_paths: float = 1.0, merge_area: float = 0.0, merge_from: int = 1,
                 connect_count: float = 1.0, caustic_merges: bool = False):
        if heuristic not in ("balance", "power"):
            raise ValueError(f"lab_bdpt: heuristic must be 'balance' or 'power', got '{heuristic}'")
        if heuristic == "power" and not beta > 0:
            raise ValueError(f"lab_bdpt: the power heuristic's exponent beta must be > 0, got {beta}")
        if not light_paths > 0:
            raise ValueError(f"lab_bdpt: light_paths must be > 0, got {light_paths}")
        if not 0 < connect_count <= 1:
            raise ValueError(f"lab_vcm: connect_count must be in (0, 1], got {connect_count}")
        if isinstance(strategies, Technique):
            kinds = strategies
        else:
            kinds = parse_techniques(strategies) if isinstance(strategies, str) else techniques_of(strategies)
        if not kinds:
            raise ValueError(f"lab_bdpt: strategies must be one of {', '.join(PRESETS)} or a non-empty "
                             f"subset of {', '.join(NAMES.values())}, got {strategies!r}")
        if Technique.MERGE in kinds and not merge_area > 0:
            raise ValueError(f"lab_vcm: merging needs merge_area = pi r^2 N_light > 0, got {merge_area}")
        # (a light subpath's sums hold merges at its vertices before it knows how far from the
        # sensor they will lie; only the camera's first vertex is always known to be one)
        if merge_from not in (1, 2):
            raise ValueError(f"lab_vcm: merge_from must be 1 (every camera vertex merges) or 2 (all but the "
                             f"first), got {merge_from!r}")
        self.beta = 1.0 if heuristic == "balance" else float(beta)
        #: the enabled techniques
        self.techniques = kinds
        self.light_paths = float(light_paths)
        #: each technique's enable factor, 1.0 or 0.0
        self.e = {kind: 1.0 if kind in kinds else 0.0 for kind in ORDER}
        # eta = pi r^2 N_light: merging at a vertex over connecting there (Georgiev 2012's eta_VCM);
        # the merge terms are left out entirely without merging (as if eta = 0)
        self.merging = Technique.MERGE in kinds
        self.eta = self._m(float(merge_area)) if self.merging else 0.0
        self.inv_eta = self._m(1.0 / float(merge_area)) if self.merging else 0.0
        self.merge_from = merge_from
        self.caustic = bool(caustic_merges) and self.merging
        # a camera vertex's own merge where its light-side neighbour is an emitter or a light
        # vertex joined to it (NEE, connections): never a technique under caustic_merges
        self.eta_joined = 0.0 if self.caustic else 1.0
        # a connection technique's sample count, to the power beta (its kind's enable factor)
        self.connect_weight = self.e[Technique.CONNECT] * self._m(float(connect_count))

    @property
    def enabled(self) -> frozenset[str]:
        """The names of the enabled techniques (as users write them)."""
        return frozenset(NAMES[kind] for kind in ORDER if kind in self.techniques)

    #: lab_vcm: (eta table, 1 / eta table, iterations), one entry per iteration of a pass, each
    #: to the power beta (Dr.Jit arrays; see ``at_lanes``); None: ``eta`` holds for every lane.
    lane_tables = None

    def at_lanes(self, lane):
        """These weights for the lanes ``lane`` (Dr.Jit UInt32) of a pass: with ``lane_tables``,
        lane i merges in iteration i mod iterations and takes that iteration's eta (lab_vcm
        runs several iterations, each with its own radius, in one pass); else ``self``."""
        if self.lane_tables is None:
            return self
        import copy

        import drjit as dr

        eta, inv_eta, _ = self.lane_tables
        k = self.lane_iteration(lane)
        lanes = copy.copy(self)
        lanes.eta, lanes.inv_eta = dr.gather(type(eta), eta, k), dr.gather(type(inv_eta), inv_eta, k)
        lanes.lane_tables = None
        return lanes

    def lane_iteration(self, lane):
        """The iteration of the pass that lanes ``lane`` belong to (0 without ``lane_tables``):
        lane i is in iteration i mod K (``iteration_sizes``). A camera pass lays out a pixel's K
        samples in K neighbouring lanes, so each of them merges with another iteration's light
        vertices; blocks of 64 lanes per iteration, which kept a SIMD packet in one iteration's
        cells, gave all of a pixel's samples in a pass the same light vertices: 1.3x to 2.3x the
        merging variance on sds, for merges up to 20% cheaper."""
        return 0 if self.lane_tables is None else lane % self.lane_tables[2]

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

    def _flag(self, state: SubpathMis, start_kind: Technique):
        """Enable factor of the innermost ratio ``state.dvcm`` stands for."""
        return state.first * self.e[start_kind] + (1.0 - state.first) * self.connect_weight

    def _gated(self, state: SubpathMis, start_kind: Technique):
        """``state.dvcm`` times its enable factor (0 for a disabled kind, whatever dvcm is)."""
        return _gate(self._flag(state, start_kind), state.dvcm)

    def merges_at(self, depth):
        """Whether a camera vertex ``depth`` segments from the sensor merges (``merge_from``)."""
        return depth >= self.merge_from

    def _merges(self, depth):
        """``merges_at`` as a factor, 1.0 or 0.0; ``depth`` None: every camera vertex merges."""
        if depth is None or self.merge_from <= 1 or not self.merging:
            return 1.0
        return _select(self.merges_at(depth), 1.0, 0.0)

    # -- starting and extending subpaths ---------------------------------------------------

    def start_light(self, pdf_emit, pdf_nee, cos_light, delta=False) -> SubpathMis:
        """State at x_0 after sampling an emitted ray.

        ``pdf_emit``: joint density of the ray (position, area, times direction, solid angle;
        infinite emitter: direction times the position on its disc); ``pdf_nee``: density with
        which emitter sampling picks x_0 (area; solid angle for an infinite emitter), selection
        probability included in both; ``cos_light``: |cos| at x_0 of the emitted direction (1 for
        an infinite emitter); ``delta``: the emitter is a delta (point, spot, directional), so no
        camera subpath can hit it.
        """
        dvcm = self._m(pdf_nee / pdf_emit)
        dvc = _select(delta, 0.0 * dvcm, _gate(self.e[Technique.HIT], self._m(cos_light / pdf_emit)))
        return SubpathMis(dvcm, dvc, 1.0, dvc * self.inv_eta, self.start_merges())

    def start_camera(self, pdf_cam, delta=False) -> SubpathMis:
        """State at the sensor after sampling a ray; ``pdf_cam``: the sensor's direction density
        of it (solid angle, per unit film area as the t = 1 strategy's splat uses it).

        ``delta``: the sensor's direction is a delta given its sampled position (orthographic:
        the film point is the sampled quantity, the direction follows). No light vertex can then
        be joined to the sensor, so t = 1 has density 0 relative to every other strategy, as a
        connection at a delta lobe has: ``dvcm``, the t = 1 term that the camera side carries
        into every other strategy's sum, starts at 0 (``pdf_cam`` then only gives its shape)."""
        dvcm = _select(delta, 0.0 * pdf_cam, self._m(self.light_paths / pdf_cam))
        return SubpathMis(dvcm, 0.0 * pdf_cam, 1.0, 0.0 * pdf_cam)

    def after_hit(self, state: SubpathMis, dist2, cos_in) -> SubpathMis:
        """State at a new vertex: ``dist2`` the squared segment length, ``cos_in`` |cos| at the new
        vertex (both 1 on a segment to or from an infinite emitter)."""
        inv_cos = self._m(1.0 / cos_in)
        pending = state.pending * inv_cos if self.caustic else state.pending
        return SubpathMis(state.dvcm * self._m(dist2) * inv_cos, state.dvc * inv_cos, state.first,
                          state.dvm * inv_cos, state.merges, pending)

    def _scatter(self, state, pdf_fwd, pdf_rev, cos_out, delta, start_kind, merges=1.0, hold=False):
        """Shared by both sides; only the kind of the subpath's first ratio differs (``merges``:
        0.0 where this vertex does not merge; ``hold``: its merge term goes to ``pending``, and
        the one pending from the last vertex counts if this vertex is a delta lobe)."""
        ratio, rev, inner = self._m(cos_out / pdf_fwd), self._m(pdf_rev), self._gated(state, start_kind)
        now = 0.0 if hold else merges
        folded = ratio * (state.dvc * rev + inner + self.eta * now)   # eta: merging at this vertex
        through_vc, through_vm = state.dvc, state.dvm           # (a delta lobe passes these on)
        if hold:
            through_vc, through_vm = state.dvc + self.eta * state.pending, state.dvm + state.pending
        cos_m = self._m(cos_out)
        dvc = _select(delta, through_vc * cos_m, folded)
        dvcm = _select(delta, 0.0 * folded, self._m(1.0 / pdf_fwd))
        dvm = state.dvm
        if self.merging:
            folded_vm = ratio * (state.dvm * rev + inner * self.inv_eta + now)
            dvm = _select(delta, through_vm * cos_m, folded_vm)
        pending = _select(delta, 0.0 * folded, ratio * merges) if hold else 0.0
        return SubpathMis(dvcm, dvc, 0.0 * state.first, dvm, 1.0, pending)

    def scatter_light(self, state, pdf_fwd, pdf_rev, cos_out, delta=False) -> SubpathMis:
        """State after sampling the next direction at a light-subpath vertex: ``pdf_fwd`` the
        sampled direction's solid-angle density (adjoint BSDF), ``pdf_rev`` the density of
        sampling the reverse (towards the previous vertex, coming from the new direction),
        ``cos_out`` |cos| of the new direction at this vertex, ``delta`` a delta lobe sampled.
        With ``caustic_merges`` the new state's ``merges`` (for the next vertex) is ``delta``."""
        out = self._scatter(state, pdf_fwd, pdf_rev, cos_out, delta, Technique.NEE, state.merges)
        if self.caustic:
            out = out._replace(merges=_select(delta, 1.0, 0.0))
        return out

    def start_merges(self):
        """``merges`` at a light subpath's first vertex after the emitter (0.0 under
        ``caustic_merges``: the emitter is no delta lobe)."""
        return 0.0 if self.caustic else 1.0

    def scatter_camera(self, state, pdf_fwd, pdf_rev, cos_out, delta=False, depth=None) -> SubpathMis:
        """``scatter_light`` for a camera-subpath vertex ``depth`` segments from the sensor."""
        return self._scatter(state, pdf_fwd, pdf_rev, cos_out, delta, Technique.LIGHT, self._merges(depth), self.caustic)

    # -- the weights of the four kinds -----------------------------------------------------

    def hit(self, camera: SubpathMis, pdf_nee, pdf_emit, pdf_pos):
        """s = 0: the camera subpath (state after ``after_hit`` at the emitter) hit a non-delta
        emitter. ``pdf_nee``, ``pdf_emit`` as in ``start_light`` for this point and the ray back
        along the segment; ``pdf_pos``: the emission position density of the point (used when
        the emitter is the first camera vertex, where the competitor is light tracing)."""
        first = camera.first
        inner = _gate(first * self.e[Technique.LIGHT], self._m(pdf_pos)) + _gate((1.0 - first) * self.e[Technique.NEE],
                                                                         self._m(pdf_nee))
        w_camera = _gate(inner, camera.dvcm) + self._m(pdf_emit) * camera.dvc
        return self.e[Technique.HIT] / (1.0 + w_camera)

    def nee(self, camera: SubpathMis, pdf_nee, pdf_emit, cos_light, cos_cam, dist2,
            pdf_cam_fwd, pdf_cam_rev, delta=False, depth=None):
        """s = 1, t >= 2: emitter sampling at a camera vertex. ``cos_light``, ``cos_cam``: |cos|
        at the emitter point and at the camera vertex along the segment, ``dist2`` its squared
        length (1, 1 for an infinite emitter); ``pdf_cam_fwd``: BSDF density at the camera vertex
        of the direction to the emitter, ``pdf_cam_rev``: of the direction back along the camera
        subpath given the emitter's; ``delta``: delta emitter (it cannot be hit); ``depth``: the
        camera vertex's, in segments from the sensor."""
        p_cam0 = pdf_cam_fwd * cos_light / dist2
        w_light = _select(delta, 0.0 * p_cam0, _gate(self.e[Technique.HIT], self._m(p_cam0 / pdf_nee)))
        inner = (self.eta * (self._merges(depth) * self.eta_joined) + self._gated(camera, Technique.LIGHT)
                 + camera.dvc * self._m(pdf_cam_rev))
        w_camera = self._m(pdf_emit * cos_cam / (dist2 * pdf_nee)) * inner
        return self.e[Technique.NEE] / (w_light + 1.0 + w_camera)

    def connect(self, light: SubpathMis, camera: SubpathMis, pdf_light_fwd, pdf_light_rev,
                pdf_cam_fwd, pdf_cam_rev, cos_light, cos_cam, dist2, depth=None):
        """s >= 2, t >= 2: a connection between a light vertex and a camera vertex (neither a
        delta lobe). ``pdf_light_fwd``: density at the light vertex of the direction to the
        camera vertex, ``pdf_light_rev``: of the direction back along the light subpath given
        that one; ``pdf_cam_*`` likewise; ``cos_*``: |cos| at each end; ``dist2``; ``depth``:
        the camera vertex's, in segments from the sensor."""
        w_light = self._m(pdf_cam_fwd * cos_light / dist2) * (
            self.eta * light.merges + self._gated(light, Technique.NEE) + light.dvc * self._m(pdf_light_rev))
        w_camera = self._m(pdf_light_fwd * cos_cam / dist2) * (
            self.eta * (self._merges(depth) * self.eta_joined) + self._gated(camera, Technique.LIGHT)
            + camera.dvc * self._m(pdf_cam_rev))
        if not self.e[Technique.CONNECT]:
            return 0.0 * w_light
        # (this technique's term is its count n_c^beta, as each term of the sums carries its own)
        return self.connect_weight / (w_light + self.connect_weight + w_camera)

    def light_to_camera(self, light: SubpathMis, pdf_cam, cos_light, dist2, pdf_light_rev):
        """t = 1, s >= 2: a light vertex (not a delta lobe) joined to the sensor. ``pdf_cam``: the
        sensor's direction density towards it (as in ``start_camera``), ``cos_light`` |cos| at the
        light vertex, ``pdf_light_rev``: density at the light vertex of the direction back along
        the light subpath given the sensor's. (The light vertex is the camera's first: merging
        there counts unless ``merge_from`` > 1.)"""
        w_light = self._m(pdf_cam * cos_light / (dist2 * self.light_paths)) * (
            self.eta * (self._merges(1) * light.merges) + self._gated(light, Technique.NEE)
            + light.dvc * self._m(pdf_light_rev))
        return self.e[Technique.LIGHT] / (1.0 + w_light)

    def emitter_to_camera(self, pdf_cam, cos_light, dist2, pdf_pos, delta=False):
        """t = 1, s = 1: an emitted point joined to the sensor directly (``pdf_pos``: its emission
        position density; infinite emitter: its direction density, with cos_light = dist2 = 1)."""
        ratio = pdf_cam * cos_light / (dist2 * self.light_paths * pdf_pos)
        w_light = _select(delta, 0.0 * ratio, _gate(self.e[Technique.HIT], self._m(ratio)))
        return self.e[Technique.LIGHT] / (1.0 + w_light)


    @property
    def merge_bounded(self) -> bool:
        """Whether ``merge_bound`` can fall below 1: only light tracing and connections put
        terms into the camera side's sum (else merging's roulette has nothing to skip)."""
        return bool(self.techniques & (Technique.LIGHT | Technique.CONNECT))

    def merge_bound(self, camera: SubpathMis):
        """An upper bound on ``merge`` at a camera vertex, whatever light vertex it merges with:
        its weight without the terms that depend on the light vertex (all of them >= 0)."""
        return self.e[Technique.MERGE] / (1.0 + self._gated(camera, Technique.LIGHT) * self.inv_eta)

    def merge(self, light: SubpathMis, camera: SubpathMis, pdf_cam_fwd, pdf_cam_rev):
        """Merging a light vertex with a camera vertex at (about) the same point x_i, neither a
        delta lobe (``light`` and ``camera``: their states after ``after_hit``). The camera
        vertex's BSDF stands for both: ``pdf_cam_fwd`` its density of the light vertex's
        incoming direction (towards x_{i-1}) given the camera's, ``pdf_cam_rev`` the reverse."""
        w_light = self._gated(light, Technique.NEE) * self.inv_eta + light.dvm * self._m(pdf_cam_fwd)
        w_camera = self._gated(camera, Technique.LIGHT) * self.inv_eta + camera.dvm * self._m(pdf_cam_rev)
        return self.e[Technique.MERGE] / (w_light + 1.0 + w_camera)


def feasible(delta):
    """Which strategies s = 0 .. k can build a path with these delta flags (numpy bools, k + 1
    long): ``delta[0]`` a delta emitter (it cannot be hit, but can be connected to),
    ``delta[i]`` for 0 < i < k a delta lobe at x_i (no connection may end there), ``delta[k]``
    a sensor whose direction is a delta (orthographic: no light vertex can be joined to it, so
    t = 1, s = k, is infeasible)."""
    import numpy as np

    delta = np.asarray(delta, dtype=bool)
    k = delta.shape[0] - 1
    ok = np.empty_like(delta)
    ok[0] = ~delta[0]
    for s in range(1, k + 1):
        ok[s] = ~delta[s] if s == 1 else ~(delta[s] | delta[s - 1])
    return ok


def brute_force_weights(p_light, p_camera, delta, beta: float = 1.0, strategies="all",
                        p_nee=None, light_paths: float = 1.0, merge_area: float = 0.0,
                        merge_from: int = 1, connect_count: float = 1.0, caustic_merges: bool = False):
    """The weights of every technique computed directly from the path's densities (numpy).

    ``p_light[i]``: area density of x_i generated from the light side (``p_light[0]`` the
    emission position density), ``p_camera[i]``: from the camera side (``p_camera[k]`` the
    sensor's own, common to all strategies); shape (k + 1,) or (k + 1, n paths). ``p_nee``: the
    density of x_0 under emitter sampling (s = 1, t >= 2; default ``p_light[0]``); the t = 1
    strategy's density is multiplied by ``light_paths``, a connection's (s >= 2, t >= 2) by
    ``connect_count``. ``delta`` as in ``feasible``.
    Merging at x_i (i = 1 .. k - 1, not a delta vertex), when ``strategies`` has ``merge``: the
    light subpath builds x_0 .. x_i, the camera subpath x_k .. x_i, density
    p_light[0..i] p_camera[i..k] ``merge_area`` (pi r^2 N_light), where x_i is at least
    ``merge_from`` segments from the sensor (k - i >= merge_from; else weight 0) and, with
    ``caustic_merges``, x_{i-1} is an interior delta vertex (i >= 2). Returns p^beta / sum over the
    enabled feasible techniques of p^beta, 0 for a disabled or infeasible one: rows s = 0 .. k,
    then (with merging) rows for merging at x_1 .. x_{k-1}. Computed in logarithms, so densities
    may span any range.
    """
    import numpy as np

    p_light, p_camera = np.asarray(p_light, dtype=np.float64), np.asarray(p_camera, dtype=np.float64)
    k = p_light.shape[0] - 1
    enabled = BdptWeights(strategies=strategies, merge_area=merge_area or 1.0).techniques
    log_l, log_c = np.log(p_light), np.log(p_camera)
    log_nee = log_l[0] if p_nee is None else np.log(np.asarray(p_nee, dtype=np.float64))
    ok = feasible(delta)
    logs = []
    for s in range(k + 1):
        kind = Strategy(s, k + 1 - s).technique
        log_p = log_l[:s].sum(axis=0) + log_c[s:].sum(axis=0)
        if kind == Technique.NEE:
            log_p = log_p - log_l[0] + log_nee
        if kind == Technique.LIGHT:
            log_p = log_p + np.log(light_paths)
        if kind == Technique.CONNECT:
            log_p = log_p + np.log(connect_count)
        usable = ok[s] & (kind in enabled)
        logs.append(np.where(usable, beta * log_p, -np.inf))
    if Technique.MERGE in enabled:
        delta = np.asarray(delta, dtype=bool)
        for i in range(1, k):
            log_p = log_l[:i + 1].sum(axis=0) + log_c[i:].sum(axis=0) + np.log(merge_area)
            allowed = ~delta[i] & (k - i >= merge_from)
            if caustic_merges:
                allowed = allowed & delta[i - 1] & (i >= 2)
            logs.append(np.where(allowed, beta * log_p, -np.inf))
    logs = np.array(logs)
    top = logs.max(axis=0)
    top = np.where(np.isfinite(top), top, 0.0)
    terms = np.exp(logs - top)
    total = terms.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, terms / total, 0.0)
