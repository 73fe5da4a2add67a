"""Property tests of lab_bdpt's recursive MIS weights against the brute-force reference.

Random paths (fixed seeds, k = 1 .. 7 segments, i.e. 2 .. 8 vertices, 4000 paths per length,
densities, cosines and squared distances log-uniform over many decades, random delta emitters,
delta lobes and infinite emitters) are weighted twice: by the O(1) recursion, walking each
subpath as the integrator will, and by the products of per-vertex area densities. In float64
the two agree to a relative 1e-9 (RTOL); weights of the strategies that can build a path sum to
1, over all kinds and over restricted subsets; a deliberately wrong update (a missing cosine, a
swapped reverse density) is caught; Dr.Jit arrays give numpy's numbers to float32 precision.
With merging (lab_vcm's extra technique at every interior vertex, density
p_light(x_0..x_i) p_camera(x_i..x_k) pi r^2 N_light) the same holds over connections and merges
together, and a connection that leaves out merging at its own vertex is caught; so it does
without merging at the camera's first vertex (``merge_from`` = 2), where any camera-side sum
that still counts that merge is caught.
"""
import numpy as np
import pytest

from mitsuba_lab.plugins.integrators.bdpt.techniques import Technique
from mitsuba_lab.plugins.integrators.bdpt.weights import (BdptWeights, KINDS, brute_force_weights,
                                                         feasible)

N = 4000
RTOL = 1e-9
SUBSETS = [("hit",), ("nee",), ("light",), ("connect",), ("hit", "nee"), ("light", "connect"),
           ("hit", "light"), ("nee", "connect"), ("hit", "nee", "light")]


def random_paths(k, seed, n=N, spread=1.0, media=False):
    """Per-vertex geometry of n random paths x_0 .. x_k (arrays indexed [vertex, path]);
    ``spread`` < 1 narrows the log-ranges (float32 cannot hold a power of 1e-10 densities).

    ``media``: interior vertices are medium vertices with probability 0.4 (never a delta lobe;
    their g = sigma_t, 1e-3 .. 1e3, stands for both cosines), and every segment has a
    transmittance T in 1e-4 .. 1 (the probability with which distance sampling passes it in
    the path's channel, ``g["T"]``), in both directions the same."""
    rng = np.random.default_rng(seed)

    def _logu(rng, lo, hi, shape):
        return np.exp(spread * rng.uniform(np.log(lo), np.log(hi), shape))

    g = {
        "d2": _logu(rng, 1e-3, 1e3, (k, n)),             # squared length of edge x_i x_{i+1}
        "cos_l": _logu(rng, 1e-3, 1.0, (k + 1, n)),      # |cos| at x_i towards x_{i-1}
        "cos_c": _logu(rng, 1e-3, 1.0, (k + 1, n)),      # |cos| at x_i towards x_{i+1}
        "to_cam": _logu(rng, 1e-4, 1e4, (k + 1, n)),     # solid-angle density at x_i towards x_{i+1}
        "to_light": _logu(rng, 1e-4, 1e4, (k + 1, n)),   # ... towards x_{i-1}
        "pos": _logu(rng, 1e-4, 1e4, n),                 # emission position density of x_0
        "nee": _logu(rng, 1e-4, 1e4, n),                 # emitter-sampling density of x_0
        "delta": rng.random((k + 1, n)) < 0.3,
        "infinite": rng.random(n) < 0.25,
        "light_paths": 1.0 + 99.0 * rng.random(),
    }
    g["delta"][k] = False                                # the sensor is never a delta vertex
    if media:
        in_medium = rng.random((k + 1, n)) < 0.4
        in_medium[0] = in_medium[k] = False
        sigma_t = _logu(rng, 1e-3, 1e3, (k + 1, n))
        g["cos_l"] = np.where(in_medium, sigma_t, g["cos_l"])
        g["cos_c"] = np.where(in_medium, sigma_t, g["cos_c"])
        g["delta"] = g["delta"] & ~in_medium
        g["medium"], g["sigma_t"] = in_medium, sigma_t
        g["T"] = _logu(rng, 1e-4, 1.0, (k, n))
    inf = g["infinite"]
    g["d2"][0] = np.where(inf, 1.0, g["d2"][0])          # x_0 at infinity: no distance, no cosine
    g["cos_c"][0] = np.where(inf, 1.0, g["cos_c"][0])
    # A delta lobe's forward and reverse probabilities are equal (they cancel).
    interior = g["delta"].copy()
    interior[0] = False
    g["to_light"] = np.where(interior, g["to_cam"], g["to_light"])
    return g


