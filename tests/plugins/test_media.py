"""The path family (lab_naive, lab_nee, lab_mis) in participating media agrees with Mitsuba's
`volpath` in expectation, in rgb, mono and spectral, on the scenes of tests/media_scenes.py
(fog behind a null boundary, a point light and the camera inside forward-scattering fog,
a chromatic medium in glass, heterogeneous smoke with a spot light and a masked card), and with
`volpathmis` where lab_mis does spectral MIS; majorant grids (their bounds checked at random points,
their tracking against quadrature ray by ray) and spectral MIS.

Tolerance: |z| <= Z_BOUND (tests/agreement.py) for every 8x8 block mean and every image
channel mean, 16 seeds a side (Welch, about 30 degrees of freedom); power: a 3% error in the
free-flight weight passes the bound, as do majorant grid bounds at 0.4x against quadrature. The
proofs that render stacks of their own (a 3% error in the shadow rays' transmittance, a wrong
equi-angular density, the 0.4x grid in a render, spectral MIS that forgets the path's channel
ratios, equi-angular mode without NEE for lights at infinity) run in benchmarks/power/test_media_power.py.
"""
import numpy as np
import pytest

import mitsuba as mi
import backend
import media_scenes
import mitsuba_lab
from agreement import SEEDS_LAB, SEEDS_REF, Z_BOUND, assert_agrees, cached_renders, pixel_problem, renders, z_scores
from mitsuba_lab.scene import SceneTraits, equivalent_strategies, make_integrator, strategy_applicability

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier

SPP = 16
DEPTH = 6


def reference(scene, max_depth=DEPTH, kind="volpath", name=None):
    """``kind``'s renders of the scene; with ``name`` (media_scenes' scene, unmodified) rendered
    once per run and shared (agreement.cached_renders: fixed seeds, so the same stack): fog_box's
    reference served 6 tests, smoke's 5, point_in_fog's 3."""
    if name is None:
        return renders(scene, make_integrator(kind, {"max_depth": max_depth}), SPP, SEEDS_REF)
    return cached_renders(("media_scenes", name), scene, kind, {"max_depth": max_depth}, SPP, SEEDS_REF)


def lab(scene, kind="lab_mis", max_depth=DEPTH, **params):
    return renders(scene, make_integrator(kind, {"max_depth": max_depth, **params}), SPP, SEEDS_LAB)


@pytest.mark.parametrize("name", ["fog_box", "point_in_fog", "chromatic_in_glass", "smoke"])
def test_lab_mis_agrees_with_volpath(name):
    """(In the chromatic medium against volpathmis, whose spectral MIS lab_mis does by default:
    volpath's one-channel weights are heavy-tailed there, and against the lab's lighter-tailed
    estimate its 16-seed mean gave |z| 4.5.)"""
    scene = mi.load_dict(media_scenes.SCENES[name]())
    kind = "volpathmis" if name == "chromatic_in_glass" else "volpath"
    assert_agrees(lab(scene), reference(scene, kind=kind, name=name), f"lab_mis on {name} against {kind}")


@pytest.mark.parametrize("kind, name", [("lab_nee", "smoke"), ("lab_naive", "fog_box")])
def test_lab_nee_and_lab_naive_agree_with_volpath(kind, name):
    scene = mi.load_dict(media_scenes.SCENES[name]())
    assert_agrees(lab(scene, kind), reference(scene, name=name), f"{kind} on {name}")


@pytest.mark.parametrize("kind, sampling, name", [
    ("lab_mis", "distance", "fog_box"), ("lab_mis", "equiangular", "fog_box"),
    ("lab_mis", "equiangular", "point_in_fog"), ("lab_nee", "mis", "fog_box"), ("lab_nee", "equiangular", "point_in_fog")])
