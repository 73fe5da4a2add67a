"""lab_bdpt's equi-angular camera flights (``bdpt/camera_flight.py``) in the MIS weights.

The camera subpaths draw a segment's distance from a mixture (equi-angular towards the lights'
points with probability q, else a free flight), so a segment's density differs by its direction:
the camera's is r times the light's g T (r: ``camera_flight.ratio``). The recursion takes r as
``after_hit``'s ``forward`` on the camera side, ``backward`` on the light side, and on each
connecting segment's light-end cosine (the camera's density of the light vertex).

1. Random paths (test_bdpt_weights.py's, k = 1 .. 7, 4000 a length, medium vertices, a T on every
   segment) with a random r per segment (1e-2 .. 1e2): the recursion equals the brute force over
   p_camera = p_W g T r / d^2 within RTOL (1e-9, float64) and the weights sum to 1.
2. The same paths' vertices placed in a real homogeneous fog (sigma_t 0.3, a point light and an
   area light, q = 0.5), every r and T evaluated by the module in float32 from the vertices, as
   the subpaths evaluate them: the weights sum to 1 within 1e-4.
Power: q dropped on the light side (its reverse densities from free flights, r = 1) or the
camera's own r left out of a connection misses the sum by far more than its tolerance.
3. The flight's sampled distances follow the density ``ratio`` reports: a chi-square test of
   200 000 flights' outcomes (20 distance bins and the surface) against the mixture's
   probabilities, p > 1e-4; power: the same test against the free flight's probabilities fails.
"""
import numpy as np
import pytest

import drjit as dr
import mitsuba as mi
from test_bdpt_weights import N, RTOL, _max_rel, random_paths
from mitsuba_lab.plugins.integrators.bdpt import camera_flight
from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights, brute_force_weights, feasible

TOL = 1e-4


def mixture_weights(g, mis, r_cam, r_light=None, r_connect=None, rho=None, rho_light=None):
    """Every strategy's weight by the recursion with the camera's density ratio ``r_cam[i]`` of
    segment i (x_i x_{i+1}) walked from x_{i+1}; ``r_light``: the light side's value of it
    (default the same), ``r_connect``: the connections' (default the same). ``rho``: equi-angular
    NEE's density over s = 1's (at x_1; None: no such technique), an extra last row of weights;
    ``rho_light``: the light side's value of it (default the same)."""
    k = g["d2"].shape[0]
    rho_light = rho if rho_light is None else rho_light
    r_light = r_cam if r_light is None else r_light
    r_connect = r_cam if r_connect is None else r_connect
    d2, cl, cc, fw, rv, delta, T = g["d2"], g["cos_l"], g["cos_c"], g["to_cam"], g["to_light"], g["delta"], g["T"]
    pdf_emit = g["pos"] * fw[0]
    light = {}
    state = mis.start_light(pdf_emit, g["nee"], cc[0], delta[0])
    carried = None
    for i in range(1, k):
        state = mis.after_hit(state, d2[i - 1], cl[i], T[i - 1], backward=r_light[i - 1])
        if carried is not None:
            state = mis.add_equiangular(state, mis.after_hit(carried, d2[i - 1], cl[i], T[i - 1],
                                                             backward=r_light[i - 1]), rho_light)
            carried = None
        light[i] = state
        if i == 1 and rho is not None:
            carried = mis.equiangular_term(state, fw[i], cc[i], delta[i])
        state = mis.scatter_light(state, fw[i], rv[i], cc[i], delta[i])
    camera = {}
    state = mis.start_camera(rv[k], delta[k])
    for i in range(k - 1, -1, -1):
        state = mis.after_hit(state, d2[i], cc[i], T[i], forward=r_cam[i])
        camera[i] = state
        if i > 0:
            state = mis.scatter_camera(state, rv[i], fw[i], cl[i], delta[i], depth=k - i)
    w = np.zeros((k + 2, N))
    rc = r_connect
    eq = {} if rho is None or k < 2 else {"rho": rho}       # (x_1 is the sensor when k = 1)
    for s in range(k + 1):
        t = k + 1 - s
        at_1 = eq if s == 2 else {}                          # (a light subpath's first vertex)
        if s == 0:
            w[s] = mis.hit(camera[0], g["nee"], pdf_emit, g["pos"], **eq)
        elif t == 1 and s == 1:
            w[s] = mis.emitter_to_camera(rv[1], cc[0] * T[0] * rc[0], d2[0], g["pos"], delta[0])
        elif s == 1:
            w[s] = mis.nee(camera[1], g["nee"], pdf_emit, cc[0] * T[0] * rc[0], cl[1] * T[0], d2[0], rv[1], fw[1],
                           delta[0], depth=k - 1, **eq)
            if eq:
                w[k + 1] = w[s] * mis._m(rho)
        elif t == 1:
            w[s] = mis.light_to_camera(light[k - 1], rv[k], cc[k - 1] * T[k - 1] * rc[k - 1], d2[k - 1], rv[k - 1],
                                       **at_1)
        else:
            w[s] = mis.connect(light[s - 1], camera[s], fw[s - 1], rv[s - 1], rv[s], fw[s],
                               cc[s - 1] * T[s - 1] * rc[s - 1], cl[s] * T[s - 1], d2[s - 1], depth=k - s, **at_1)
    ok = np.concatenate([feasible(delta), feasible(delta)[1:2]])
    return np.where(ok, w, 0.0)


