"""lab_photon on the scenes users write: mixed delta/smooth BSDFs, principled clear coat, shading
normals, hide_emitters, spectral variants; and its one-line refusals.

lab_photon is consistent, not unbiased: at a finite number of passes its image is blurred by
the kernel (biased low at silhouettes and edges). So it is checked against Mitsuba's `path` by
region means and relMSE with stated tolerances, and by its error falling with passes, never by
z-scores of the mean. Seeds are fixed, every run is deterministic. Tolerances come from
measurements on this machine (4 seeds each, quoted at each test), with room for the seed's
noise; the holes they guard against were far outside them (numbers quoted too).
"""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mitsuba_lab
from backend import HOME, variant
from mitsuba_lab.errors import one_line
from mitsuba_lab.metrics import rel_mse
from mitsuba_lab.plugins.integrators.photon.gather import DELTA_MASK

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

RES = 32
PLASTIC = {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.3, 0.7]}}
CLEARCOAT = {"type": "principled", "base_color": {"type": "rgb", "value": [0.7, 0.2, 0.15]},
             "roughness": 0.5, "clearcoat": 1.0, "clearcoat_gloss": 0.9}
MASK = {"type": "mask", "opacity": 0.5, "bsdf": {"type": "diffuse"}}


def photon(**params):
    return mi.load_dict({"type": "lab_photon", "photons_per_pass": 20000, **params})


def spheres_box(first: dict, second: dict, film: dict | None = None) -> mi.Scene:
    """Mitsuba's Cornell box with its two boxes replaced by spheres 'ball0' and 'ball1'."""
    d = mi.cornell_box()
    d["sensor"]["film"].update({"width": RES, "height": RES, "rfilter": {"type": "box"}, **(film or {})})
    del d["small-box"], d["large-box"]
    d["ball0"] = {"type": "sphere", "center": [-0.42, -0.6, -0.25], "radius": 0.4, "bsdf": first}
    d["ball1"] = {"type": "sphere", "center": [0.42, -0.6, 0.25], "radius": 0.4, "bsdf": second}
    return mi.load_dict(d)


def sees(scene: mi.Scene, shape_id: str) -> np.ndarray:
    """(H, W) mask of the pixels whose centre sees shape ``shape_id`` first."""
    sensor = scene.sensors()[0]
    w, h = (int(v) for v in sensor.film().crop_size())
    idx = dr.arange(mi.UInt32, w * h)
    pos = mi.Point2f((mi.Float(idx % w) + 0.5) / w, (mi.Float(idx // w) + 0.5) / h)
    ray, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5))
    hit = scene.ray_intersect(ray).shape
    want = mi.ShapePtr([s for s in scene.shapes() if s.id() == shape_id][0])
    same = dr.reinterpret_array(mi.UInt32, hit) == dr.reinterpret_array(mi.UInt32, want)
    return np.array(same).reshape(h, w)


def path_image(scene, spp, seed=1000, **params):
    return np.array(mi.render(scene, integrator=mi.load_dict({"type": "path", **params}), spp=spp, seed=seed),
                    dtype=np.float64)


def region_rel_mse(img, ref, mask):
    return rel_mse(img[mask], ref[mask])


# ------------------------------------------------------------------ mixed BSDFs


@pytest.mark.parametrize("bsdf, exact", [
    (PLASTIC, None), ({"type": "twosided", "b": PLASTIC}, None), (MASK, None),
    # blendbsdf of a delta BSDF and a smooth one: Mitsuba's own sample() adds the smooth BSDF's
    # density to the delta lobe's discrete probability, which weights its delta samples low
    # (0.552 instead of 0.6 here, also in `path`); sampled alone the delta lobes give (1 - w) x 1.
    ({"type": "blendbsdf", "weight": 0.4, "a": {"type": "conductor"}, "b": {"type": "diffuse"}}, 0.6),
])
def test_delta_lobes_sampled_alone_carry_their_share(bsdf, exact):
    """E[weight] of a sample with only the delta flags in the type mask (how camera paths go
    through a mixed BSDF) = E[weight x 1(delta lobe sampled)] with the full BSDF, or the exact
    value. 200k samples at two angles; |z| <= 5 (Welch) or 1e-3 from the exact value."""
    b = mi.load_dict(bsdf)
    n = 200_000
    for cos in (0.9, 0.3):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        si.n = mi.Normal3f(0, 0, 1)
        si.wi = mi.Vector3f(math.sqrt(1 - cos * cos), 0.0, cos)
        rng = mi.PCG32(n, dr.arange(mi.UInt64, n))
        s1, s2 = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
        alone = np.array(b.sample(mi.BSDFContext(mi.TransportMode.Radiance, DELTA_MASK), si, s1, s2)[1])[0]
        if exact is not None:
            assert abs(alone.mean() - exact) < 1e-3, (alone.mean(), exact)
            continue
        bs, w = b.sample(mi.BSDFContext(), si, s1, s2)
        full = np.array(dr.select(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta), w, 0.0))[0]
        se = math.sqrt(full.var() / n + alone.var() / n) + 1e-9
        assert abs(full.mean() - alone.mean()) <= 5 * se, (cos, full.mean(), alone.mean())