def test_every_medium_sampling_agrees_with_volpath(kind, sampling, name):
    """Free flights alone, equi-angular sampling alone (with phase-function hits for lab_mis), and
    both (lab_mis's default, tested above; lab_nee weighs its two light samples by balance)."""
    scene = mi.load_dict(media_scenes.SCENES[name]())
    assert_agrees(lab(scene, kind, medium_sampling=sampling), reference(scene, name=name), f"{kind} {sampling} on {name}")


@pytest.mark.parametrize("kind", ["lab_nee", "lab_mis"])
def test_equiangular_mode_keeps_nee_for_lights_at_infinity(kind):
    """medium_sampling = equiangular aims at a light point; a sky and a sun have none, so NEE at
    medium vertices must still sample them (lab_nee once lost their scattered light: 0.614 against
    volpath's 0.667 on smoke). The point light above the fog is equi-angular sampling's. Power:
    benchmarks/power/test_media_power.py drops that NEE again, and both estimators fail."""
    scene = mi.load_dict(media_scenes.fog_box_sky())
    assert_agrees(lab(scene, kind, medium_sampling="equiangular"), reference(scene, name="fog_box_sky"),
                  f"{kind} equiangular under a sky and a sun")


@pytest.mark.parametrize("kind", ["lab_nee", "lab_mis"])
def test_emitters_at_infinity_light_nothing_through_unbounded_fog(kind):
    """The sky and a sun seen from the sensor's unbounded fog: no light crosses an infinite
    stretch of it, so the path family renders black, as the bidirectional family does. (Mitsuba's
    volpath gives 0.00224 here: it puts an emitter at infinity 2 bounding-sphere radii away, so a
    speck far off that nothing sees changes its image; experiments/results/2026-11-29-env-in-unbounded-fog.md.
    Before, lab_nee's NEE gave 0.0028 and lab_mis's 0.0014.)"""
    scene = mi.load_dict(media_scenes.sky_in_unbounded_fog())
    image = renders(scene, make_integrator(kind, {"max_depth": 6}), 4, [0])
    assert image.max() == 0, image.max()


def test_delta_tracking_shadow_rays_agree_with_volpath():
    scene = mi.load_dict(media_scenes.smoke())
    assert_agrees(lab(scene, transmittance="delta"), reference(scene, name="smoke"), "lab_mis transmittance=delta on smoke")


@pytest.mark.parametrize("max_depth", [1, 3])
def test_depth_counts_medium_vertices_and_not_null_boundaries(max_depth):
    """max_depth as volpath counts it: a scattering event in a medium is a vertex, crossing a
    null boundary is not (with 1, the light is seen through the fog box's boundary)."""
    scene = media_scenes.fog_box()
    scene["environment"] = media_scenes.environment(0.5)        # seen through the box at max_depth 1
    scene = mi.load_dict(scene)
    images = lab(scene, max_depth=max_depth)
    assert images.mean() > 0.05
    assert_agrees(images, reference(scene, max_depth), f"lab_mis max_depth {max_depth}")


@pytest.mark.parametrize("kind, name", [("ad_mono", "chromatic_smoke"), ("ad_spectral", "chromatic_in_glass")])
def test_mono_and_spectral_variants_agree_with_volpath(kind, name):
    variant = backend.variant(kind)
    if variant not in mi.variants():
        pytest.skip(f"{variant} is not in this Mitsuba build")
    mitsuba_lab.use_variant(variant)
    try:
        scene = mi.load_dict(media_scenes.SCENES[name]())
        images = lab(scene)
        assert pixel_problem(images, kind == "ad_spectral") == ""
        result = z_scores(images, reference(scene))
        print(f"lab_mis on {name} in {variant}: max |z| {result.max_abs_z:.2f}, relative difference "
              f"{result.rel_diff.round(4)}")
        assert result.max_abs_z <= Z_BOUND
    finally:
        mitsuba_lab.use_variant(backend.HOME)


