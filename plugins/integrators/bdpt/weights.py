"""lab_bdpt's and lab_vcm's MIS weights: Georgiev's recursion (``recursion``) with the lab's
extensions, each a layer that changes the recursion's hooks.

* ``StrategySubsets``: ``strategies``, a subset of the techniques (``techniques.Technique``:
  e.g. ``LIGHT``, light tracing alone, or ``HIT | NEE``, unidirectional path tracing with MIS).
  Disabled techniques get weight 0 and leave the sums, so the enabled ones still sum to 1 over
  any path they can build: the subset is unbiased for the light it can reach. The flags are
  folded into the running sums as the kinds become known: a ratio's kind depends only on
  whether it is its subpath's first one (light side: nee, camera side: light tracing) or not
  (connect), which ``first`` tells (1.0 while ``dvcm`` still comes from the subpath's start).
  The emitter point seen by the sensor (s = 1, t = 1) is light tracing's too.
* ``ConnectionCounts``: each connection technique sampled ``connect_count`` times per camera
  vertex, in (0, 1] (lab_vcm's ``connections = one``: a camera vertex connects to one light
  vertex of its subpath, picked uniformly, about once per L light vertices; the weights use
  1 / L). Any counts > 0 give weights that sum to 1, so the estimate is unbiased whatever the
  count; the closer it is to the true sampling rate, the lower the variance.
* ``MergeFrom``: ``merge_from`` = 2 leaves merging out at the camera's first vertex (one
  segment from the sensor), as a technique and from every other technique's sums: the
  camera-side calls (``scatter_camera``, ``nee``, ``connect``) take the camera vertex's
  ``depth``, and ``light_to_camera``'s light vertex is the camera's first. (A light subpath's
  sums hold merges at its vertices before it knows how far from the sensor they will lie; only
  the camera's first vertex is always known to be one.)
* ``CausticMerges``: ``caustic_merges`` makes merging at x_i a technique only where x_{i-1}, the
  vertex before it on the light's side, is an interior delta-lobe vertex (the light vertex
  arrived through a specular bounce: Jensen's caustic photons). The rule is a property of the
  path, so the weights of the techniques left still sum to 1; a light subpath knows it at each
  vertex (``merges``, from its last lobe), a camera subpath only once it reaches x_{i-1}, so its
  merge term waits in ``pending`` until then.
* ``LaneTables``: lab_vcm runs several iterations in one pass, each merging with its own
  radius: lane i takes iteration i mod K's eta.

``BdptWeights`` is all of them; ``brute_force_weights`` computes every technique's weight
directly from a path's densities, the reference the recursion is tested against.
"""
from __future__ import annotations

from .recursion import Recursion, SubpathMis, select
from .techniques import (CONNECTIONS, NAMES, ORDER, PRESETS, Strategy, Technique, parse_techniques,
                         techniques_of)

#: The names of lab_bdpt's techniques, as users write them.
KINDS = tuple(NAMES[kind] for kind in ORDER if kind in CONNECTIONS)
#: (``SubpathMis`` lives in ``recursion``; the subpaths import it from here.)
__all__ = ["BdptWeights", "SubpathMis", "KINDS", "brute_force_weights", "feasible", "iteration_sizes",
           "strategy_kind"]


def iteration_sizes(lanes: int, iterations: int) -> list[int]:
    """How many of ``lanes`` lanes each iteration holds: lane i belongs to iteration i mod K
    (``BdptWeights.lane_iteration``)."""
    size, rest = divmod(lanes, iterations)
    return [size + (k < rest) for k in range(iterations)]


def _gate(flag, x):
    """flag * x, and exactly 0 where flag is 0 even if x is inf or NaN there (a density only a
    disabled strategy needs may be unusable, and must not spoil the enabled ones' weights)."""
    if isinstance(flag, (int, float)):
        return flag * x if flag else 0.0
    return select(flag != 0, flag * x, 0.0 * flag)


def strategy_kind(s: int, t: int) -> str:
    """The name of strategy (s, t)'s kind (``techniques.Strategy.technique``)."""
    return NAMES[Strategy(s, t).technique]