def reference(g, beta, r_cam, rho=None):
    """The brute force over p_camera with r; with ``rho``, equi-angular NEE's row (density s = 1's
    times rho) last, computed here directly."""
    k = g["d2"].shape[0]
    p_light, p_camera = np.empty((k + 1, N)), np.empty((k + 1, N))
    p_light[0] = g["pos"]
    for i in range(1, k + 1):
        p_light[i] = g["to_cam"][i - 1] * g["cos_l"][i] * g["T"][i - 1] / g["d2"][i - 1]
    p_camera[k] = 1.0
    for i in range(k):
        p_camera[i] = g["to_light"][i + 1] * g["cos_c"][i] * g["T"][i] * r_cam[i] / g["d2"][i]
    if rho is None or k < 2:
        w = brute_force_weights(p_light, p_camera, g["delta"], beta, "all", g["nee"], g["light_paths"])
        return np.concatenate([w, np.zeros((1, N))])
    ok = feasible(g["delta"])
    logs = []
    for s in range(k + 1):
        log_p = np.log(p_light[:s]).sum(axis=0) + np.log(p_camera[s:]).sum(axis=0)
        if s == 1:
            log_p += np.log(g["nee"]) - np.log(p_light[0])
        if s == k:
            log_p += np.log(g["light_paths"])
        logs.append(np.where(ok[s], beta * log_p, -np.inf))
    logs.append(np.where(ok[1], logs[1] + beta * np.log(rho), -np.inf))
    logs = np.array(logs)
    top = logs.max(axis=0)
    terms = np.exp(logs - np.where(np.isfinite(top), top, 0.0))
    return terms / np.maximum(terms.sum(axis=0), 1e-300)