@pytest.mark.parametrize("what", ["free_flight"])      # (transmittance and equiangular_pdf:
# benchmarks/power/test_media_power.py, results in experiments/results/2026-11-28-power-proofs.md)
def test_a_three_percent_error_in_a_medium_estimator_is_caught(monkeypatch, what):
    """Power: the free flights' weight or the shadow rays' transmittance 3% too high, or the
    equi-angular density that the other techniques' MIS weights see 30% too high (the weights
    then no longer sum to 1)."""
    from mitsuba_lab.plugins.integrators.common import media

    original = getattr(media, what)

    def biased(*args, **kwargs):
        out = original(*args, **kwargs)
        if what == "free_flight":
            mei, scattered, weight, ratios, nulls = out
            return mei, scattered, weight * 1.03, ratios, nulls
        return out * (1.3 if what == "equiangular_pdf" else 1.03)

    monkeypatch.setattr(media, what, biased)
    scene = mi.load_dict(media_scenes.fog_box())
    result = z_scores(lab(scene), reference(scene, name="fog_box"))
    print(f"{what} too high: max |z| {result.max_abs_z:.1f}, relative difference {result.rel_diff.round(4)}")
    assert result.max_abs_z > Z_BOUND


@pytest.mark.parametrize("case", ["dense_albedo_0999", "extinction_1e-4", "grazing"])
def test_stiff_media_give_finite_non_negative_pixels(case):
    """A dense medium of albedo 0.999 (long random walks), one of extinction 1e-4 (almost no
    collision), and a camera grazing the fog box's top face."""
    if case == "dense_albedo_0999":
        scene = media_scenes.fog_box(albedo=0.999, sigma_t=20.0)
    elif case == "extinction_1e-4":
        scene = media_scenes.fog_box(sigma_t=1e-4)
    else:
        scene = media_scenes.fog_box()
        scene["sensor"]["to_world"] = media_scenes.T().look_at(origin=[0, 1.2, 4], target=[0, 1.2, 0], up=[0, 1, 0])
    images = renders(mi.load_dict(scene), make_integrator("lab_mis", {"max_depth": -1}), 16, range(2))
    assert pixel_problem(images, False) == ""
    assert images.mean() > 0


def test_the_planner_runs_the_path_family_on_media_and_leaves_the_others_out():
    traits = SceneTraits.from_scene(mi.load_dict(media_scenes.fog_box()))
    for kind in ("lab_naive", "lab_nee", "lab_mis", "lab_bdpt", "lab_vcm", "lab_photon"):
        assert strategy_applicability(traits, kind, {}) == (True, ""), kind
    applies, reason = strategy_applicability(traits, "lab_mmlt", {})
    assert not applies and "participating media" in reason and "lab_mis" in reason


def test_a_medium_makes_the_estimators_differ_where_every_bsdf_is_delta():
    """Only null and glass surfaces: without a medium lab_naive, lab_nee and lab_mis are one
    estimator; a medium's phase function is smooth, so in chromatic_in_glass-like scenes they
    are not."""
    scene = media_scenes.chromatic_in_glass()
    scene["floor"]["bsdf"] = {"type": "conductor"}
    scene["light"]["bsdf"] = {"type": "null"}
    traits = SceneTraits.from_scene(mi.load_dict(scene))
    assert not traits.smooth_bsdf and traits.media
    strategies = {"naive": ("lab_naive", {}), "nee": ("lab_nee", {}), "mis": ("lab_mis", {})}
    assert equivalent_strategies(traits, strategies) == {"naive": "naive", "nee": "nee", "mis": "mis"}
    del scene["ball"]["interior"]
    traits = SceneTraits.from_scene(mi.load_dict(scene))
    assert set(equivalent_strategies(traits, strategies).values()) == {"naive"}