def area_densities(g):
    """(p_light, p_camera) of every vertex, the brute force's input."""
    k = g["d2"].shape[0]
    p_light, p_camera = np.empty((k + 1, N)), np.empty((k + 1, N))
    T = g.get("T", np.ones((k, N)))                      # (media: p_A = p_W g T / d^2)
    p_light[0] = g["pos"]
    for i in range(1, k + 1):
        p_light[i] = g["to_cam"][i - 1] * g["cos_l"][i] * T[i - 1] / g["d2"][i - 1]
    p_camera[k] = 1.0
    for i in range(k):
        p_camera[i] = g["to_light"][i + 1] * g["cos_c"][i] * T[i] / g["d2"][i]
    return p_light, p_camera


def recursive_weights(g, mis, wrong=None, media_calls=False):
    """Every strategy's weight by the recursion, subpaths walked as the integrator will walk them
    (``wrong``: a deliberate mistake, to show the test's power; ``media_calls``: each call told which
    of its vertices lie in a medium, as lab_vcm's merging at medium vertices needs)."""
    k = g["d2"].shape[0]
    d2, cl, cc, fw, rv, delta = g["d2"], g["cos_l"], g["cos_c"], g["to_cam"], g["to_light"], g["delta"]
    # media: each segment's T goes to after_hit and, on a connecting segment, with its cosines
    # (heterogeneous media: the camera subpath's and the connections' own evaluations of it)
    tr = g.get("T")
    T_light = np.ones((k, N)) if tr is None else tr
    T_cam, T = g.get("T_camera", tr), g.get("T_connect", T_light)
    pdf_emit = g["pos"] * fw[0]

    def at(i, name="medium"):
        """The keyword telling a call whether x_i lies in a medium (none without ``media_calls``)."""
        return {name: g["medium"][i]} if media_calls else {}

    light = {}
    state = mis.start_light(pdf_emit, g["nee"], cc[0], delta[0])
    for i in range(1, k):
        cos_in = np.where(g["medium"][i], 1.0, cl[i]) if wrong == "sigma_t" else cl[i]
        seg = None if tr is None or wrong == "transmittance" else tr[i - 1]
        state = mis.after_hit(state, d2[i - 1], cos_in, seg)
        light[i] = state
        cos_out = 1.0 if wrong == "cosine" else cc[i]
        pdf_rev = fw[i] if wrong == "swap" else rv[i]
        state = mis.scatter_light(state, fw[i], pdf_rev, cos_out, delta[i], **at(i))
    camera = {}
    state = mis.start_camera(rv[k], delta[k])            # (delta[k]: an orthographic sensor)
    for i in range(k - 1, -1, -1):
        state = mis.after_hit(state, d2[i], cc[i], None if tr is None else T_cam[i])
        camera[i] = state
        if i > 0:                          # (x_i lies k - i segments from the sensor)
            state = mis.scatter_camera(state, rv[i], fw[i], cl[i], delta[i], depth=k - i, **at(i))
    w = np.zeros((k + 1, N))
    for s in range(k + 1):
        t = k + 1 - s
        if s == 0:
            w[s] = mis.hit(camera[0], g["nee"], pdf_emit, g["pos"])
        elif t == 1 and s == 1:
            w[s] = mis.emitter_to_camera(rv[1], cc[0] * T[0], d2[0], g["pos"], delta[0])
        elif s == 1:
            w[s] = mis.nee(camera[1], g["nee"], pdf_emit, cc[0] * T[0], cl[1] * T[0], d2[0], rv[1], fw[1],
                           delta[0], depth=k - 1, **at(1))
        elif t == 1:
            w[s] = mis.light_to_camera(light[k - 1], rv[k], cc[k - 1] * T[k - 1], d2[k - 1], rv[k - 1], **at(k - 1))
        else:
            w[s] = mis.connect(light[s - 1], camera[s], fw[s - 1], rv[s - 1], rv[s], fw[s],
                               cc[s - 1] * T[s - 1], cl[s] * T[s - 1], d2[s - 1], depth=k - s,
                               **at(s - 1, "light_medium"), **at(s, "camera_medium"))
    w = np.where(feasible(delta), w, 0.0)    # the integrator never runs an infeasible one
    if not media_calls:
        return w
    merges = [np.where(delta[i] | (k - i < mis.merge_from), 0.0,
                       mis.merge(light[i], camera[i], rv[i], fw[i], **at(i))) for i in range(1, k)]
    return np.concatenate([w, np.array(merges).reshape(-1, N)])