@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_direction_dependent_densities_equal_brute_force(beta):
    worst, worst_sum = 0.0, 0.0
    for k in range(1, 8):
        g = random_paths(k, seed=4600 + 10 * k + int(beta), media=True)
        r = np.exp(np.random.default_rng(k).uniform(np.log(1e-2), np.log(1e2), (k, N)))
        mis = BdptWeights("power", beta, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            got = mixture_weights(g, mis, r)
            ref = reference(g, beta, r)
        worst = max(worst, _max_rel(got, ref))
        buildable = feasible(g["delta"]).any(axis=0)
        worst_sum = max(worst_sum, float(np.abs(got.sum(axis=0)[buildable] - 1.0).max()))
    print(f"beta={beta}: max relative error vs brute force {worst:.2e}, max |sum - 1| {worst_sum:.2e}")
    assert worst < RTOL and worst_sum < RTOL


@pytest.mark.parametrize("beta", [1.0, 2.0])
def test_equiangular_nee_equals_brute_force(beta):
    """A second s = 1 technique (equi-angular NEE, density s = 1's times rho at x_1) with r on
    every segment: equal to the brute force over all k + 2 techniques, summing to 1."""
    worst, worst_sum = 0.0, 0.0
    for k in range(1, 8):
        g = random_paths(k, seed=4700 + 10 * k + int(beta), media=True)
        rng = np.random.default_rng(50 + k)
        r = np.exp(rng.uniform(np.log(1e-2), np.log(1e2), (k, N)))
        rho = np.exp(rng.uniform(np.log(1e-3), np.log(1e3), N))
        mis = BdptWeights("power", beta, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            got = mixture_weights(g, mis, r, rho=rho)
            ref = reference(g, beta, r, rho)
        worst = max(worst, _max_rel(got, ref))
        buildable = feasible(g["delta"]).any(axis=0)
        worst_sum = max(worst_sum, float(np.abs(got.sum(axis=0)[buildable] - 1.0).max()))
    print(f"beta={beta}: max relative error vs brute force {worst:.2e}, max |sum - 1| {worst_sum:.2e}")
    assert worst < RTOL and worst_sum < RTOL


def test_equiangular_nee_left_out_of_the_light_side_is_caught():
    """Power: the light side without equi-angular NEE's term (rho = 0 there)."""
    g = random_paths(4, seed=17, media=True)
    rng = np.random.default_rng(3)
    r = np.ones((4, N))
    rho = np.exp(rng.uniform(np.log(1e-1), np.log(1e1), N))
    mis = BdptWeights("power", 2.0, light_paths=g["light_paths"])
    with np.errstate(all="ignore"):
        got = mixture_weights(g, mis, r, rho=rho, rho_light=0.0 * rho)
    buildable = feasible(g["delta"]).any(axis=0)
    err = float(np.abs(got.sum(axis=0)[buildable] - 1.0).max())
    print(f"light side without rho: max |sum - 1| {err:.2e}")
    assert err > 1e3 * RTOL


# -- r and T from a real fog ------------------------------------------------------------------
SIGMA_T = 0.3


def fog_scene(**shapes):
    return mi.load_dict({
        "type": "scene", **shapes,
        "point": {"type": "point", "position": [0.2, 1.5, -0.4], "intensity": {"type": "rgb", "value": 5.0}},
        "area": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([1.0, 2.0, 0.5]),
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 2.0}}},
    })


@pytest.fixture(scope="module")
def fog():
    """(a scene with a point light and an area light, a homogeneous fog around them)."""
    return fog_scene(), mi.load_dict({"type": "homogeneous", "sigma_t": SIGMA_T, "albedo": 0.8})


def _points(a):
    return mi.Point3f(*(mi.Float(np.ascontiguousarray(c, dtype=np.float32)) for c in a))