def test_equivalent_strategies_in_media():
    """With only a point light, lab_mis with free flights alone is lab_nee (every weight 1), but
    with medium_sampling = mis its heuristic weighs NEE against equi-angular sampling; without a
    medium the medium parameters change nothing."""
    strategies = {"nee": ("lab_nee", {}), "mis_distance": ("lab_mis", {"medium_sampling": "distance"}),
                  "mis": ("lab_mis", {}), "nee_mis": ("lab_nee", {"medium_sampling": "mis"})}
    fog = SceneTraits.from_scene(mi.load_dict(media_scenes.fog_box_point()))
    assert equivalent_strategies(fog, strategies) == {"nee": "nee", "mis_distance": "nee", "mis": "mis",
                                                      "nee_mis": "nee_mis"}
    clear = media_scenes.fog_box_point()
    del clear["box"]["interior"]
    clear = SceneTraits.from_scene(mi.load_dict(clear))
    assert set(equivalent_strategies(clear, strategies).values()) == {"nee"}


# ------------------------------------------------------------------ majorant grids (issue 44)
def _points_in_every_cell(grid, per_cell, seed):
    """(cells [n, 3] as x, y, z indices, world points [n, 3]): ``per_cell`` uniform points in
    every cell of ``grid``, and the grid's faces and corners (u = 0 and 1 on each axis)."""
    rx, ry, rz = grid.resolution
    idx = np.stack(np.meshgrid(np.arange(rx), np.arange(ry), np.arange(rz), indexing="ij"), -1).reshape(-1, 3)
    cells = np.repeat(idx, per_cell, axis=0)
    rng = np.random.default_rng(seed)
    frac = rng.random(cells.shape)
    frac[::per_cell] = 0.0                       # each cell's lower corner, and upper below
    frac[1::per_cell] = 1.0 - 1e-7
    u = (cells + frac) / np.array([rx, ry, rz])
    to_world = np.array(grid.to_local.inverse().matrix)
    return cells, u @ to_world[:3, :3].T + to_world[:3, 3]


@pytest.mark.parametrize("name", ["smoke", "smoke.xml"])
def test_the_majorant_grid_bounds_the_extinction_everywhere(name):
    """Every cell's bound is >= sigma_t as the medium evaluates it (trilinear, scaled) at 64
    random points of the cell and at its corners; were it below anywhere, delta and ratio
    tracking would be biased. No render: the medium evaluated directly."""
    import drjit as dr
    from agreement import scene_path
    from mitsuba_lab.plugins.integrators.common import majorants

    scene = mi.load_dict(media_scenes.smoke()) if name == "smoke" else mi.load_file(scene_path("smoke.xml"))
    grid = majorants.MajorantGrid.of(scene, 16)
    cells, points = _points_in_every_cell(grid, 64, seed=44)
    mei = dr.zeros(mi.MediumInteraction3f, len(points))
    mei.p = mi.Point3f(*(points[:, a] for a in range(3)))
    _, _, sigma_t = grid.medium.get_scattering_coefficients(mei, True)
    sigma_t = np.array(sigma_t)[0]
    bound = grid.bounds[cells[:, 2], cells[:, 1], cells[:, 0]]
    print(f"{name}: {grid.describe()}; largest sigma_t / bound {np.max(sigma_t / np.maximum(bound, 1e-30)):.6f}")
    assert np.all(sigma_t <= bound) and sigma_t.max() > 0.9 * grid.global_majorant
    assert grid.nbytes == 4 * int(np.prod(grid.resolution))
    assert grid.bounds.mean() < 0.6 * grid.global_majorant          # the point: most cells far below


