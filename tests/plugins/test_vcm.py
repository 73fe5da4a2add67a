"""lab_vcm: vertex connection and merging.

* Exact: ``mode = bpt`` renders lab_bdpt's image, ``lt`` lab_bdpt's light tracing and ``pt``
  lab_mis's image (same seed, same code path; float atomics in the splats give ~1e-6).
* In expectation: with a small merging radius (r_1 = 0.02 on scenes 2-5 units across, so the
  blur's bias is far below the noise of 16 seeds x 16 iterations) ``vcm`` and ``bpm`` agree
  with Mitsuba's ``path`` by the z-test of the other agreement tests (|z| <= Z_BOUND = 5 on 3x3
  blocks of 8x8 pixels and on the image means); the merging estimate's normalisation times 1.10
  fails it (power; benchmarks/power/test_bdpt_vcm_power.py). The same with and without ``merge_first`` (merging at the camera's first
  vertex, Georgiev et al.'s VCM, or not: lab_vcm's default).
* With ``aim`` 0.9 (most light subpaths sent at the glass sphere) ppm and bpm, where merging
  carries the direct light too, agree with ``path`` by the block test; weights that leave out
  the mixture's cosine share fail it (power).
* Consistency: with a large first radius the bias is plain (blur at the box's edges and
  corners) and shrinks as the radius shrinks with the iterations; the Epanechnikov kernel (the
  default) blurs less than the constant one at the same radius, and both agree with `path`.
* No NaN, Inf or negative pixel on the stiff scenes; bad parameters are one line.
"""
import functools
import os

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from agreement import Z_BOUND, assert_agrees, path_reference, pixel_problem, renders, z_scores
from backend import HOME, variant
from mitsuba_lab.scene import load_scene, make_integrator

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
RES = 24
SEEDS_LAB = range(16)
SEEDS_REF = range(1000, 1016)
MAX_DEPTH = 8
SMALL_RADIUS = 0.02


def scene_path(name):
    return os.path.join(ROOT, "scenes", name)


def vcm(**params):
    # (the estimator itself: no pilot choosing path tracing instead, unless a test asks)
    return make_integrator("lab_vcm", {"max_depth": MAX_DEPTH, "pilot": False, **params})


def render(scene, integrator, spp=4, seed=3):
    return np.array(mi.render(scene, integrator=integrator, spp=spp, seed=seed))


@pytest.mark.parametrize("name", ["cornell_box.xml", "caustic.xml", "stiff/light_in_glass.xml"])
def test_modes_without_merging_are_lab_bdpt_and_lab_mis(name):
    scene = load_scene(scene_path(name), res=RES)
    bdpt = {"max_depth": MAX_DEPTH}               # (defaults: bpt and lt aim as lab_bdpt does, 0.5)
    pairs = (("bpt", make_integrator("lab_bdpt", bdpt)),
             ("lt", make_integrator("lab_bdpt", {**bdpt, "strategies": "light"})),
             ("pt", make_integrator("lab_mis", bdpt)))
    for mode, other in pairs:
        np.testing.assert_allclose(render(scene, vcm(mode=mode)), render(scene, other), rtol=2e-4, atol=1e-5,
                                   err_msg=f"mode={mode} on {name}")


def path_stack(name, spp=64):
    """`path` on scenes/``name`` at RES, spp x SEEDS_REF: rendered once per run and variant
    (``agreement.path_reference``; the same stack serves test_bdpt, test_vcm, test_aim)."""
    return path_reference(name, RES, spp, MAX_DEPTH, SEEDS_REF)


#: Every mode and merge_first setting once, the modes that merge most (ppm, vcm) on the caustic:
#: 5 of the 10 (scene x mode) cases; the other 5, and the kernel and light_paths cases' other
#: scene, run in benchmarks/agreement/test_vcm_matrix.py.
MERGING_CASES = [("caustic.xml", "vcm", True), ("cornell_box.xml", "bpm", True), ("caustic.xml", "ppm", True),
                 ("cornell_box.xml", "vcm", False), ("caustic.xml", "bpm", False)]
MOVED_MERGING_CASES = [(n, m, f) for n in ("cornell_box.xml", "caustic.xml")
                       for m, f in (("vcm", True), ("bpm", True), ("ppm", True), ("vcm", False), ("bpm", False))
                       if (n, m, f) not in MERGING_CASES]