class StrategySubsets(Recursion):
    """Layer: only the ``techniques`` enabled (``e``: each one's enable factor, 1.0 or 0.0)."""
    techniques = CONNECTIONS | Technique.MERGE
    e = dict.fromkeys(ORDER, 1.0)

    @property
    def enabled(self) -> frozenset[str]:
        """The names of the enabled techniques (as users write them)."""
        return frozenset(NAMES[kind] for kind in ORDER if kind in self.techniques)

    def _own(self, kind):
        return self.e[kind]

    def _term(self, kind, x):
        return _gate(self.e[kind], x)

    def _flag(self, state: SubpathMis, start_kind: Technique):
        """Enable factor of the innermost ratio ``state.dvcm`` stands for."""
        return state.first * self.e[start_kind] + (1.0 - state.first) * self.connect_weight

    def _gated(self, state: SubpathMis, start_kind: Technique):
        """``state.dvcm`` times its enable factor (0 for a disabled kind, whatever dvcm is)."""
        return _gate(self._flag(state, start_kind), state.dvcm)

    def _inner(self, state, start_kind):
        return self._gated(state, start_kind)

    def _hit_inner(self, camera, pdf_pos_A, pdf_direct_A, eq=1.0):
        first = camera.first
        inner = _gate(first * self.e[Technique.LIGHT], self._m(pdf_pos_A)) + _gate(
            (1.0 - first) * self.e[Technique.NEE], self._m(pdf_direct_A) * eq)
        return _gate(inner, camera.dvcm)

    @property
    def merge_bounded(self) -> bool:
        """Whether ``merge_bound`` can fall below 1: only light tracing and connections put
        terms into the camera side's sum (else merging's roulette has nothing to skip)."""
        return bool(self.techniques & (Technique.LIGHT | Technique.CONNECT))


class ConnectionCounts(StrategySubsets):
    """Layer: ``connect_weight``, a connection technique's sample count to the power beta (its
    enable factor included), in the numerator of its weight and in every ratio it folds into."""

    def count_connections(self, connect_count: float) -> None:
        self.connect_weight = self.e[Technique.CONNECT] * self._m(float(connect_count))


class MergeFrom(ConnectionCounts):
    """Layer: merging from camera vertex ``merge_from`` on (1: every vertex; 2: all but the first)."""
    merge_from = 1

    def merges_at(self, depth):
        """Whether a camera vertex ``depth`` segments from the sensor merges (``merge_from``)."""
        return depth >= self.merge_from

    def _merges(self, depth):
        """``merges_at`` as a factor, 1.0 or 0.0; ``depth`` None: every camera vertex merges."""
        if depth is None or self.merge_from <= 1 or not self.merging:
            return 1.0
        return select(self.merges_at(depth), 1.0, 0.0)

    def _camera_merges(self, depth):
        return self._merges(depth)


class CausticMerges(MergeFrom):
    """Layer: with ``caustic``, merging at x_i only after a delta lobe at x_{i-1} on the light's
    side (``eta_joined``: a camera vertex's own merge where its light-side neighbour is an
    emitter or a light vertex joined to it, by NEE or a connection, never counts then)."""
    caustic = False
    eta_joined = 1.0

    def start_merges(self):
        """``merges`` at a light subpath's first vertex after the emitter (0.0 under
        ``caustic_merges``: the emitter is no delta lobe)."""
        return 0.0 if self.caustic else 1.0

    def _light_merges(self, light):
        return light.merges

    def _joined_merges(self, depth):
        return self._merges(depth) * self.eta_joined

    def _sensor_merges(self, light):
        return self._merges(1) * light.merges

    def _pending_after_hit(self, pending, inv_cos):
        return pending * inv_cos if self.caustic else pending

    def scatter_light(self, state, pdf_fwd_W, pdf_rev_W, cos_out, delta=False, medium=None) -> SubpathMis:
        """With ``caustic_merges`` the new state's ``merges`` (for the next vertex) is ``delta``."""
        out = super().scatter_light(state, pdf_fwd_W, pdf_rev_W, cos_out, delta, medium)
        if self.caustic:
            out = out._replace(merges=select(delta, 1.0, 0.0))
        return out

    def scatter_camera(self, state, pdf_fwd_W, pdf_rev_W, cos_out, delta=False, depth=None,
                       medium=None) -> SubpathMis:
        """With ``caustic_merges`` this vertex's merge term waits in ``pending``, and the one
        pending from the last vertex counts where this vertex is a delta lobe: the sums a delta
        lobe passes on gain it, the others do not (the recursion with no merge here, twice)."""
        if not self.caustic:
            return super().scatter_camera(state, pdf_fwd_W, pdf_rev_W, cos_out, delta, depth, medium)
        merges = self._camera_merges(depth) * self._volume_ratio(medium)
        kept = self._scatter(state, pdf_fwd_W, pdf_rev_W, cos_out, delta, Technique.LIGHT, 0.0)
        through = self._scatter(state._replace(dvc=state.dvc + self.eta * state.pending, dvm=state.dvm + state.pending),
                                pdf_fwd_W, pdf_rev_W, cos_out, delta, Technique.LIGHT, 0.0)
        ratio = self._m(cos_out / pdf_fwd_W)
        return kept._replace(dvc=select(delta, through.dvc, kept.dvc), dvm=select(delta, through.dvm, kept.dvm),
                             pending=select(delta, kept.dvcm, ratio * merges))   # (kept.dvcm: 0 there)