_ref = {}


def plastic_clearcoat():
    if "pc" not in _ref:
        scene = spheres_box(PLASTIC, CLEARCOAT)
        _ref["pc"] = scene, path_image(scene, 2048)
    return _ref["pc"]


def test_plastic_and_clearcoat_converge_to_path():
    """A plastic sphere (delta Fresnel reflection + diffuse) and a principled one with a clear
    coat (all lobes glossy or diffuse in Mitsuba 3.9) in the Cornell box, direct=photons, 20000
    photons per pass, seed 1, against `path` at 2048 spp (region relMSE floor ~2e-4).

    Measured (4 seeds, mean +- sd): plastic region mean / path 0.965 +- 0.036 at 8 passes,
    0.974 +- 0.008 at 64 (a diffuse sphere in its place: 0.982: the kernel's blur at the
    silhouette); region relMSE 0.0049 -> 0.0009 (8 -> 64 passes), clear coat 0.0033 -> 0.0006.
    Before the delta lobes were followed the plastic region was 20% dark at any number of
    passes (0.80 at 64 passes, 64x64); the 5% bound fails an 8% darker plastic (asserted).
    Asserted at 4 and 32 passes: region means within 5% at 32, each region's relMSE at 32 below
    0.4 x its value at 4 and below 0.004."""
    scene, ref = plastic_clearcoat()
    masks = {"plastic": sees(scene, "ball0"), "clearcoat": sees(scene, "ball1")}
    images = {p: np.array(mi.render(scene, integrator=photon(passes=p, direct="photons"), spp=1, seed=1))
              for p in (4, 32)}
    for name, mask in masks.items():
        ratio = images[32][mask].mean() / ref[mask].mean()
        assert abs(ratio - 1) < 0.05, (name, ratio)
        errors = [region_rel_mse(images[p], ref, mask) for p in (4, 32)]
        assert errors[1] < 0.4 * errors[0] and errors[1] < 0.004, (name, errors)
    dark = 0.92 * images[32][masks["plastic"]].mean() / ref[masks["plastic"]].mean()
    assert abs(dark - 1) > 0.05                     # power: an 8% darker plastic would fail


def test_partially_opaque_mask_converges_to_path():
    """A `mask` of opacity 0.5 over a diffuse BSDF (null pass-through + diffuse), direct=nee, 32
    passes: region mean within 5% of `path` (measured 0.997 at 64 passes on 64x64; before:
    0.56, the light behind the mask missing)."""
    scene = spheres_box(MASK, CLEARCOAT)
    ref = path_image(scene, 1024)
    mask = sees(scene, "ball0")
    img = np.array(mi.render(scene, integrator=photon(passes=32, direct="nee"), spp=1, seed=2))
    assert abs(img[mask].mean() / ref[mask].mean() - 1) < 0.05
    assert np.all(np.isfinite(img)) and img.min() >= 0


def test_the_planner_no_longer_leaves_photons_out_of_mixed_bsdfs():
    from mitsuba_lab.plugins.integrators.photon.estimator import PhotonMapping
    from mitsuba_lab.scene import SceneTraits

    traits = SceneTraits.from_scene(plastic_clearcoat()[0])
    assert traits.mixed_bsdfs and PhotonMapping.applicability(traits, {}) == (True, "")