@pytest.mark.parametrize("name, mode, merge_first", MERGING_CASES)
def test_merging_agrees_with_mitsuba_path(name, mode, merge_first):
    """merge_first = false: no merging at the camera's first vertex, in the techniques or in the
    weights (a sum that still counted it would darken what the camera sees directly)."""
    scene = load_scene(scene_path(name), res=RES)
    lab = renders(scene, vcm(mode=mode, radius=SMALL_RADIUS, merge_first=merge_first), 16, SEEDS_LAB)
    assert_agrees(lab, path_stack(name), f"lab_vcm mode={mode}, merge_first={merge_first} on {name}")


#: Light subpaths per camera subpath for the aimed block tests: enough merges in every block.
AIMED_LIGHT_PATHS = 16


@functools.lru_cache(maxsize=None)
def caustic_block_reference():
    """`path` on the caustic for the block test: BLOCK_SEEDS renders of 16 spp."""
    from agreement import BLOCK_SEEDS

    scene = load_scene(scene_path("caustic.xml"), res=RES)
    return renders(scene, make_integrator("path", {"max_depth": MAX_DEPTH}), 16, range(1000, 1000 + BLOCK_SEEDS))


def aimed_merges(mode):
    """``mode`` (ppm or bpm) with ``aim`` 0.9 on the caustic: BLOCK_SEEDS renders of 4 iterations."""
    from agreement import BLOCK_SEEDS

    scene = load_scene(scene_path("caustic.xml"), res=RES)
    integrator = vcm(mode=mode, radius=SMALL_RADIUS, merge_first=True, aim=0.9, light_paths=AIMED_LIGHT_PATHS)
    return renders(scene, integrator, 4, range(BLOCK_SEEDS))


@pytest.mark.parametrize("mode", ["ppm", "bpm"])
def test_merging_aimed_light_vertices_agrees_with_mitsuba_path(mode):
    """Aim 0.9 where merging carries the direct light too (ppm: merging alone; bpm: merging and
    emitter hits under MIS) agrees with `path` by the block test.

    With aim 0.9 only a tenth of the light subpaths leave the light unaimed, each with ten
    times the weight, and they alone bring the direct light to the floor and wall right of the
    sphere. At one light subpath per camera subpath (576 per iteration, r = 0.02) a block there
    reads above 0.05 (about half its mean) in 3-6% of the renders (30-39% without aim), and the
    top 5% of the renders hold 94-98% of its sum: too heavy a tail for the block test's normal
    approximation. Seeds 0-63 then read 3-9% of `path` in two blocks (|z| 88), seeds 128-191
    pass, and 2048 other seeds read 1.01 of the unaimed image in the blocks' right column
    (z 0.2): no bias, too few merges. ``AIMED_LIGHT_PATHS`` light subpaths per camera subpath
    give every block enough."""
    from agreement import assert_blocks_agree

    assert_blocks_agree(aimed_merges(mode), caustic_block_reference(), f"lab_vcm {mode} aim=0.9 on caustic.xml")


def test_aimed_light_vertices_without_the_mixture_density_are_caught(monkeypatch):
    """Power: light subpaths weighted as if their direction had the cosine density plus the aimed
    one, without the cosine share's (1 - aim), carry a tenth of the light that leaves unaimed."""
    from agreement import block_test
    from mitsuba_lab.plugins.integrators.common import aim as aim_module

    aimed = aim_module.AimedEmission._aimed_pdf
    monkeypatch.setattr(aim_module.AimedEmission, "pdf",
                        lambda self, cos_out, y, d: cos_out * dr.inv_pi + aimed(self, y, d))

    result = block_test(aimed_merges("ppm"), caustic_block_reference())
    print(f"without the mixture density: {result.summary()}")
    assert result.failing


CORNELL_RADIUS = 0.3