class LaneTables(CausticMerges):
    """Layer: one eta per lane, from its iteration's radius (lab_vcm)."""

    #: lab_vcm: (eta table, 1 / eta table, iterations), one entry per iteration of a pass, each
    #: to the power beta (Dr.Jit arrays; see ``at_lanes``); None: ``eta`` holds for every lane.
    lane_tables = None
    #: lab_vcm in media: each iteration's merge_volume, to the power beta (None: ``eta_volume``)
    volume_table = None

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
        if self.volume_table is not None:
            lanes.eta_volume = dr.gather(type(eta), self.volume_table, k)
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


class BdptWeights(LaneTables):
    """The MIS weights for one heuristic, one exponent and one set of techniques.

    ``heuristic``: ``balance`` or ``power`` (exponent ``beta``); ``strategies``: ``Technique``
    flags, or what users write (a preset name, ``all``, ``camera`` = hit + nee, ``light``, or
    kinds joined by '+'; or an iterable of kind names), parsed once here; ``light_paths``: the
    number of light subpaths each camera subpath competes with in the t = 1 strategy (SmallVCM's
    light-subpath count: light tracing splats one light subpath into many pixels);
    ``merge_area``: pi r^2 N_light, with merging among the techniques, and ``merge_volume``:
    4/3 pi r_v^3 N_light, merging's at medium vertices (0: none merges there); ``merge_from``,
    ``connect_count``, ``caustic_merges``: the layers above (the module docstring).
    """

    def __init__(self, heuristic: str = "power", beta: float = 2.0, strategies="all",
                 light_paths: float = 1.0, merge_area: float = 0.0, merge_from: int = 1,
                 connect_count: float = 1.0, caustic_merges: bool = False, merge_volume: float = 0.0):
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
        if merge_from not in (1, 2):
            raise ValueError(f"lab_vcm: merge_from must be 1 (every camera vertex merges) or 2 (all but the "
                             f"first), got {merge_from!r}")
        merging = Technique.MERGE in kinds
        super().__init__(1.0 if heuristic == "balance" else beta, light_paths, merging, merge_area, merge_volume)
        #: the enabled techniques, and each one's enable factor (1.0 or 0.0)
        self.techniques = kinds
        self.e = {kind: 1.0 if kind in kinds else 0.0 for kind in ORDER}
        self.merge_from = merge_from
        self.caustic = bool(caustic_merges) and merging
        self.eta_joined = 0.0 if self.caustic else 1.0
        self.count_connections(connect_count)


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
                        merge_from: int = 1, connect_count: float = 1.0, caustic_merges: bool = False,
                        merge_volume: float = 0.0, medium=None):
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
    ``caustic_merges``, x_{i-1} is an interior delta vertex (i >= 2); at a medium vertex
    (``medium[i]``, numpy bools like ``delta``) ``merge_volume`` (4/3 pi r_v^3 N_light, with
    volume densities there) stands for ``merge_area``. Returns p^beta / sum over the
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
            size = merge_area if medium is None else np.where(medium[i], merge_volume, merge_area)
            log_p = log_l[:i + 1].sum(axis=0) + log_c[i:].sum(axis=0) + np.log(size)
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