# ------------------------------------------------------------------ shading normals


def tilted_floor(tilt_deg=30.0, n=4) -> mi.Mesh:
    """The Cornell floor (y = -1) as a flat grid mesh whose vertex normals lean by tilt_deg."""
    xs = np.linspace(-1, 1, n + 1)
    verts = np.array([[x, -1.0, z] for z in xs for x in xs], np.float32)
    t = math.radians(tilt_deg)
    normals = np.tile(np.array([math.sin(t), math.cos(t), 0.0], np.float32), (len(verts), 1))
    faces = []
    for i in range(n):
        for j in range(n):
            a = i * (n + 1) + j
            faces += [[a, a + n + 1, a + 1], [a + 1, a + n + 1, a + n + 2]]
    faces = np.array(faces, np.uint32)
    mesh = mi.Mesh("floor", len(verts), len(faces), has_vertex_normals=True)
    params = mi.traverse(mesh)
    params["vertex_positions"] = dr.ravel(mi.Point3f(*verts.T))
    params["vertex_normals"] = dr.ravel(mi.Normal3f(*normals.T))
    params["faces"] = dr.ravel(mi.Vector3u(*faces.T))
    params.update()
    return mesh


def test_shading_normals_match_path():
    """The box's floor as a flat mesh whose vertex normals lean 30 degrees, direct=photons, 16
    passes, against `path` at 2048 spp. Measured: floor region mean / path 0.993 (16 passes)
    and 0.988 (64); without the correction (photon flux divided by the shading cosine, no
    adjoint factor) 1.138 and 1.132. Asserted: within 4%."""
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=RES, height=RES, rfilter={"type": "box"})
    del d["small-box"], d["large-box"], d["floor"]
    d["floor"] = tilted_floor()
    scene = mi.load_dict(d)
    ref = path_image(scene, 2048)
    mask = sees(scene, "floor")
    img = np.array(mi.render(scene, integrator=photon(passes=16, direct="photons", photons_per_pass=50000),
                             spp=1, seed=3))
    assert abs(img[mask].mean() / ref[mask].mean() - 1) < 0.04, img[mask].mean() / ref[mask].mean()


# ------------------------------------------------------------------ hide_emitters


def test_hide_emitters_matches_path():
    """An area lamp in view and a constant environment, RGBA film: with hide_emitters, alpha
    (the share of pixels seeing geometry other than emitters) and the colour agree with
    `path` with hide_emitters (alpha means within 0.02, image means within 4%, relMSE < 0.02;
    measured 0.3976 vs 0.3979, 0.0818 vs 0.0812, relMSE 0.0037). Without hiding, alpha is 1."""
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 45,
                   "to_world": mi.ScalarTransform4f().look_at([0, 1.2, 3], [0, 0.2, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": RES, "height": RES, "pixel_format": "rgba",
                            "rfilter": {"type": "box"}}},
        "floor": {"type": "rectangle", "bsdf": {"type": "diffuse"},
                  "to_world": mi.ScalarTransform4f().rotate([1, 0, 0], -90).scale(1.2)},
        "ball": {"type": "sphere", "center": [0, 0.4, 0], "radius": 0.4, "bsdf": PLASTIC},
        "lamp": {"type": "rectangle", "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 6}},
                 "to_world": mi.ScalarTransform4f().translate([0.6, 0.5, 0.6]).rotate([0, 1, 0], 45).scale(0.25)},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": [0.3, 0.4, 0.5]}}})
    ref = path_image(scene, 1024, hide_emitters=True)
    img = np.array(mi.render(scene, integrator=photon(passes=16, hide_emitters=True), spp=1, seed=2))
    assert abs(img[..., 3].mean() - ref[..., 3].mean()) < 0.02 and ref[..., 3].mean() < 0.5
    assert abs(img[..., :3].mean() / ref[..., :3].mean() - 1) < 0.04
    assert rel_mse(img[..., :3], ref[..., :3]) < 0.02
    shown = np.array(mi.render(scene, integrator=photon(passes=1), spp=1, seed=2))
    assert shown[..., 3].min() == 1.0


# ------------------------------------------------------------------ variants and refusals