@pytest.mark.parametrize("name", ["cornell_box.xml", "caustic.xml"])
def test_caustic_merges_agree_with_mitsuba_path(name):
    """merge_vertices = caustic: merging only light vertices reached through a delta lobe, and
    counted as a technique only there. The Cornell box has no delta lobe, so nothing merges (the
    image is unbiased at any radius: here 0.3, a sixth of the box, with ``merge_first``, where
    merges in the weights would take much of the light); the caustic scene's glass gives merges
    on the floor under it."""
    scene = load_scene(scene_path(name), res=RES)
    radius = CORNELL_RADIUS if name == "cornell_box.xml" else SMALL_RADIUS
    # (aim 0: with mode vcm's default aim most light subpaths pass the glass, and the share of
    # caustic vertices below says nothing about the selection)
    integrator = vcm(radius=radius, merge_vertices="caustic", merge_first=True, aim=0.0)
    lab = renders(scene, integrator, 16, SEEDS_LAB)
    stats = integrator.bdpt_stats()
    print(f"{name}: {stats['merging_vertices']} of {stats['light_vertices_stored']} stored light vertices merge")
    if name == "cornell_box.xml":
        assert stats["merging_vertices"] == 0
    else:
        assert 0 < stats["merging_vertices"] < stats["light_vertices_stored"] / 2
    assert_agrees(lab, path_stack(name), f"lab_vcm merge_vertices=caustic on {name}")


def test_caustic_merges_with_every_vertex_in_the_grid_are_caught(monkeypatch):
    """Power: a grid that still holds every light vertex, while the weights count merging only
    after a delta lobe, adds the merges of the Cornell box's diffuse light on top of the other
    techniques' full share of it."""
    from mitsuba_lab.plugins.integrators.vcm import merging

    built = merging.VertexGrid.__init__

    def every_vertex(self, vertices, *args, **kwargs):
        caustic, vertices.caustic = vertices.caustic, False
        built(self, vertices, *args, **kwargs)
        vertices.caustic = caustic

    monkeypatch.setattr(merging.VertexGrid, "__init__", every_vertex)
    scene = load_scene(scene_path("cornell_box.xml"), res=RES)
    lab = renders(scene, vcm(radius=CORNELL_RADIUS, merge_vertices="caustic", merge_first=True), 16, SEEDS_LAB)
    result = z_scores(lab, path_stack("cornell_box.xml"))
    print(f"every vertex in the grid: max |z| {result.max_abs_z:.1f}, relative difference {result.rel_diff.round(3)}")
    assert result.max_abs_z > Z_BOUND


@pytest.mark.parametrize("name", ["caustic.xml"])       # (both scenes: benchmarks/agreement/test_vcm_matrix.py)
def test_the_constant_kernel_agrees_with_mitsuba_path(name):
    """kernel = constant (SmallVCM's 1 / (pi r^2)) in bpm, merging at every camera vertex, where
    merging carries most of the image; the default Epanechnikov kernel is every other test's."""
    scene = load_scene(scene_path(name), res=RES)
    lab = renders(scene, vcm(mode="bpm", radius=SMALL_RADIUS, merge_first=True, kernel="constant"), 16, SEEDS_LAB)
    assert_agrees(lab, path_stack(name), f"lab_vcm bpm, constant kernel, on {name}")


@pytest.mark.parametrize("name", ["caustic.xml"])       # (both scenes: benchmarks/agreement/test_vcm_matrix.py)
def test_more_light_paths_agree_with_mitsuba_path(name):
    """light_paths = 4: four light subpaths per camera subpath in each iteration, all merged with
    (merging density pi r^2 N with N four times larger) and all splatting."""
    scene = load_scene(scene_path(name), res=RES)
    integrator = vcm(radius=SMALL_RADIUS, light_paths=4)
    lab = renders(scene, integrator, 16, SEEDS_LAB)
    assert integrator.bdpt_stats()["light_subpaths"] == 4 * RES * RES * 16
    assert_agrees(lab, path_stack(name), f"lab_vcm light_paths=4 on {name}")