def fog_paths(k, seed, scene, medium, q=0.5, light_q=None):
    """``random_paths(k, media=True)`` with vertices in a 4-unit box of fog: T = exp(-sigma_t d),
    a medium vertex's g = sigma_t, d2 from the points, and r of every segment from the module
    (``light_q``: the light side's q, for the power check)."""
    g = random_paths(k, seed, media=True)
    rng = np.random.default_rng(seed + 7)
    x = rng.uniform(-2.0, 2.0, (3, k + 1, N))
    d = np.linalg.norm(x[:, 1:] - x[:, :-1], axis=0)
    g["d2"] = np.where(g["infinite"][None] & (np.arange(k)[:, None] == 0), 1.0, d * d)
    medium_vertex = g["medium"]
    g["cos_l"] = np.where(medium_vertex, SIGMA_T, g["cos_l"])
    g["cos_c"] = np.where(medium_vertex, SIGMA_T, g["cos_c"])
    g["T"] = np.exp(-SIGMA_T * d)

    def r_of(q_side):
        mix = camera_flight.EquiangularMixture(scene, q_side)
        n = k * N
        on = dr.full(mi.Bool, True, n)
        ptr = dr.select(on, mi.MediumPtr(medium), dr.zeros(mi.MediumPtr))
        o, end = _points(x[:, 1:].reshape(3, -1)), _points(x[:, :-1].reshape(3, -1))
        collides = mi.Bool(np.ascontiguousarray(medium_vertex[:-1].reshape(-1)))
        wavelengths = dr.zeros(mi.Ray3f, n).wavelengths
        r = camera_flight.ratio(mix, ptr, o, end, collides, wavelengths, dr.zeros(mi.UInt32, n), on)
        return np.broadcast_to(np.asarray(r, dtype=np.float64), (n,)).reshape(k, N)

    r_cam = r_of(q)
    r_light = r_cam if light_q is None else r_of(light_q)
    return g, r_cam, r_light


