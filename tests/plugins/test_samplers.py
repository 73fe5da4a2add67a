"""Tests of the lab samplers (plugins/samplers/): distribution, structure, rendering.

Statistical tests use fixed seeds and state their tolerance; every one of them
fails for a sampler that is non-uniform, biased, unstructured or correlated.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import mitsuba_lab  # noqa: F401  (sets the variant, registers the plugins)
import drjit as dr
import mitsuba as mi
from scipy import special, stats
from scipy.stats import qmc

from mitsuba_lab.plugins.samplers.common import sobol_02

LAB = ("lab_independent", "lab_stratified", "lab_halton", "lab_sobol", "lab_zsobol")
QMC = ("lab_halton", "lab_sobol", "lab_zsobol")
#: Per-test significance of the chi-square uniformity tests.
ALPHA = 1e-3
CORNELL = Path(__file__).resolve().parents[2] / "scenes" / "cornell_box.xml"


def make(kind: str, spp: int, **params) -> mi.Sampler:
    return mi.load_dict({"type": kind, "sample_count": spp, **params})


def draw(kind: str, spp: int, n_pixels: int, seed: int, pattern: str = "2212",
         static_dims: bool = True, **params):
    """Seed a wavefront of n_pixels x spp lanes and draw one request per letter
    of ``pattern`` ('1' = next_1d, '2' = next_2d); returns (n_pixels, spp, n_dims).
    ``static_dims=False`` makes the sampler treat every dimension as known only
    to the kernel (the path taken inside an integrator's loop)."""
    if kind == "lab_zsobol":
        params.setdefault("width", int(np.sqrt(n_pixels)))
    s = make(kind, spp, **params)
    s.static_dims = static_dims
    s.seed(seed, n_pixels * spp)
    cols = []
    for c in pattern:
        if c == "1":
            cols.append(s.next_1d())
        else:
            p = s.next_2d()
            cols += [p.x, p.y]
    dr.eval(*cols)                      # one kernel for all requests (one compilation)
    return np.stack([np.array(c) for c in cols], axis=-1).reshape(n_pixels, spp, -1)


# ---------------------------------------------------------------------------
# Exactness against independent implementations
# ---------------------------------------------------------------------------

def test_lab_independent_reproduces_mitsuba_independent():
    """TEA-scrambled state and stream, as Mitsuba's PCG32Sampler: identical numbers."""
    ours, theirs = make("lab_independent", 4), make("independent", 4)
    for s in (ours, theirs):
        s.seed(5, 4096)
    for _ in range(3):
        assert np.array_equal(np.array(ours.next_1d()), np.array(theirs.next_1d()))
        assert np.array_equal(np.array(ours.next_2d()), np.array(theirs.next_2d()))


def test_unscrambled_sobol_equals_scipy():
    """Dimensions 0 and 1, all 2^12 points. scipy enumerates in Gray-code order
    (Antonov & Saleev), so its point i is ours at index i ^ (i >> 1)."""
    m = 12
    i = np.arange(1 << m, dtype=np.uint32)
    x, y = sobol_02(mi.UInt32(i ^ (i >> 1)), m)
    ours = np.stack([np.array(x), np.array(y)], axis=1).astype(np.float64) * 2.0 ** -32
    ref = qmc.Sobol(d=2, scramble=False).random_base2(m)
    assert np.array_equal(ours, ref)


# ---------------------------------------------------------------------------
# Uniformity: chi-square on 1D and 2D histograms, and across dimension pairs
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("kind", LAB)
def test_chi2_uniformity(kind):
    pts = draw(kind, 16, 1024, seed=3).reshape(-1, 7)     # 16384 points, dims 0..6
    bins = 8
    for d in range(7):                                    # 1D marginals, 16 bins
        counts = np.histogram(pts[:, d], bins=16, range=(0, 1))[0]
        assert stats.chisquare(counts).pvalue > ALPHA, (kind, d)
    for a, b in ((0, 1), (2, 3), (5, 6), (0, 2), (1, 5), (3, 4)):   # pairs and cross-pairs
        counts = np.histogram2d(pts[:, a], pts[:, b], bins=bins, range=[[0, 1], [0, 1]])[0]
        assert stats.chisquare(counts.ravel()).pvalue > ALPHA, (kind, a, b)
    assert pts.min() >= 0 and pts.max() < 1


def test_stratified_cells_any_count():
    pts = draw("lab_stratified", 16, 64, seed=1, pattern="21")
    cells = np.floor(pts[..., 0] * 4) + 4 * np.floor(pts[..., 1] * 4)
    assert all(len(set(c)) == 16 for c in cells)            # 4x4 grid: one sample per cell
    assert all(len(set(c)) == 16 for c in np.floor(pts[..., 2] * 16))
    pts = draw("lab_stratified", 8, 64, seed=1, pattern="2")  # off a square: 2x4 grid
    cells = np.floor(pts[..., 0] * 2) + 2 * np.floor(pts[..., 1] * 4)
    assert all(len(set(c)) == 8 for c in cells)


# ---------------------------------------------------------------------------
# Net structure and discrepancy
# ---------------------------------------------------------------------------

def is_02_net(p: np.ndarray) -> bool:
    """True if the 2^m points form a (0,m,2)-net: one point per elementary interval."""
    m = int(np.log2(len(p)))
    q = np.floor(p * (1 << m)).astype(np.int64)
    for a in range(m + 1):
        cell = (q[:, 0] >> (m - a)) * (1 << (m - a)) + (q[:, 1] >> a)
        if len(np.unique(cell)) != len(p):
            return False
    return True


@pytest.mark.parametrize("kind", ("lab_sobol", "lab_zsobol"))
def test_scrambled_sobol_keeps_net_property(kind):
    pts = draw(kind, 256, 16, seed=11, pattern="2212")
    for pixel in pts:
        for pair in ((0, 1), (2, 3), (5, 6)):
            assert is_02_net(pixel[:, pair])
    assert not is_02_net(np.random.default_rng(0).random((256, 2)))   # the check can fail


def test_zsobol_pixel_blocks_are_nets():
    """Ahmed & Wonka: an aligned 2x2 block of pixels holds a 4x larger net."""
    pts = draw("lab_zsobol", 16, 64, seed=2, pattern="22")   # 8x8 pixels
    img = pts.reshape(8, 8, 16, 4)
    for by in range(0, 8, 2):
        for bx in range(0, 8, 2):
            block = img[by:by + 2, bx:bx + 2].reshape(-1, 4)
            assert is_02_net(block[:, :2]) and is_02_net(block[:, 2:])
    sob = draw("lab_sobol", 16, 64, seed=2, pattern="2").reshape(8, 8, 16, 2)
    assert not all(is_02_net(sob[y:y + 2, x:x + 2].reshape(-1, 2)) for y in (0, 2) for x in (0, 2))


@pytest.mark.parametrize("kind", ("lab_sobol", "lab_halton", "lab_zsobol", "lab_stratified"))
def test_star_discrepancy_below_random(kind):
    """L2-star discrepancy at N = 256, mean over 8 pixels, vs 8 random point sets."""
    pts = draw(kind, 256, 16, seed=4, pattern="2")[:8]
    ours = np.mean([qmc.discrepancy(p, method="L2-star") for p in pts])
    rng = np.random.default_rng(4)
    rand = np.mean([qmc.discrepancy(rng.random((256, 2)), method="L2-star") for _ in range(8)])
    limit = 0.7 if kind == "lab_stratified" else 0.5
    assert ours < limit * rand, (ours, rand)


# ---------------------------------------------------------------------------
# Unbiasedness and convergence
# ---------------------------------------------------------------------------

#: f = x0 y0^2 + 3 [x1 + y1 > 1.2] + z^2, integral 1/6 + 3 * 0.32 + 1/3.
EXACT = 1 / 6 + 0.96 + 1 / 3


def integrand(p):
    return p[..., 0] * p[..., 1] ** 2 + 3.0 * (p[..., 2] + p[..., 3] > 1.2) + p[..., 4] ** 2


@pytest.mark.parametrize("kind", LAB)
def test_unbiased_over_seeds(kind):
    """Image-mean estimate over 24 seeds; |z| < 4 (two-sided p ~ 6e-5)."""
    est = np.array([integrand(draw(kind, 16, 64, seed=k, pattern="221")).mean() for k in range(24)])
    z = (est.mean() - EXACT) / (est.std(ddof=1) / np.sqrt(len(est)))
    assert abs(z) < 4.0, (kind, est.mean(), z)
    assert est.std() > 0                         # seeds do give different estimates


SIGMA = 0.15
BUMP = (SIGMA * np.sqrt(2 * np.pi) * (special.ndtr(0.6 / SIGMA) - special.ndtr(-0.4 / SIGMA))) * \
       (SIGMA * np.sqrt(2 * np.pi) * (special.ndtr(0.5 / SIGMA) - special.ndtr(-0.5 / SIGMA)))


def mse_slope(kind: str, spps=(16, 64, 256, 1024), n_pixels=256):
    mses = []
    for spp in spps:
        p = draw(kind, spp, n_pixels, seed=7, pattern="12")[..., 1:]   # the pair after a 1D request
        f = np.exp(-((p[..., 0] - 0.4) ** 2 + (p[..., 1] - 0.5) ** 2) / (2 * SIGMA ** 2))
        mses.append(np.mean((f.mean(axis=1) - BUMP) ** 2))
    return np.polyfit(np.log(spps), np.log(mses), 1)[0]


def test_hash_scramble_matches_exact_owen_on_pixel_integrals():
    """lab_sobol's hash-based scramble integrates random Gaussian bumps and disks (64 spp,
    1024 pixels, 6 seeds) with the MSE of exactly nested uniform scrambling of the same
    points (numpy reference), within 4 standard errors of the ratio; and both beat
    multijitter on the smooth family (their N^-3 rate at work) by more than 2x. A
    digital shift in place of the scramble fails the first check (ratio 1.53)."""
    import sys
    from functools import partial

    sys.path.insert(0, str(CORNELL.parents[1] / "benchmarks"))    # the benchmark's study, checked here
    from pixel_integrals import exact_owen_pair, first_pair, integrand_families, pixel_integral_mse
    families = integrand_families(1024, np.random.default_rng(7))
    seeds = range(6)
    ours = pixel_integral_mse(partial(first_pair, "lab_sobol"), 64, families, seeds)
    exact = pixel_integral_mse(exact_owen_pair, 64, families, seeds)
    mj = pixel_integral_mse(partial(first_pair, "multijitter"), 64, families, seeds)
    for fam in families:
        a, b = np.array(ours[fam]), np.array(exact[fam])
        rel_se = np.hypot(a.std(ddof=1) / a.mean(), b.std(ddof=1) / b.mean()) / np.sqrt(len(a))
        assert abs(np.log(a.mean() / b.mean())) < 4 * rel_se, (fam, a.mean() / b.mean(), rel_se)
    assert np.mean(ours["gaussian"]) < 0.5 * np.mean(mj["gaussian"])


def test_convergence_slopes_on_gaussian_bump():
    """Owen-scrambled Sobol converges like N^-3 on smooth integrands, PCG32 like N^-1."""
    slope_sobol, slope_indep = mse_slope("lab_sobol"), mse_slope("lab_independent")
    assert slope_sobol < -1.5, slope_sobol
    assert -1.25 < slope_indep < -0.75, slope_indep
    assert mse_slope("lab_zsobol") < -1.5


# ---------------------------------------------------------------------------
# Seeds, clone, parameters
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("kind", LAB)
def test_deterministic_seeds_and_clone(kind):
    a, b, c = (draw(kind, 16, 64, seed=s) for s in (9, 9, 10))
    assert np.array_equal(a, b) and not np.allclose(a, c)
    s = make(kind, 16, **({"width": 8} if kind == "lab_zsobol" else {}))
    s.seed(1, 64 * 16)
    s.next_2d()
    twin = s.clone()
    for _ in range(2):
        assert np.array_equal(np.array(s.next_2d()), np.array(twin.next_2d()))
        assert np.array_equal(np.array(s.next_1d()), np.array(twin.next_1d()))
    assert "sample_count=16" in str(s)


@pytest.mark.parametrize("kind", ("lab_stratified", "lab_halton", "lab_sobol", "lab_zsobol"))
@pytest.mark.parametrize("spp", (1, 3, 16, 64, 256))
def test_trace_time_dimensions_give_the_same_numbers(kind, spp):
    """A request whose dimension is known at trace time (before an integrator's loop)
    takes a specialised path (lab_halton unrolls its digit loop); it must return
    exactly what the general path does, here forced with ``static_dims = False``,
    for 70 dimensions (past lab_halton's 64 bases) and both Halton randomisations."""
    variants = ({"randomization": "owen"}, {"randomization": "permute_digits"}) if kind == "lab_halton" else ({},)
    for params in variants:
        known = draw(kind, spp, 16, seed=4, pattern="21" * 23 + "2", **params)
        general = draw(kind, spp, 16, seed=4, pattern="21" * 23 + "2", static_dims=False, **params)
        assert known.shape[-1] == 71
        assert np.array_equal(known, general), params


def test_the_refined_reciprocal_is_correctly_rounded_from_a_few_ulps_off():
    """CUDA's dr.rcp is rcp.approx (up to an ulp off); lab_halton's general path refines it so
    that it equals the trace-time path's correctly rounded constants on a GPU too. Every base,
    from approximations up to 3 ulps either side; without the refinement 6 of 7 would differ."""
    from mitsuba_lab.plugins.samplers.halton import PRIMES, refined_reciprocal

    for b in PRIMES:
        exact = np.float32(1.0 / b)
        approx = [exact]
        for _ in range(3):
            approx = [np.nextafter(approx[0], np.float32(0))] + approx + [np.nextafter(approx[-1], np.float32(1))]
        refined = refined_reciprocal(mi.Float(float(b)), mi.Float(np.array(approx, dtype=np.float32)))
        assert np.array_equal(refined.numpy(), np.full(7, exact)), b
        assert np.count_nonzero(np.array(approx) != exact) == 6


@pytest.mark.parametrize("kind", QMC)
def test_advance_restarts_the_dimensions(kind):
    """A new pass (advance(), as Mitsuba's multi-pass rendering calls it) restarts at
    dimension 0 with a fresh randomisation: dimension 0 is stratified again (16 spp,
    one sample per interval of 1/16 for every QMC sampler), the points differ from
    the first pass, and trace-time and general dimensions still agree."""
    passes = []
    for static in (True, False):
        s = make(kind, 16, **({"width": 4} if kind == "lab_zsobol" else {}))
        s.static_dims = static
        s.seed(6, 16 * 16)
        first = [s.next_2d().x, s.next_1d(), s.next_2d().y]
        s.advance()
        second = [s.next_2d().x, s.next_1d(), s.next_2d().y]
        dr.eval(*first, *second)
        passes.append([np.array(v).reshape(16, 16) for v in first + second])
    known, general = passes
    assert all(np.array_equal(a, b) for a, b in zip(known, general))
    x0 = known[3]
    assert all(len(set(np.floor(px * 16).astype(int))) == 16 for px in x0)
    assert not np.allclose(x0, known[0])


@pytest.mark.parametrize("kind", ("lab_halton", "lab_sobol"))
def test_requests_inside_a_symbolic_loop(kind):
    """Inside a symbolic loop (as in Mitsuba's path integrator) the dimension is a
    loop variable: the loop's draws equal the same requests made in sequence."""
    n, trips = 16 * 64, 3
    s = make(kind, 64)
    s.seed(2, n)
    s.next_2d()                                    # the pixel request, before the loop
    out = dr.zeros(mi.Float, 3 * n * trips)
    lane = dr.arange(mi.UInt32, n)

    def body(k, s):
        p, u = s.next_2d(), s.next_1d()
        for j, v in enumerate((p.x, p.y, u)):
            dr.scatter(out, v, (k * 3 + j) * n + lane)
        return k + 1, s

    dr.while_loop((mi.UInt32(0), s), lambda k, s: k < trips, body)
    looped = np.array(out).reshape(trips * 3, n).T.reshape(16, 64, -1)
    assert np.array_equal(looped, draw(kind, 64, 16, seed=2, pattern="2" + "21" * trips)[..., 2:])


@pytest.mark.parametrize("params, name", [
    ({"type": "lab_sobol", "sample_count": 0}, "sample_count"),
    ({"type": "lab_independent", "seed": -1}, "seed"),
    ({"type": "lab_halton", "randomization": "cranley"}, "randomization"),
    ({"type": "lab_zsobol", "width": -4}, "width"),
])
def test_parameter_errors_name_the_parameter(params, name):
    with pytest.raises(Exception, match=name):
        mi.load_dict(params)


def test_power_of_two_warning():
    s = make("lab_sobol", 12)
    with pytest.warns(UserWarning, match="power of two"):
        s.seed(0, 12 * 4)
    # lab_zsobol on a non-square block without 'width': tests/plugins/test_zsobol_films.py


# ---------------------------------------------------------------------------
# Rendering through Mitsuba's C++ `path` and the lab's `lab_mis`
# ---------------------------------------------------------------------------

def cornell(sampler: str, res: int = 32, spp: int = 16):
    xml = CORNELL.read_text().replace('<sampler type="independent">', f'<sampler type="{sampler}">')
    return mi.load_string(xml, res=res, spp=spp, max_depth=6)


@pytest.fixture(scope="module")
def reference_mean():
    img = mi.render(cornell("independent", spp=1024), seed=1000)
    return float(np.mean(np.array(img)))


@pytest.mark.slow
@pytest.mark.parametrize("kind", LAB)
@pytest.mark.parametrize("integrator", ("path", "lab_mis"))
def test_render_with_sampler(kind, integrator, reference_mean):
    """Image mean within 2% of a 1024-spp reference; one kernel serves every seed."""
    scene = cornell(kind, spp=64)
    integ = mi.load_dict({"type": integrator, "max_depth": 6})
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        hashes = []
        means = []
        for seed in (1, 2):
            dr.kernel_history()
            img = mi.render(scene, integrator=integ, seed=seed)
            dr.eval(img)
            hashes.append({k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT})
            a = np.array(img)
            assert np.isfinite(a).all() and a.min() >= 0
            means.append(a.mean())
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert hashes[0] == hashes[1]                   # no recompilation across seeds
    assert means[0] != means[1]
    assert abs(np.mean(means) / reference_mean - 1) < 0.02


def test_lab_independent_renders_exactly_like_independent():
    ours = np.array(mi.render(cornell("lab_independent"), seed=3))
    theirs = np.array(mi.render(cornell("independent"), seed=3))
    assert np.array_equal(ours, theirs)


def test_halton_permute_digits_uniform_and_unbiased():
    pts = draw("lab_halton", 16, 1024, seed=3, randomization="permute_digits").reshape(-1, 7)
    for a, b in ((0, 1), (2, 3), (5, 6)):
        counts = np.histogram2d(pts[:, a], pts[:, b], bins=8, range=[[0, 1], [0, 1]])[0]
        assert stats.chisquare(counts.ravel()).pvalue > ALPHA, (a, b)
    est = np.array([integrand(draw("lab_halton", 16, 64, seed=k, pattern="221",
                                   randomization="permute_digits")).mean() for k in range(24)])
    z = (est.mean() - EXACT) / (est.std(ddof=1) / np.sqrt(len(est)))
    assert abs(z) < 4.0, z


# ---------------------------------------------------------------------------
# The fast paths: float digit extraction, table-free digit permutations
# ---------------------------------------------------------------------------

@pytest.mark.slow
def test_halton_float_digits_are_exact():
    """floor((n + 1/2) / b) in float32 equals n div b for every n < 2^21 (MAX_SPP) and prime."""
    from mitsuba_lab.plugins.samplers.halton import MAX_SPP, PRIMES
    n = dr.arange(mi.UInt32, MAX_SPP)
    ref = np.arange(MAX_SPP)
    for b in PRIMES:
        base = mi.Float(dr.opaque(mi.UInt32, b))
        inv = dr.rcp(base)
        q = dr.floor(dr.fma(mi.Float(n), inv, 0.5 * inv))
        assert np.array_equal(np.array(mi.UInt32(q)), ref // b), b
        # the constant used where the dimension is known at trace time is the same float
        assert np.float32(1.0 / b) == np.array(inv)[0], b


def test_halton_is_stratified_per_base():
    """Per pixel, b^k samples of the base-b dimension fall one per interval of length b^-k."""
    for spp, dim, base in ((16, 0, 2), (9, 1, 3), (25, 2, 5)):
        for rnd in ("owen", "permute_digits"):
            pts = draw("lab_halton", spp, 32, seed=5, pattern="111", randomization=rnd)[..., dim]
            assert all(len(set(np.floor(p * base ** round(np.log(spp) / np.log(base))))) == spp for p in pts)


def test_zsobol_digit_permutations_cover_s4():
    from mitsuba_lab.plugins.samplers.zsobol import _gf4_permute
    h = dr.arange(mi.UInt32, 64)
    perms = {tuple(np.array(_gf4_permute(mi.UInt32(d), h))[i] for d in range(4)) for i in range(64)}
    assert len(perms) == 24


@pytest.mark.parametrize("spp", (1, 2, 4, 8))
def test_zsobol_index_is_a_block_preserving_bijection(spp):
    """For every dimension the permuted index of the 8x8 x spp lanes is a permutation of
    0..64 spp - 1 that maps each aligned Morton block (a block of base-4 digits: the
    levels are at bit counts of the parity of n_bits) onto an aligned block."""
    s = make("lab_zsobol", spp, width=8)
    s.seed(3, 64 * spp)
    m = np.array(s.morton_index)
    for dim in (0, 2, 7):
        idx = np.array(s._sobol_index(mi.UInt32(dim)))
        assert np.array_equal(np.sort(idx), np.arange(64 * spp))
        for bits in range(s.n_bits % 2 or 2, s.n_bits, 2):
            blocks = {}
            for a, b in zip(m >> bits, idx >> bits):
                assert blocks.setdefault(a, b) == b


# ---------------------------------------------------------------------------
# Keys, the inlined Kensler shuffle, lab_zsobol's padding
# ---------------------------------------------------------------------------

def test_sample_keys_are_distinct_and_balanced():
    """One unit's keys for different dimensions, passes and purposes are all different,
    and every bit of every key is 1 for about half of 4096 units: within 5 standard
    errors (60 keys x 32 bits; family-wise false alarm ~1e-3)."""
    from mitsuba_lab.plugins.samplers.common import (
        JITTER_X, JITTER_Y, PERMUTE, SCRAMBLE_X, SCRAMBLE_Y, sample_key, unit_key)
    n = 4096
    units = unit_key(dr.opaque(mi.UInt32, 17), dr.arange(mi.UInt32, n))
    keys = [sample_key(units, dim, pass_index, purpose)
            for dim in (0, 1, 2, 63, 64) for pass_index in (0, 1)
            for purpose in (None, PERMUTE, SCRAMBLE_X, SCRAMBLE_Y, JITTER_X, JITTER_Y)]
    table = np.stack([np.array(k) for k in keys])                 # (keys, units)
    assert all(len(set(table[:, u])) == len(keys) for u in range(n))
    bits = (table[..., None] >> np.arange(32, dtype=np.uint32)) & 1
    assert np.all(np.abs(bits.mean(axis=1) - 0.5) < 5 * 0.5 / np.sqrt(n))


@pytest.mark.parametrize("n", (2, 4, 16, 64, 256, 1024))
def test_padded_index_is_mitsubas_kensler_permutation(n):
    """The inlined round for power-of-two counts gives mi.permute_kensler's numbers."""
    from mitsuba_lab.plugins.samplers.common import padded_index
    lane = dr.arange(mi.UInt32, n * 256)
    index, seed = lane % n, mi.sample_tea_32(lane // n, mi.UInt32(3))[0]
    assert np.array_equal(np.array(padded_index(index, n, seed)),
                          np.array(mi.permute_kensler(index, n, seed)))


def test_zsobol_dimensions_get_their_own_blocks_and_pairings():
    """Dimension pairs of lab_zsobol are shuffled apart: pixels rarely hold the same block
    of the sequence in dimension 0 and in dimension 2 or 7 (one shared pixel order would
    make neighbours complementary in every dimension at once, a less blue error), and
    the pairing of a pixel's samples across dimensions differs from pixel to pixel."""
    s = make("lab_zsobol", 16, width=8)
    s.seed(3, 64 * 16)
    idx = {d: np.array(s._sobol_index(mi.UInt32(d))).reshape(64, 16) for d in (0, 2, 7)}
    for d in (2, 7):
        assert np.mean(idx[d][:, 0] >> 4 == idx[0][:, 0] >> 4) < 0.25
        pairing = {tuple(idx[d][p][np.argsort(idx[0][p] & 15)] & 15) for p in range(64)}
        assert len(pairing) > 48