@pytest.mark.parametrize("name", ["cornell_box.xml"])       # (both scenes: benchmarks/agreement/test_vcm_matrix.py)
def test_fewer_light_paths_agree_with_mitsuba_path(name):
    """light_paths = 1/4: a quarter as many light subpaths as camera subpaths in each iteration
    (merging density pi r^2 N with N a quarter of the camera's; camera subpaths share each light
    subpath's connections), 16 iterations in one pass: 576 x 16 / 4, a multiple of the 16."""
    scene = load_scene(scene_path(name), res=RES)
    integrator = vcm(radius=SMALL_RADIUS, light_paths=0.25)
    lab = renders(scene, integrator, 16, SEEDS_LAB)
    assert integrator.bdpt_stats()["light_subpaths"] == 576 * 16 // 4
    assert_agrees(lab, path_stack(name), f"lab_vcm light_paths=1/4 on {name}")


@pytest.mark.parametrize("pixels, spp, light_paths", [(576, 16, 0.25), (4096, 64, 1 / 64), (4096, 7, 0.3),
                                                      (1000, 3, 0.5), (576, 16, 1.0)])
def test_a_camera_lane_connects_to_a_light_subpath_of_its_own_iteration(pixels, spp, light_paths):
    """Camera lane i connects to light subpath i mod N; both must belong to the same iteration of
    the pass (the one whose radius and N_k the lane's weights use)."""
    from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights

    integrator = vcm(light_paths=light_paths)
    lanes = pixels * spp
    count = integrator.passes.light_subpaths(max(1, round(lanes * light_paths)), spp, lanes)
    assert 0 < count <= max(round(lanes * light_paths), spp) and count % spp == 0
    weights = BdptWeights("power", 2.0, "all")
    weights.lane_tables = (None, None, mi.UInt32(spp))
    lane = dr.arange(mi.UInt32, lanes)
    own, light = weights.lane_iteration(lane), weights.lane_iteration(lane % count)
    assert dr.all(own == light), f"{dr.count(own != light)} of {lanes} lanes connect across iterations"


#: Seeds a side of the suite's variance check (benchmarks/vcm_variance.py runs the 24 it was
#: written with); VARIANCE_BOUND is 5 bootstrap standard errors of the ratio at that size (0.12).
VARIANCE_SEEDS = 8
VARIANCE_BOUND = 0.6
#: The pixels of sds.xml's directly lit back wall at 64 x 64 (160 pixels).
VARIANCE_WALL = (slice(2, 12), slice(4, 20))