def _fog_sums(fog, light_q=None, connect_one=False):
    worst, spread = 0.0, []
    for k in range(1, 7):
        g, r_cam, r_light = fog_paths(k, 5200 + k, *fog, light_q=light_q)
        spread.append(r_cam)
        mis = BdptWeights("power", 2.0, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            w = mixture_weights(g, mis, r_cam, r_light, np.ones_like(r_cam) if connect_one else None)
        buildable = feasible(g["delta"]).any(axis=0)
        worst = max(worst, float(np.abs(w.sum(axis=0)[buildable] - 1.0).max()))
    return worst, np.concatenate([s.reshape(-1) for s in spread])


def test_fog_densities_give_weights_that_sum_to_one(fog):
    worst, r = _fog_sums(fog)
    print(f"r from {r.min():.3g} to {r.max():.3g}; max |sum - 1| {worst:.2e}")
    assert worst < TOL and r.max() > 5 and r.min() < 0.9


@pytest.mark.parametrize("mistake", ["light side without q", "connections without r"])
def test_a_wrong_mixture_density_is_caught(fog, mistake):
    worst, _ = _fog_sums(fog, light_q=0.0 if mistake == "light side without q" else None,
                         connect_one=mistake == "connections without r")
    print(f"{mistake}: max |sum - 1| {worst:.2e}")
    assert worst > 100 * TOL


# -- the flight samples the density ratio() reports -------------------------------------------
def _flight_outcomes(scene, medium, q, n=200_000, t_max=6.0):
    mix = camera_flight.EquiangularMixture(scene, q)
    rng = mi.PCG32(n)
    on = dr.full(mi.Bool, True, n)
    ptr = dr.select(on, mi.MediumPtr(medium), dr.zeros(mi.MediumPtr))
    o = mi.Point3f(-1.5, 1.0, 0.3)
    d = dr.normalize(mi.Vector3f(1.0, 0.2, -0.3))
    ray = mi.Ray3f(dr.zeros(mi.Point3f, n) + o, dr.zeros(mi.Vector3f, n) + d)
    exact = (dr.zeros(mi.MediumInteraction3f, n), dr.zeros(mi.Bool, n), dr.zeros(mi.UnpolarizedSpectrum, n),
             dr.zeros(mi.Float, n))
    mei, scattered, weight, _ = camera_flight.flight(mix, ptr, ray, mi.Float(t_max), rng.next_float32(),
                                                     rng.next_float32(), dr.zeros(mi.UInt32, n), on, exact)
    t = np.where(np.asarray(scattered), np.asarray(mei.t), np.inf)
    edges = np.linspace(0.0, t_max, 21)
    counts = np.append(np.histogram(t[np.isfinite(t)], edges)[0], np.isinf(t).sum())
    # the density ratio() reports times the free flight's, integrated per bin (midpoint rule, 64 a bin)
    fine = np.linspace(0.0, t_max, 20 * 64 + 1)
    mid = 0.5 * (fine[1:] + fine[:-1])
    m = mid.size
    pts = dr.zeros(mi.Point3f, m) + o + dr.zeros(mi.Vector3f, m) + d * mi.Float(mid.astype(np.float32))
    on_m = dr.full(mi.Bool, True, m)
    ptr_m = dr.select(on_m, mi.MediumPtr(medium), dr.zeros(mi.MediumPtr))
    wl = dr.zeros(mi.Ray3f, m).wavelengths
    r = np.asarray(camera_flight.ratio(mix, ptr_m, dr.zeros(mi.Point3f, m) + o, pts, dr.full(mi.Bool, True, m), wl,
                                       dr.zeros(mi.UInt32, m), on_m), dtype=np.float64)
    density = r * SIGMA_T * np.exp(-SIGMA_T * mid)
    p_bins = (density * (fine[1] - fine[0])).reshape(20, 64).sum(axis=1)
    surface = dr.zeros(mi.Point3f, 1) + o + d * t_max
    r_s = float(camera_flight.ratio(mix, dr.select(dr.full(mi.Bool, True, 1), mi.MediumPtr(medium),
                                                   dr.zeros(mi.MediumPtr)),
                                    dr.zeros(mi.Point3f, 1) + o, surface, dr.zeros(mi.Bool, 1),
                                    dr.zeros(mi.Ray3f, 1).wavelengths, dr.zeros(mi.UInt32, 1),
                                    dr.full(mi.Bool, True, 1))[0])
    p = np.append(p_bins, r_s * np.exp(-SIGMA_T * t_max))
    p_free = np.append(SIGMA_T * np.exp(-SIGMA_T * mid).reshape(20, 64).sum(axis=1) * (fine[1] - fine[0]),
                       np.exp(-SIGMA_T * t_max))
    return counts, p, p_free


def _chi2_p(counts, p):
    from scipy.stats import chisquare

    expected = counts.sum() * p / p.sum()
    return chisquare(counts, expected).pvalue, abs(p.sum() - 1.0)


def test_flights_follow_the_reported_density(fog):
    counts, p, p_free = _flight_outcomes(*fog, 0.5)
    pvalue, mass = _chi2_p(counts, p)
    wrong, _ = _chi2_p(counts, p_free)
    print(f"chi-square p {pvalue:.3g} (mass off 1 by {mass:.1e}); against free flights' p {wrong:.3g}")
    assert pvalue > 1e-4 and mass < 2e-3 and wrong < 1e-10


# -- equi-angular NEE's rho from a real fog, and its draws ------------------------------------
def test_rho_from_both_ends_gives_weights_that_sum_to_one(fog):
    """rho of x_1 evaluated as the camera does (the piece's end: a ray from x_2 through x_1 to a
    floor plane at y = -3) and as the light side does (|x_2 - x_1| plus ``beyond`` x_1): the
    weights of all k + 2 techniques sum to 1 within TOL (float32 geometry) on every path whose
    segment x_2 x_1 is unoccluded."""
    scene = fog_scene(floor={"type": "rectangle", "bsdf": {"type": "diffuse"},
                             "to_world": mi.ScalarTransform4f().translate([0, -3, 0]).rotate([1, 0, 0], -90).scale(50)})
    mix = camera_flight.EquiangularMixture(scene, 0.0, nee="all")
    medium = fog[1]
    worst, positive = 0.0, 0
    for k in range(2, 7):
        g, _, _ = fog_paths(k, 5300 + k, *fog)
        rng = np.random.default_rng(k)
        x1 = rng.uniform(-2.0, 2.0, (3, N)).astype(np.float32)
        x2 = x1 + rng.normal(0.0, 1.0, (3, N)).astype(np.float32)
        x2[1] = np.abs(x2[1]) + 0.1 + x1[1]                   # x_2 above x_1: the ray goes down to the floor
        on = dr.full(mi.Bool, True, N)
        ptr = dr.select(on, mi.MediumPtr(medium), dr.zeros(mi.MediumPtr))
        wl, ch = dr.zeros(mi.Ray3f, N).wavelengths, dr.zeros(mi.UInt32, N)
        p1, p2 = _points(x1), _points(x2)
        d = dr.normalize(p1 - p2)
        t_cam = scene.ray_intersect_preliminary(mi.Ray3f(p2, d), active=on).t
        t_light = dr.norm(p1 - p2) + camera_flight.beyond(scene, p1, d, on)
        visible = np.asarray(t_cam > dr.norm(p1 - p2))      # (a segment through the area light: no path)
        rho_c = np.asarray(camera_flight.rho(mix, ptr, p2, p1, t_cam, 1.0, wl, ch, on), dtype=np.float64)
        rho_l = np.asarray(camera_flight.rho(mix, ptr, p2, p1, t_light, 1.0, wl, ch, on), dtype=np.float64)
        positive += int((rho_c > 0).sum())
        g["medium"][1] = True
        mis = BdptWeights("power", 2.0, light_paths=g["light_paths"])
        with np.errstate(all="ignore"):
            w = mixture_weights(g, mis, np.ones((k, N)), rho=rho_c, rho_light=rho_l)
        buildable = feasible(g["delta"]).any(axis=0) & visible
        worst = max(worst, float(np.abs(w.sum(axis=0)[buildable] - 1.0).max()))
    print(f"{positive} paths with rho > 0; max |sum - 1| {worst:.2e}")
    assert worst < TOL and positive > 10000


def test_equiangular_nee_draws_follow_its_density(fog):
    """``_eq_draw``'s distances over [0, 6] from a point passing the point light: a chi-square test
    of 200 000 draws in 20 bins against ``eq_density`` integrated per bin (midpoint rule, 256 points a
    bin), p > 1e-4; power: against
    the uniform density it fails."""
    scene, _ = fog
    mix = camera_flight.EquiangularMixture(scene, 0.0, nee="all")
    n, t_s = 200_000, 6.0
    rng = mi.PCG32(n)
    o = dr.zeros(mi.Point3f, n) + mi.Point3f(-1.5, 1.0, 0.3)
    d = dr.zeros(mi.Vector3f, n) + dr.normalize(mi.Vector3f(1.0, 0.2, -0.3))
    t, p = camera_flight._eq_draw(mix, o, d, mi.Float(t_s), rng.next_float32(), rng.next_float32())
    t, p = np.asarray(t), np.asarray(p)
    counts = np.histogram(t[p > 0], np.linspace(0.0, t_s, 21))[0]
    fine = np.linspace(0.0, t_s, 20 * 256 + 1)
    mid = mi.Float((0.5 * (fine[1:] + fine[:-1])).astype(np.float32))
    m = dr.width(mid)
    dens = np.asarray(camera_flight.eq_density(mix, dr.zeros(mi.Point3f, m) + mi.Point3f(-1.5, 1.0, 0.3),
                                               dr.zeros(mi.Vector3f, m) + dr.normalize(mi.Vector3f(1.0, 0.2, -0.3)),
                                               mid, mi.Float(t_s)), dtype=np.float64)
    # only the point light's share draws (P(e) of the finite emitters, here both)
    p_bins = (dens * (fine[1] - fine[0])).reshape(20, 256).sum(axis=1)
    pvalue, mass = _chi2_p(counts, p_bins)
    wrong, _ = _chi2_p(counts, np.ones(20))
    print(f"chi-square p {pvalue:.3g}; mass {p_bins.sum():.4f}; against uniform p {wrong:.3g}")
    assert pvalue > 1e-4 and abs(p_bins.sum() - 1.0) < 2e-3 and wrong < 1e-10