def _reference(g, beta, strategies="all"):
    p_light, p_camera = area_densities(g)
    return brute_force_weights(p_light, p_camera, g["delta"], beta, strategies, g["nee"], g["light_paths"])


def _max_rel(a, b):
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300) * (b > 0) + np.abs(a) * (b == 0)))


@pytest.mark.parametrize("heuristic,beta", [("balance", 1.0), ("power", 2.0), ("power", 3.0)])
def test_recursion_equals_brute_force_and_sums_to_one(heuristic, beta):
    worst = 0.0
    for k in range(1, 8):
        g = random_paths(k, seed=100 * k + int(beta))
        mis = BdptWeights(heuristic, beta, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            got, ref = recursive_weights(g, mis), _reference(g, beta)
        worst = max(worst, _max_rel(got, ref))
        buildable = feasible(g["delta"]).any(axis=0)    # e.g. point light -> mirror -> pinhole is not
        total = got.sum(axis=0)
        np.testing.assert_allclose(total[buildable], 1.0, rtol=RTOL)
        assert np.all(total[~buildable] == 0.0) and buildable.mean() > 0.8
    print(f"beta={beta}: max relative error recursion vs brute force {worst:.2e}")
    assert worst < RTOL


@pytest.mark.parametrize("subset", SUBSETS)
def test_restricted_strategies_sum_to_one_where_they_reach(subset):
    worst, reached = 0.0, 0
    for k in range(1, 8):
        g = random_paths(k, seed=7000 + k)
        mis = BdptWeights("power", 2.0, strategies=subset, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            got, ref = recursive_weights(g, mis), _reference(g, 2.0, subset)
        worst = max(worst, _max_rel(got, ref))
        kinds = np.array([_kind(s, k) in subset for s in range(k + 1)])[:, None]
        reachable = (feasible(g["delta"]) & kinds).any(axis=0)
        reached += int(reachable.sum())
        total = got.sum(axis=0)
        np.testing.assert_allclose(total[reachable], 1.0, rtol=RTOL)
        assert np.all(total[~reachable] == 0.0)
    print(f"{'+'.join(subset)}: {reached} paths reachable, max relative error {worst:.2e}")
    assert worst < RTOL and reached > 0


def _kind(s, k):
    from mitsuba_lab.plugins.integrators.bdpt.weights import strategy_kind

    return strategy_kind(s, k + 1 - s)


@pytest.mark.parametrize("wrong", ["cosine", "swap"])
def test_a_wrong_update_is_caught(wrong):
    """The power of the comparison: a light-side scatter that drops its cosine, or uses the
    forward density where the reverse belongs, misses the brute force by far more than RTOL."""
    g = random_paths(4, seed=11)
    mis = BdptWeights("power", 2.0, light_paths=g["light_paths"])
    with np.errstate(all="ignore"):
        err = _max_rel(recursive_weights(g, mis, wrong=wrong), _reference(g, 2.0))
    print(f"{wrong}: max relative error {err:.2e}")
    assert err > 1e3 * RTOL


@pytest.mark.parametrize("merging", [False, True])
def test_an_orthographic_sensor_leaves_light_tracing_out(merging):
    """A sensor whose direction is a delta (``delta[k]``: orthographic) makes t = 1 infeasible;
    the camera subpath that starts with its t = 1 term at 0 (``start_camera(delta=True)``)
    weights the other strategies (merging too) as the brute force does, summing to 1, while the
    pinhole's start, which still counts t = 1 in every other strategy's sum, is caught."""
    worst, caught = 0.0, np.inf
    subset = KINDS + ("merge",) if merging else KINDS
    for k in range(1, 8):
        g = random_paths(k, seed=4100 + k)
        g["delta"][k] = True
        area = 0.5 if merging else 0.0
        mis = BdptWeights("power", 2.0, strategies=subset, light_paths=g["light_paths"], merge_area=area)
        p_light, p_camera = area_densities(g)
        walk = recursive_weights_with_merging if merging else recursive_weights
        with np.errstate(all="ignore"):
            got = walk(g, mis)
            ref = brute_force_weights(p_light, p_camera, g["delta"], 2.0, subset, g["nee"], g["light_paths"], area)
            pinhole = walk({**g, "delta": np.concatenate([g["delta"][:k], np.zeros((1, N), bool)])}, mis)
        pinhole[k] = 0.0                                 # (t = 1 never runs: only the start differs)
        worst = max(worst, _max_rel(got, ref))
        caught = min(caught, _max_rel(pinhole, ref))
        reach = ref.sum(axis=0) > 0
        assert np.all(got[k] == 0.0) and reach.mean() > 0.5
        np.testing.assert_allclose(got.sum(axis=0)[reach], 1.0, rtol=RTOL)
    print(f"orthographic, merging {merging}: max relative error {worst:.2e}; the pinhole's start: {caught:.2e}")
    assert worst < RTOL and caught > 1e3 * RTOL


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="lab_bdpt: strategies"):
        BdptWeights(strategies=("hit", "photons"))
    with pytest.raises(ValueError, match="lab_bdpt: heuristic"):
        BdptWeights("max")
    with pytest.raises(ValueError, match="beta"):
        BdptWeights("power", 0.0)
    assert BdptWeights(strategies="camera").enabled == {"hit", "nee"}
    assert set(KINDS) == BdptWeights().enabled


def test_drjit_arrays_give_numpy_numbers():
    pytest.importorskip("drjit")
    llvm = pytest.importorskip("drjit.llvm")
    k, n = 5, 512
    g = random_paths(k, seed=5, spread=0.3)
    mis = BdptWeights("power", 2.0, light_paths=g["light_paths"])
    with np.errstate(all="ignore"):
        ref = recursive_weights(g, mis)[:, :n]
    cut = {key: (v[..., :n] if isinstance(v, np.ndarray) else v) for key, v in g.items()}

    def to_dr(a):
        if a.dtype == bool:
            return [llvm.Bool(row) for row in a] if a.ndim == 2 else llvm.Bool(a)
        return [llvm.Float(row.astype(np.float32)) for row in a] if a.ndim == 2 else llvm.Float(a.astype(np.float32))

    d = {key: (to_dr(v) if isinstance(v, np.ndarray) else v) for key, v in cut.items()}
    d2, cl, cc, fw, rv, delta = d["d2"], d["cos_l"], d["cos_c"], d["to_cam"], d["to_light"], d["delta"]
    pdf_emit = d["pos"] * fw[0]
    light, state = {}, mis.start_light(pdf_emit, d["nee"], cc[0], delta[0])
    for i in range(1, k):
        state = mis.after_hit(state, d2[i - 1], cl[i])
        light[i] = state
        state = mis.scatter_light(state, fw[i], rv[i], cc[i], delta[i])
    camera, state = {}, mis.start_camera(rv[k])
    for i in range(k - 1, -1, -1):
        state = mis.after_hit(state, d2[i], cc[i])
        camera[i] = state
        if i > 0:
            state = mis.scatter_camera(state, rv[i], fw[i], cl[i], delta[i])
    got = [mis.hit(camera[0], d["nee"], pdf_emit, d["pos"]),
           mis.nee(camera[1], d["nee"], pdf_emit, cc[0], cl[1], d2[0], rv[1], fw[1], delta[0])]
    got += [mis.connect(light[s - 1], camera[s], fw[s - 1], rv[s - 1], rv[s], fw[s], cc[s - 1], cl[s], d2[s - 1])
            for s in range(2, k)]
    got.append(mis.light_to_camera(light[k - 1], rv[k], cc[k - 1], d2[k - 1], rv[k - 1]))
    got = np.where(feasible(cut["delta"]), np.array([np.asarray(x, dtype=np.float64) for x in got]), 0.0)
    err = np.max(np.abs(got - ref))
    print(f"drjit.llvm vs numpy: max abs weight difference {err:.2e} over {n} paths")
    assert err < 1e-4


@pytest.mark.parametrize("subset", [("hit", "light"), ("light", "connect")])
def test_a_wrong_restriction_is_caught(monkeypatch, subset):
    """The subset test's power: folding every innermost ratio with the ``connect`` flag (ignoring
    that a subpath's first ratio is a nee or light-tracing one) misweights these subsets."""
    g = random_paths(4, seed=12)
    mis = BdptWeights("power", 2.0, strategies=subset, light_paths=g["light_paths"])
    monkeypatch.setattr(mis, "_flag", lambda state, start_kind: mis.e[Technique.CONNECT])
    with np.errstate(all="ignore"):
        err = _max_rel(recursive_weights(g, mis), _reference(g, 2.0, subset))
    print(f"flag, {'+'.join(subset)}: max relative error {err:.2e}")
    assert err > 1e3 * RTOL


# -- Merging (lab_vcm): one more technique per interior vertex ----------------------------------
MERGE_SUBSETS = [("hit", "nee", "light", "connect", "merge"), ("merge",), ("light", "merge"),
                 ("hit", "nee", "merge"), ("connect", "merge")]


def merging_states(g, mis):
    """(light, camera): each subpath's MIS state on arrival at x_i, i = 1 .. k - 1."""
    k = g["d2"].shape[0]
    d2, cl, cc, fw, rv, delta = g["d2"], g["cos_l"], g["cos_c"], g["to_cam"], g["to_light"], g["delta"]
    light, state = {}, mis.start_light(g["pos"] * fw[0], g["nee"], cc[0], delta[0])
    for i in range(1, k):
        state = mis.after_hit(state, d2[i - 1], cl[i])
        light[i] = state
        state = mis.scatter_light(state, fw[i], rv[i], cc[i], delta[i])
    camera, state = {}, mis.start_camera(rv[k], delta[k])
    for i in range(k - 1, 0, -1):
        state = mis.after_hit(state, d2[i], cc[i])
        camera[i] = state
        state = mis.scatter_camera(state, rv[i], fw[i], cl[i], delta[i], depth=k - i)
    return light, camera


def recursive_weights_with_merging(g, mis):
    """``recursive_weights`` plus, for each interior vertex x_i (i = 1 .. k - 1), the weight of
    merging a light vertex with a camera vertex there (rows k + 1 ..): the camera vertex's BSDF
    gives both directions' densities (``to_light`` and ``to_cam`` at x_i)."""
    k = g["d2"].shape[0]
    fw, rv, delta = g["to_cam"], g["to_light"], g["delta"]
    light, camera = merging_states(g, mis)
    # (the integrator does not merge at a camera vertex nearer the sensor than merge_from, nor,
    # with caustic_merges, with a light vertex whose ``merges`` is 0: the grid leaves it out)
    merges = [np.where(delta[i] | (k - i < mis.merge_from) | (np.asarray(light[i].merges) == 0), 0.0,
                       mis.merge(light[i], camera[i], rv[i], fw[i]))
              for i in range(1, k)]
    return np.concatenate([recursive_weights(g, mis), np.array(merges).reshape(-1, N)])


@pytest.mark.parametrize("caustic", [False, True])
@pytest.mark.parametrize("merge_from", [1, 2])
@pytest.mark.parametrize("subset", MERGE_SUBSETS)
@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_merging_weights_equal_brute_force_and_sum_to_one(subset, beta, merge_from, caustic):
    """Vertex connection and merging (Georgiev et al. 2012): merging at x_i has density
    p_light(x_0..x_i) p_camera(x_i..x_k) pi r^2 N_light, and the recursion (a third running
    quantity, dVM) weights it, and every connection, against all the others; with
    ``merge_from`` = 2 the camera's first vertex is no merging technique, in any sum; with
    ``caustic_merges`` only a vertex after an interior delta vertex (light side) is one."""
    worst = 0.0
    for k in range(1, 8):
        g = random_paths(k, seed=900 * k + int(beta))
        area = float(np.exp(np.random.default_rng(k).uniform(np.log(1e-4), np.log(1e4))))
        mis = BdptWeights("power", beta, strategies=subset, light_paths=g["light_paths"], merge_area=area,
                          merge_from=merge_from, caustic_merges=caustic)
        p_light, p_camera = area_densities(g)
        with np.errstate(all="ignore"):
            got = recursive_weights_with_merging(g, mis)
            ref = brute_force_weights(p_light, p_camera, g["delta"], beta, subset, g["nee"], g["light_paths"],
                                      area, merge_from, caustic_merges=caustic)
        worst = max(worst, _max_rel(got, ref))
        reach = ref.sum(axis=0) > 0
        np.testing.assert_allclose(got.sum(axis=0)[reach], 1.0, rtol=RTOL)
        assert np.all(got.sum(axis=0)[~reach] == 0.0)
    print(f"{'+'.join(subset)}, beta {beta}, merge_from {merge_from}, caustic {caustic}: max relative error "
          f"{worst:.2e}")
    assert worst < RTOL


@pytest.mark.parametrize("subset", MERGE_SUBSETS)
def test_no_merge_weight_exceeds_the_camera_sides_bound(subset):
    """``merge_bound`` (merging's Russian roulette runs a merge with probability bound / 0.5) is
    at least the merge weight with every light vertex; below 1 only where techniques with fewer
    camera vertices (light tracing, connections) compete."""
    lowest = 1.0
    for k in range(2, 8):
        g = random_paths(k, seed=500 + k)
        mis = BdptWeights("power", 2.0, strategies=subset, light_paths=g["light_paths"], merge_area=7.0)
        light, camera = merging_states(g, mis)
        with np.errstate(all="ignore"):
            for i in range(1, k):
                weight = mis.merge(light[i], camera[i], g["to_light"][i], g["to_cam"][i])
                bound = np.broadcast_to(mis.merge_bound(camera[i]), weight.shape)
                ok = np.isfinite(weight)
                assert np.all(weight[ok] <= bound[ok] * (1 + 1e-12)), (subset, k, i)
                lowest = min(lowest, float(np.min(bound)))
    print(f"{'+'.join(subset)}: smallest bound {lowest:.2e}")
    assert (lowest < 1e-3) if {"light", "connect"} & set(subset) else (lowest == 1.0)


@pytest.mark.parametrize("mistake", ["scatter_camera", "nee", "connect", "light_to_camera"])
def test_a_first_vertex_merge_left_in_a_sum_is_caught(monkeypatch, mistake):
    """Power of the merge_from = 2 check: a camera-side call that still counts merging at the
    camera's first vertex (in dVC and dVM, in next-event estimation's sum, a connection's, or
    light tracing's) misweights paths."""
    area, kinds = 3.0, MERGE_SUBSETS[0]
    err = 0.0
    for k in range(2, 6):
        g = random_paths(k, seed=13 + k)
        mis = BdptWeights("power", 2.0, strategies=kinds, light_paths=g["light_paths"], merge_area=area,
                          merge_from=2)
        every = BdptWeights("power", 2.0, strategies=kinds, light_paths=g["light_paths"], merge_area=area)
        if mistake == "light_to_camera":
            monkeypatch.setattr(mis, mistake, every.light_to_camera)
        else:
            right = getattr(mis, mistake)
            monkeypatch.setattr(mis, mistake, lambda *a, depth=None, right=right: right(*a, depth=None))
        p_light, p_camera = area_densities(g)
        with np.errstate(all="ignore"):
            ref = brute_force_weights(p_light, p_camera, g["delta"], 2.0, kinds, g["nee"], g["light_paths"],
                                      area, 2)
            err = max(err, _max_rel(recursive_weights_with_merging(g, mis), ref))
    print(f"{mistake}: max relative error {err:.2e}")
    assert err > 1e3 * RTOL


def test_merging_off_changes_nothing():
    """Without ``merge`` the recursion is bit for bit the connections-only one (lab_bdpt)."""
    g = random_paths(5, seed=3)
    plain = BdptWeights("power", 2.0, light_paths=g["light_paths"])
    with_area = BdptWeights("power", 2.0, light_paths=g["light_paths"], merge_area=0.5)
    with np.errstate(all="ignore"):
        np.testing.assert_array_equal(recursive_weights(g, plain), recursive_weights(g, with_area))
    with pytest.raises(ValueError, match="merge_area"):
        BdptWeights(strategies=("merge",))
    with pytest.raises(ValueError, match="merge_from"):
        BdptWeights(strategies=("merge",), merge_area=1.0, merge_from=3)


def test_a_missing_merge_term_is_caught():
    """Power: connections that forget merging at their own vertex (the eta term) are wrong."""
    g = random_paths(4, seed=12)
    area = 3.0
    mis = BdptWeights("power", 2.0, strategies=MERGE_SUBSETS[0], light_paths=g["light_paths"], merge_area=area)
    p_light, p_camera = area_densities(g)
    with np.errstate(all="ignore"):
        ref = brute_force_weights(p_light, p_camera, g["delta"], 2.0, MERGE_SUBSETS[0], g["nee"],
                                  g["light_paths"], area)
        mis.eta = 0.0                                  # the deliberate mistake
        err = _max_rel(recursive_weights_with_merging(g, mis), ref)
    print(f"missing eta: max relative error {err:.2e}")
    assert err > 1e3 * RTOL


@pytest.mark.parametrize("subset", [KINDS, MERGE_SUBSETS[0], ("nee", "connect")])
@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_a_connection_count_weights_connections_as_the_brute_force_does(subset, beta):
    """lab_vcm's ``connections = one`` counts each connection technique n_c < 1 times per camera
    vertex: its density becomes n_c p, in every sum and in its own weight, and the weights of
    every path still sum to 1; weighting connections as count 1 is caught."""
    worst, wrong = 0.0, 0.0
    merging = "merge" in subset
    for k in range(1, 8):
        g = random_paths(k, seed=700 * k + int(beta))
        count = float(np.random.default_rng(k).uniform(0.05, 1.0))
        area = 2.5 if merging else 0.0
        mis = BdptWeights("power", beta, strategies=subset, light_paths=g["light_paths"], merge_area=area,
                          merge_from=2 if merging else 1, connect_count=count)
        p_light, p_camera = area_densities(g)
        with np.errstate(all="ignore"):
            got = recursive_weights_with_merging(g, mis) if merging else recursive_weights(g, mis)
            ref = brute_force_weights(p_light, p_camera, g["delta"], beta, subset, g["nee"], g["light_paths"],
                                      area, 2 if merging else 1, connect_count=count)
            uncounted = brute_force_weights(p_light, p_camera, g["delta"], beta, subset, g["nee"],
                                            g["light_paths"], area, 2 if merging else 1)
        worst = max(worst, _max_rel(got, ref))
        wrong = max(wrong, _max_rel(got, uncounted))
        reach = ref.sum(axis=0) > 0
        np.testing.assert_allclose(got.sum(axis=0)[reach], 1.0, rtol=RTOL)
    print(f"{'+'.join(subset)}, beta {beta}: max relative error {worst:.2e} (against count 1: {wrong:.2e})")
    assert worst < RTOL
    assert wrong > 1e3 * RTOL
    with pytest.raises(ValueError, match="connect_count"):
        BdptWeights(connect_count=0.0)


@pytest.mark.parametrize("mistake", ["every merge", "camera merges at once", "joined merges"])
def test_a_caustic_merge_rule_applied_wrongly_is_caught(monkeypatch, mistake):
    """Power of the ``caustic_merges`` check: weights against every merge (the rule forgotten in
    the reference), a camera subpath that counts its vertex's merge before it knows the next
    vertex is a delta lobe, or next-event estimation and connections that still count a merge at
    their camera vertex (whose light-side neighbour is never a delta lobe), misweight paths."""
    area, kinds = 3.0, MERGE_SUBSETS[0]
    err = 0.0
    for k in range(3, 7):
        g = random_paths(k, seed=41 + k)
        mis = BdptWeights("power", 2.0, strategies=kinds, light_paths=g["light_paths"], merge_area=area,
                          merge_from=2, caustic_merges=True)
        caustic = mistake != "every merge"
        if mistake == "camera merges at once":
            monkeypatch.setattr(mis, "scatter_camera", lambda state, fwd, rev, cos, delta=False, depth=None:
                                mis._scatter(state, fwd, rev, cos, delta, Technique.LIGHT, mis._merges(depth)))
        if mistake == "joined merges":
            mis.eta_joined = 1.0
        p_light, p_camera = area_densities(g)
        with np.errstate(all="ignore"):
            ref = brute_force_weights(p_light, p_camera, g["delta"], 2.0, kinds, g["nee"], g["light_paths"],
                                      area, 2, caustic_merges=caustic)
            err = max(err, _max_rel(recursive_weights_with_merging(g, mis), ref))
    print(f"{mistake}: max relative error {err:.2e}")
    assert err > 1e3 * RTOL


# -- Participating media (lab_bdpt's media_paths) ---------------------------------------------
@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_medium_vertices_equal_brute_force_and_sum_to_one(beta):
    """Paths with medium vertices (g = sigma_t for both cosines, no delta lobe) and a
    transmittance on every segment: the recursion, given T in after_hit and with the cosines of
    each connecting segment, equals the brute force over p_A = p_W g T / d^2, and the weights
    of all strategies sum to 1."""
    worst, mediums = 0.0, 0
    for k in range(1, 8):
        g = random_paths(k, seed=9100 + 10 * k + int(beta), media=True)
        mediums += int(g["medium"].sum())
        mis = BdptWeights("power", beta, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            got, ref = recursive_weights(g, mis), _reference(g, beta)
        worst = max(worst, _max_rel(got, ref))
        buildable = feasible(g["delta"]).any(axis=0)
        np.testing.assert_allclose(got.sum(axis=0)[buildable], 1.0, rtol=RTOL)
    print(f"beta={beta}: {mediums} medium vertices, max relative error recursion vs brute force {worst:.2e}")
    assert worst < RTOL and mediums > 10000


@pytest.mark.parametrize("subset", [("light",), ("hit", "nee"), ("nee", "connect")])
def test_medium_vertices_in_restricted_strategies(subset):
    worst = 0.0
    for k in range(1, 8):
        g = random_paths(k, seed=9500 + k, media=True)
        mis = BdptWeights("power", 2.0, strategies=subset, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            got, ref = recursive_weights(g, mis), _reference(g, 2.0, subset)
        worst = max(worst, _max_rel(got, ref))
    print(f"{'+'.join(subset)} with media: max relative error {worst:.2e}")
    assert worst < RTOL


@pytest.mark.parametrize("wrong", ["sigma_t", "transmittance"])
def test_a_wrong_medium_density_is_caught(wrong):
    """Power: a medium vertex's forward density without its sigma_t (p_A = p_W T / d^2), or the
    segment's transmittance left out of the forward density, misses the brute force by orders of
    magnitude more than RTOL."""
    g = random_paths(4, seed=13, media=True)
    mis = BdptWeights("power", 2.0, light_paths=g["light_paths"])
    with np.errstate(all="ignore"):
        err = _max_rel(recursive_weights(g, mis, wrong=wrong), _reference(g, 2.0))
    print(f"{wrong} left out: max relative error {err:.2e}")
    assert err > 1e3 * RTOL