def ppm_and_photon_wall(seeds, blocked: bool = False):
    """(lab_vcm ppm, lab_photon) renders of sds.xml's back wall at equal light vertices (64x64;
    16 iterations of 65536 light subpaths, 4 to a pass, against 16 passes of 65536 photons; r =
    0.03 kept by alpha = 0.999, both Epanechnikov, direct light from the light vertices too), on
    ``seeds``; ``blocked``: iterations in blocks of 64 lanes (the bug: a pixel's samples in a pass
    then share their light vertices), ppm only."""
    from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights

    scene = load_scene(scene_path("sds.xml"), res=64)
    wall = VARIANCE_WALL
    photon = None if blocked else renders(scene, make_integrator("lab_photon", {
        "max_depth": MAX_DEPTH, "direct": "photons", "radius": 0.03, "aim": 0.0, "alpha": 0.999,
        "photons_per_pass": 65536, "passes": 16}), 1, seeds)[:, wall[0], wall[1], :3]
    right = BdptWeights.lane_iteration
    if blocked:
        BdptWeights.lane_iteration = lambda self, lane: (lane // 64) % self.lane_tables[2]
    try:
        lab = renders(scene, vcm(mode="ppm", radius=0.03, alpha=0.999, light_paths=16), 16, seeds)
    finally:
        BdptWeights.lane_iteration = right
    return lab[:, wall[0], wall[1], :3], photon


def variance_ratio(lab, photon):
    """The ratio of their mean per-pixel variances (each pixel's variance over the seeds, scaled by
    its squared mean + 0.01)."""
    scale = (lab.mean(0) + photon.mean(0)) ** 2 / 4 + 0.01
    return (lab.var(0, ddof=1) / scale).mean() / (photon.var(0, ddof=1) / scale).mean()


def bootstrap_error(lab, photon, rounds=200, seed=0):
    """The ratio's standard error by resampling the seeds of each side."""
    rng = np.random.default_rng(seed)
    pick = lambda stack: stack[rng.integers(0, len(stack), len(stack))]      # noqa: E731
    return float(np.std([variance_ratio(pick(lab), pick(photon)) for _ in range(rounds)], ddof=1))


def check_merging_has_lab_photons_variance_at_equal_light_vertices():
    """ppm against lab_photon at equal work on sds (``ppm_and_photon_wall``): on the directly lit
    back wall the ratio of their mean per-pixel variances is 1 within VARIANCE_BOUND = 0.6 on 8
    seeds a side (5 bootstrap standard errors of 0.12; measured 0.96). Power: iterations in
    blocks of 64 lanes, which gave a pixel's samples in a pass the same light vertices, measure
    2.36 on the same 8 seeds, past 1.6. The check as written, 24 seeds and a bound of 0.2 (5
    standard errors of 0.038; measured 1.00), is ``benchmarks/vcm_variance.py``."""
    lab, photon = ppm_and_photon_wall(range(VARIANCE_SEEDS))
    blocked, _ = ppm_and_photon_wall(range(VARIANCE_SEEDS), blocked=True)
    ratio, wrong = variance_ratio(lab, photon), variance_ratio(blocked, photon)
    print(f"variance of lab_vcm ppm / lab_photon: {ratio:.2f}; with blocks of 64 lanes: {wrong:.2f}")
    assert abs(ratio - 1) < VARIANCE_BOUND
    assert wrong > 1 + VARIANCE_BOUND


def test_merging_roulette_keeps_the_estimate_where_it_skips_most_merges(monkeypatch):
    """Merging's Russian roulette with MERGE_ROULETTE = 4 (a merge runs with probability bound / 4,
    at most 1/4) against every merge run, the same biased estimator (r_1 = 0.1, 4 light subpaths
    per camera subpath, merge_first: merges carry 19% of the caustic scene's light at res 24):
    counted 1 / probability they agree, and a roulette that forgets that factor is caught (power)."""
    from mitsuba_lab.plugins.integrators.vcm import merging

    scene = load_scene(scene_path("caustic.xml"), res=RES)
    params = {"radius": 0.1, "light_paths": 4, "merge_first": True}
    right = merging.merge_roulette
    monkeypatch.setattr(merging, "merge_roulette", lambda w, camera, u, medium=None: (True, 1.0))
    every = renders(scene, vcm(**params), 16, SEEDS_REF)
    monkeypatch.setattr(merging, "merge_roulette", right)
    monkeypatch.setattr(merging, "MERGE_ROULETTE", 4.0)
    assert_agrees(renders(scene, vcm(**params), 16, SEEDS_LAB), every, "merges run with probability bound / 4")
    monkeypatch.setattr(merging, "merge_roulette", lambda w, camera, u, medium=None: (right(w, camera, u)[0], 1.0))
    z = z_scores(renders(scene, vcm(**params), 16, SEEDS_LAB), every).max_abs_z
    print(f"merges run with probability bound / 4, counted once: max |z| {z:.2f}")
    assert z > Z_BOUND


def test_connection_roulette_is_unbiased_where_it_skips_most_connections(monkeypatch):
    """Connections' Russian roulette with CONNECT_SHARE = 10 (a connection runs with probability
    its contribution / 10x the lane's estimate so far: nearly none run) agrees with Mitsuba's
    `path` on the Cornell box, where connections carry much of the indirect light; one that
    forgets the 1 / probability is caught (power)."""
    from mitsuba_lab.plugins.integrators.bdpt import camera_subpath
    from mitsuba_lab.plugins.integrators.vcm.integrator import LabVCMIntegrator

    scene = load_scene(scene_path("cornell_box.xml"), res=RES)
    ref = path_stack("cornell_box.xml")
    monkeypatch.setattr(LabVCMIntegrator, "CONNECT_SHARE", 10.0)
    assert_agrees(renders(scene, vcm(radius=SMALL_RADIUS), 16, SEEDS_LAB), ref, "connections run 1 in ~10+")
    right = camera_subpath.connection_roulette
    monkeypatch.setattr(camera_subpath, "connection_roulette", lambda *a: (right(*a)[0], 1.0))
    z = z_scores(renders(scene, vcm(radius=SMALL_RADIUS), 16, SEEDS_LAB), ref).max_abs_z
    print(f"connections under the roulette, counted once: max |z| {z:.2f}")
    assert z > Z_BOUND


@pytest.mark.parametrize("name", ["cornell_box.xml", "caustic.xml"])
def test_a_seed_renders_the_same_image_twice(name):
    """Both roulettes decide from the sampler and the light vertex's depth, never from the slot
    the light pass's atomics give it, so a seed's image repeats (to float atomics' order; keyed
    by slot, pixels differed by up to 17% between two runs)."""
    scene = load_scene(scene_path(name), res=32)
    first, second = (render(scene, vcm(radius=0.03), spp=8, seed=1) for _ in range(2))
    np.testing.assert_allclose(first, second, rtol=1e-5, atol=1e-6)


@functools.lru_cache(maxsize=None)
def blur_bias(iterations: int, seeds: int, kernel: str = "epanechnikov"):
    """Each seed's relative bias of the image mean for bpm (merging at every camera vertex) with
    r_1 = 0.8 (two fifths of the Cornell box's wall) and alpha = 0.25 on the box at 16x16,
    against a 4096-spp `path` mean: the blur darkens edges and corners."""
    scene = load_scene(scene_path("cornell_box.xml"), res=16)
    ref_mean = path_reference("cornell_box.xml", 16, 1024, MAX_DEPTH, range(1000, 1004))[..., :3].mean()   # (once)
    lab = renders(scene, vcm(mode="bpm", radius=0.8, alpha=0.25, merge_first=True, kernel=kernel), iterations,
                  range(seeds))[..., :3]
    means = lab.mean(axis=(1, 2, 3)) / ref_mean - 1.0
    print(f"{kernel}, {iterations} iterations: relative bias %+.4f +- %.4f" % mean_and_error(means))
    return means


def mean_and_error(values):
    return values.mean(), values.std(ddof=1) / np.sqrt(len(values))


def test_bias_shrinks_with_the_radius():
    """After 16x the iterations the radius is 2.8x smaller (r_i = r_1 i^((alpha - 1) / 2)) and
    so is the blur's darkening, beyond 3 standard errors."""
    (b16, s16), (b256, s256) = mean_and_error(blur_bias(16, 48)), mean_and_error(blur_bias(256, 12))
    assert b16 < -3 * s16                                  # plainly biased at first
    assert abs(b256) < abs(b16) - 3 * np.hypot(s16, s256)  # and much less so later


def test_the_epanechnikov_kernel_blurs_less_than_the_constant_one():
    """At the same radius, iterations and seeds (the same light and camera subpaths, so the
    difference is paired) both kernels darken the image, Epanechnikov's less (its second moment
    r^2 / 3 against the disc's r^2 / 2), by more than 3 standard errors of the difference."""
    epanechnikov, constant = blur_bias(16, 48), blur_bias(16, 48, "constant")
    (bc, sc), (d, sd) = mean_and_error(constant), mean_and_error(epanechnikov - constant)
    print(f"Epanechnikov - constant: {d:+.4f} +- {sd:.4f}")
    assert bc < -3 * sc
    assert d > 3 * sd


STIFF = sorted(f for f in os.listdir(os.path.join(ROOT, "scenes", "stiff")) if f.endswith(".xml"))


#: lab_vcm's spectral cases, (mode, light_paths, merge_vertices). The suite runs two: vcm with 4 light
#: subpaths per camera subpath emits, connects, merges and splats the extra subpaths at each pass's
#: wavelengths (everything vcm with 1 does, and more), and ppm is merging alone. merge_vertices
#: "caustic" only chooses which vertices merge, as in RGB (test_caustic_merges_...). The whole
#: list runs in benchmarks/agreement_matrix.py.
SPECTRAL_MATRIX = [("vcm", 1, "all"), ("ppm", 1, "all"), ("vcm", 4, "all"), ("vcm", 1, "caustic")]
#: The suite keeps vcm with 4 light subpaths (merging and every connection in spectral); ppm and the
#: rest of SPECTRAL_MATRIX run in benchmarks/agreement_matrix.py.
SPECTRAL_CASES = [("vcm", 4, "all")]
#: Iterations (one pass each, one set of wavelengths) per spectral render: 16, but 8 for vcm with 4
#: light subpaths, where `path`'s reference holds most of the variance and the image x 1.03 / x 0.97
#: still fails at 8 (max |z| 9.14 / 9.49; 9.57 / 10.49 at 16). ppm's own noise dominates (x 1.03 /
#: x 0.97: 3.91 / 3.01 at 16, 3.10 / 3.23 at 8), so it keeps 16.
SPECTRAL_SPP = {("vcm", 4): 8}


@pytest.mark.parametrize("mode, light_paths, merge_vertices", SPECTRAL_CASES)
def test_spectral_variant_agrees_with_mitsuba_path(mode, light_paths, merge_vertices):
    """The spectral variant, as lab_photon: one set of wavelengths per pass (here one iteration), at
    which light subpaths are emitted, merged and connected (sRGB of a spectrum may be out of
    gamut: negative channels are allowed, negative luminance is not)."""
    import mitsuba_lab

    try:
        mitsuba_lab.use_variant(variant("ad_spectral"))
        scene = load_scene(scene_path("cornell_box.xml"), res=RES)
        lab = renders(scene, vcm(mode=mode, radius=SMALL_RADIUS, light_paths=light_paths,
                                 merge_vertices=merge_vertices), SPECTRAL_SPP.get((mode, light_paths), 16),
                     SEEDS_LAB)
        assert pixel_problem(lab, True) == ""
        result = z_scores(lab, path_stack("cornell_box.xml"))
        print(f"lab_vcm mode={mode}, light_paths={light_paths}, merge_vertices={merge_vertices} in {mi.variant()}: "
              f"max |z| {result.max_abs_z:.2f}, "
              f"relative difference {result.rel_diff.round(4)}")
        assert result.max_abs_z <= Z_BOUND
    finally:
        mitsuba_lab.use_variant(HOME)


MERGE_SETTINGS = [(True, "all"), (False, "all"), (False, "caustic")]
#: Each stiff scene with one merge setting, rotating (each setting on a third of the scenes); every
#: scene with every setting: benchmarks/agreement/test_vcm_matrix.py.
STIFF_CASES = [(name, *MERGE_SETTINGS[k % len(MERGE_SETTINGS)]) for k, name in enumerate(STIFF)]
MOVED_STIFF_CASES = [(name, *m) for name in STIFF for m in MERGE_SETTINGS if (name, *m) not in STIFF_CASES]


@pytest.mark.parametrize("name, merge_first, merge_vertices", STIFF_CASES)
def test_no_nan_inf_or_negative_on_stiff_scenes(name, merge_first, merge_vertices):
    scene = load_scene(scene_path(f"stiff/{name}"), res=16)
    depth = -1 if name == "closed_box_albedo_099.xml" else MAX_DEPTH
    image = render(scene, vcm(max_depth=depth, merge_first=merge_first, merge_vertices=merge_vertices), spp=8,
                   seed=7)[None]
    assert pixel_problem(image, False) == "", f"{name}: {pixel_problem(image, False)}"


def test_refusals_are_one_line():
    for params, match in (({"mode": "ppm2"}, "parameter 'mode' must be one of vcm, bpt, bpm, ppm, lt, pt"),
                          ({"alpha": 1.0}, "parameter 'alpha' must be a number in \\(0, 1\\)"),
                          ({"radius": -1.0}, "parameter 'radius' must be"),
                          ({"light_paths": 0.01}, "parameter 'light_paths' must be a number in \\[1/64, 64\\]"),
                          ({"merge_first": 0}, "parameter 'merge_first' expects a boolean"),
                          ({"mode": "ppm", "merge_first": False}, "ppm.*merge_first = false does not apply"),
                          ({"mode": "bpm", "merge_vertices": "caustic"}, "merge_vertices = 'caustic'.*mode 'bpm'"),
                          ({"merge_vertices": "delta"}, "parameter 'merge_vertices' must be one of all, caustic"),
                          ({"strategies": "all"}, "strategies")):
        with pytest.raises(Exception, match=match):
            make_integrator("lab_vcm", params)


def test_statistics_name_the_radii_and_the_grid_time():
    """Iterations share a pass (each with its own radius): 2^18 light subpaths in the first."""
    scene = load_scene(scene_path("cornell_box.xml"), res=16)
    integrator = vcm(radius=0.1, alpha=0.5)
    render(scene, integrator, spp=4)
    stats = integrator.bdpt_stats()
    assert stats["passes"] == 1 and stats["grid_s"] > 0         # 4 iterations of 256 light subpaths
    assert stats["radius_first"] == pytest.approx(0.1) and stats["radius_last"] == pytest.approx(0.1 * 4 ** -0.25)


def test_passes_hold_about_a_fixed_number_of_stored_vertices():
    """The first pass holds 2^18 light subpaths (64 iterations at 64x64); later ones as many as
    keep about 2^20 stored vertices by the first's count, at most 2^18 subpaths: the caustic
    scene (about 0.5 stored vertices per subpath) and the Cornell box (3.1) take 64 iterations a
    pass, the closed box of albedo 0.99 (6.8) 37, so 110 iterations are 64 + 37 + 9."""
    from mitsuba_lab.plugins.integrators.vcm.integrator import PASS_LIGHT_VERTICES

    for name, spp, passes in (("caustic.xml", 80, 2), ("cornell_box.xml", 80, 2),
                              ("stiff/closed_box_albedo_099.xml", 110, 3)):
        scene = load_scene(scene_path(name), res=64)
        integrator = vcm(radius=0.03)
        render(scene, integrator, spp=spp)
        stats = integrator.bdpt_stats()
        per_path = stats["light_vertices_stored"] / stats["light_subpaths"]
        print(f"{name}: {per_path:.2f} stored vertices per subpath, {stats['passes']} passes")
        assert stats["passes"] == passes, (name, per_path, stats["passes"])
    assert 6 < per_path and int(PASS_LIGHT_VERTICES / per_path) // (64 * 64) == 37


def test_below_one_light_subpath_a_pass_holds_up_to_2_20_camera_subpaths():
    """light_paths = 1/16 on the Cornell box at 64x64: a pass's 2^18 light subpaths would serve
    1024 iterations, so 2^20 camera subpaths (256 iterations) bound it: 512 iterations take 2
    passes (at the 2^18 camera subpaths of before, 8). At 1/2 the light vertices bound it again
    (2^18 subpaths / 2048 per iteration = 128 iterations)."""
    scene = load_scene(scene_path("cornell_box.xml"), res=64)
    for light_paths, spp, passes in ((1 / 16, 512, 2), (0.5, 256, 2)):
        integrator = vcm(radius=0.03, light_paths=light_paths)
        render(scene, integrator, spp=spp)
        assert integrator.bdpt_stats()["passes"] == passes, (light_paths, integrator.bdpt_stats())


def test_bpm_without_the_first_merge_is_left_out_where_delta_lights_shine():
    """bpm's direct light from a point light reaches what the camera sees only by merging there:
    with merge_first = false the planner leaves it out (and a render warns), with the reason;
    vcm keeps next-event estimation and light tracing for it."""
    from mitsuba_lab.scene import SceneTraits, strategy_applicability

    traits = SceneTraits.from_scene(load_scene(scene_path("stiff/delta_lights_only.xml"), res=8))
    ok, reason = strategy_applicability(traits, "lab_vcm", {"mode": "bpm", "merge_first": False})
    assert not ok and "merge_first=false cannot render direct light from delta emitters" in reason, reason
    for params in ({"mode": "bpm", "merge_first": True}, {"mode": "ppm"}, {"mode": "vcm"}):
        assert strategy_applicability(traits, "lab_vcm", params) == (True, ""), params


def test_rays_and_merge_reads_are_counted():
    """lab_vcm counts lab_bdpt's ray kinds and the light vertices its merges read (``merge``); ppm
    has no NEE, connections or light tracing."""
    scene = load_scene(scene_path("cornell_box.xml"), res=16)
    every, ppm = vcm(), vcm(mode="ppm")
    for integrator in (every, ppm):
        render(scene, integrator)
    rays, lookups = every.ray_counts(), ppm.ray_counts()
    camera = 16 * 16 * 4
    assert rays["camera"] == camera and all(rays[k] > camera / 4 for k in rays), rays
    assert lookups["camera"] == camera and lookups["merge"] > 0 and lookups["light"] > 0, lookups
    assert lookups["shadow"] == lookups["connection"] == lookups["sensor"] == 0, lookups