def _grid_transmittance_z(kind: str, rays: int = 256, reps: int = 1024) -> float:
    """Max |z| over ``rays`` rays through the smoke medium (random chords of a sphere around it,
    16 of them along the x axis, where the DDA meets zero direction components) of the mean of
    ``reps`` transmittance estimates by tracking against the majorant grid, against
    exp(-optical depth) by the midpoint rule (4000 points; sigma_t 0 outside the medium's box,
    where Mitsuba clips tracking). The standard error is the estimator's (ratio), or the 0/1
    estimate's sqrt(T (1 - T) / reps) from the true T (delta: all-0 or all-1 samples have none)."""
    import drjit as dr
    from mitsuba_lab.plugins.integrators.common import majorants

    grid = majorants.MajorantGrid.of(mi.load_dict(media_scenes.smoke()), 16)
    rng = np.random.default_rng(44)
    centre = np.array([0.0, 0.8, 0.0])
    ends = rng.normal(size=(2, rays, 3))
    ends = centre + 1.5 * ends / np.linalg.norm(ends, axis=2, keepdims=True)
    ends[:, :16] = centre + rng.uniform(-0.5, 0.5, (16, 3))
    ends[0, :16, 0], ends[1, :16, 0] = -1.5, 1.5
    o, d = ends[0], ends[1] - ends[0]
    length = np.linalg.norm(d, axis=1)
    d /= length[:, None]
    s = (np.arange(4000) + 0.5) / 4000
    points = (o[:, None] + (s[None, :, None] * length[:, None, None]) * d[:, None]).reshape(-1, 3)
    mei = dr.zeros(mi.MediumInteraction3f, len(points))
    mei.p = mi.Point3f(*(points[:, a] for a in range(3)))
    _, _, sigma_t = grid.medium.get_scattering_coefficients(mei, True)
    in_box = np.all((points >= [-0.8, 0.0, -0.8]) & (points <= [0.8, 1.6, 0.8]), axis=1)
    depth = (np.array(sigma_t)[0] * in_box).reshape(rays, -1).mean(axis=1) * length
    T_true = np.exp(-depth)
    lane = np.repeat(np.arange(rays), reps)
    ray = mi.Ray3f(mi.Point3f(*(o[lane, a] for a in range(3))), mi.Vector3f(*(d[lane, a] for a in range(3))))
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(7, rays * reps)
    _, _, T, _ = majorants.track(grid, ray, mi.Float(length[lane]), sampler, mi.Bool(True), kind)
    T = np.array(T)[0].reshape(rays, reps)
    se = T.std(axis=1, ddof=1) if kind == "ratio" else np.sqrt(T_true * (1 - T_true))
    z = (T.mean(axis=1) - T_true) / np.maximum(se / np.sqrt(reps), 1e-6)
    print(f"{kind} tracking against the grid: max |z| {np.abs(z).max():.2f} over {rays} rays "
          f"(T from {T_true.min():.3f} to {T_true.max():.3f})")
    return float(np.abs(z).max())


@pytest.mark.parametrize("kind", ["ratio", "delta"])
def test_grid_tracking_transmittance_matches_quadrature(kind):
    """Ratio and delta tracking against the majorant grid, ray by ray, against the optical depth
    integrated numerically (no render: the DDA and the per-cell exponential checked directly)."""
    assert _grid_transmittance_z(kind) <= Z_BOUND


@pytest.mark.parametrize("kind, transmittance", [("lab_mis", "ratio"), ("lab_nee", "delta")])
def test_majorant_grid_tracking_agrees_with_volpath(kind, transmittance):
    """Free flights (delta tracking) and shadow rays (ratio or delta tracking) walked cell by cell
    against the grid's bounds (an 8^3 grid on the 8^3 smoke: each bound its voxel's trilinear
    neighbourhood)."""
    scene = mi.load_dict(media_scenes.smoke())
    assert_agrees(lab(scene, kind, majorants="grid", transmittance=transmittance), reference(scene, name="smoke"),
                  f"{kind} majorants=grid transmittance={transmittance} on smoke")


def test_a_majorant_grid_below_the_extinction_is_caught(monkeypatch):
    """Power: every cell's bound at 0.4 of the grid's maximum over its footprint (sigma_t exceeds
    it in part of most occupied cells) must fail the bound."""
    from mitsuba_lab.plugins.integrators.common import majorants

    monkeypatch.setattr(majorants, "ROUNDING", 0.4)
    assert _grid_transmittance_z("ratio") > Z_BOUND
    # (the same grid in a whole render of smoke against volpath fails too: that proof renders
    # a stack of its own and runs in benchmarks/power/test_media_power.py)