@pytest.fixture
def variant_switch():
    yield mitsuba_lab.use_variant
    mitsuba_lab.use_variant(HOME)


@pytest.mark.skipif(variant("ad_spectral") not in mi.variants(), reason="no spectral variant")
def test_spectral_converges_to_path(variant_switch):
    """The spectral variant, the plastic + clear-coat box, direct=nee, 32 passes (one set of 4
    wavelengths per pass), against `path` (spectral) at 2048 spp: per-channel image means
    within 4%, relMSE < 0.006 (measured on the plastic box: 1.6% max channel error and relMSE
    0.0054 at 16 passes, 0.0015 at 64; 4 passes: 13%, the colour noise of 16 wavelengths)."""
    variant_switch(variant("ad_spectral"))
    scene = spheres_box(PLASTIC, CLEARCOAT)
    ref = path_image(scene, 2048)
    img = np.array(mi.render(scene, integrator=photon(passes=32), spp=1, seed=5))
    ratio = img.mean(axis=(0, 1)) / ref.mean(axis=(0, 1))
    assert np.all(np.abs(ratio - 1) < 0.04), ratio
    assert rel_mse(img, ref) < 0.006


def check_spectral_emitters_that_importance_sample_wavelengths(variant_switch):
    """(benchmarks/agreement/test_photon_matrix.py runs it; the suite keeps spectral convergence
    above.) A blackbody area light (wavelengths importance sampled from its own spectrum, not the
    uniform map of rgb spectra): photons are still emitted at the camera's wavelengths. 24x24,
    48 passes, direct=photons, against `path` at 2048 spp: per-channel means within 4%
    (measured 0.996, 1.006, 1.002 at 4096 spp; refused before, crashed before that)."""
    variant_switch(variant("ad_spectral"))
    d = mi.cornell_box()
    d["sensor"]["film"].update({"width": 24, "height": 24, "rfilter": {"type": "box"}})
    d["light"]["emitter"]["radiance"] = {"type": "blackbody", "temperature": 3000}
    scene = mi.load_dict(d)
    ref = path_image(scene, 2048)
    img = np.array(mi.render(scene, integrator=photon(passes=48, direct="photons"), spp=1, seed=3))
    ratio = img.mean(axis=(0, 1)) / ref.mean(axis=(0, 1))
    assert np.all(np.abs(ratio - 1) < 0.04), ratio


@pytest.mark.parametrize("kind", ["ad_mono_polarized", "ad_spectral_polarized"])
def test_polarized_variants_are_refused_in_one_line(kind, variant_switch):
    name = variant(kind)
    if name not in mi.variants():
        pytest.skip(f"{name} not built")
    variant_switch(name)
    with pytest.raises(Exception) as err:
        photon()
    text = one_line(err.value)
    assert f"lab_photon: variant '{name}' is not supported: photons carry unpolarized flux" in text
    assert "\n" not in text


def test_develop_false_is_refused_in_one_line():
    scene = spheres_box(PLASTIC, CLEARCOAT, film={"width": 8, "height": 8})
    with pytest.raises(ValueError) as err:
        photon(passes=1).render(scene, develop=False)
    assert str(err.value).startswith("lab_photon: render(develop=False) is not supported") and \
        "\n" not in str(err.value)


def test_a_tiny_scene_renders_as_its_unscaled_twin():
    """scenes/stiff/scaled_1e-4.xml is the Cornell box scaled by 1e-4: with the lab's offsets
    (camera side, photons and the area light's emission rays) it renders the same image
    (measured relMSE 1e-10 between the two at 16 passes; before: 7% too bright in photons
    mode). Asserted: image means within 0.1%, relMSE < 1e-4."""
    from mitsuba_lab.scene import load_scene

    a = load_scene("scenes/cornell_box.xml", res=16)
    b = load_scene("scenes/stiff/scaled_1e-4.xml", res=16)
    for direct in ("photons", "nee"):
        ia, ib = (np.array(mi.render(s, integrator=photon(passes=2, direct=direct), spp=1, seed=2)) for s in (a, b))
        assert abs(ib.mean() / ia.mean() - 1) < 1e-3 and rel_mse(ib, ia) < 1e-4, direct