def test_majorant_grid_is_refused_in_one_line_where_it_cannot_apply_and_ignored_in_homogeneous_media():
    """A rotated sigma_t grid is refused (one line, naming the way out); a scene with only
    homogeneous media renders as with global majorants, bit for bit."""
    from mitsuba_lab.render import render

    smoke = media_scenes.smoke()
    smoke["box"]["interior"]["sigma_t"]["to_world"] = media_scenes.T().rotate([0, 1, 0], 30).scale(1.6)
    with pytest.raises(ValueError) as err:         # (the integrator's own render: mi.render would wrap it)
        make_integrator("lab_mis", {"majorants": "grid"}).render(mi.load_dict(smoke), spp=1, seed=0)
    message = str(err.value)
    assert "\n" not in message and "rotated" in message and "majorants = global" in message, message
    fog = mi.load_dict(media_scenes.fog_box())
    images = [render(fog, make_integrator("lab_mis", {"max_depth": DEPTH, "majorants": m}), spp=4, seed=3)[0]
              for m in ("global", "grid")]
    assert np.array_equal(images[0], images[1])


# ------------------------------------------------------------------ spectral MIS (issue 44)
def test_spectral_mis_and_one_channel_sampling_agree_with_mitsuba():
    """In the tenfold chromatic medium in glass: lab_nee with spectral MIS against volpathmis
    (lab_mis's default, spectral MIS with the equi-angular weights seeing the channel-averaged
    distance density, is test_lab_mis_agrees_with_volpath's), and lab_mis sampling with one
    channel (spectral_mis false) against volpath, which does the same."""
    scene = mi.load_dict(media_scenes.chromatic_in_glass())
    assert_agrees(lab(scene, "lab_nee", spectral_mis=True), reference(scene, kind="volpathmis", name="chromatic_in_glass"),
                  "lab_nee spectral_mis on chromatic_in_glass against volpathmis")
    assert_agrees(lab(scene, spectral_mis=False), reference(scene, name="chromatic_in_glass"),
                  "lab_mis one channel on chromatic_in_glass")


def test_the_majorant_grid_follows_the_medium_s_data():
    """Kept between renders of a scene, rebuilt when its sigma_t data is set anew (a stale grid
    below the new densities would bias every estimate): doubled data, doubled bounds."""
    from mitsuba_lab.plugins.integrators.common import majorants

    scene = mi.load_dict(media_scenes.smoke())
    integrator = make_integrator("lab_mis", {"majorants": "grid"})
    grid = majorants.of_integrator(integrator, scene)
    assert majorants.of_integrator(integrator, scene) is grid
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("sigma_t.data"))
    params[key] = params[key] * 2.0
    params.update()
    rebuilt = majorants.of_integrator(integrator, scene)
    assert rebuilt is not grid and np.allclose(rebuilt.bounds, 2.0 * grid.bounds, rtol=1e-6)


def test_light_samples_of_weight_zero_trace_and_count_no_shadow_ray():
    """With Veach's ``max`` heuristic a light sample whose technique is not the densest there has
    weight 0: it traces no shadow ray, and ``ray_counts`` counts none for it. On fog_box_point
    (16x12, 16 spp, seed 3, max_depth 6) power counts 12220 shadow rays and max 10075 (0.82x);
    counting the untraced ones, as before, gave max 12136 (0.99x). The images are those of before
    (the skipped samples add 0)."""
    scene = mi.load_dict(media_scenes.fog_box_point())
    counts = {}
    for heuristic in ("power", "max"):
        integrator = make_integrator("lab_mis", {"heuristic": heuristic, "max_depth": 6})
        mi.render(scene, integrator=integrator, spp=16, seed=3)
        counts[heuristic] = integrator.ray_counts()["shadow"]
    assert counts["max"] < 0.9 * counts["power"], counts
