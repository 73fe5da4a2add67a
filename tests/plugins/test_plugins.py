"""The lab integrators as Mitsuba plugins: XML, counters, kernels, variants."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import mitsuba_lab
from backend import variant
from mitsuba_lab.render import render
from mitsuba_lab.scene import load_scene, make_integrator

XML = """<scene version="3.0.0">
    <integrator type="lab_mis">
        <string name="heuristic" value="balance"/>
        <float name="beta" value="1.5"/>
        <integer name="emitter_samples" value="2"/>
        <integer name="max_depth" value="5"/>
        <boolean name="count_rays" value="true"/>
    </integrator>
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
        <sampler type="independent"><integer name="sample_count" value="8"/></sampler>
    </sensor>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
    <emitter type="constant"><rgb name="radiance" value="1.0"/></emitter>
</scene>"""


def test_xml_scene_naming_lab_mis_renders(tmp_path):
    path = tmp_path / "scene.xml"
    path.write_text(XML)
    scene = mi.load_file(str(path))
    integrator = scene.integrator()
    assert type(integrator).__name__ == "LabMISIntegrator"
    assert integrator.settings()["heuristic"] == "balance" and integrator.emitter_samples == 2
    image = np.array(mi.render(scene, spp=64))
    # Furnace check: a diffuse sphere (Mitsuba's default reflectance 0.5) is convex, so under a
    # uniform unit environment it reflects exactly 0.5; the background shows the environment (1).
    assert np.allclose(image[0, 0], 1.0, atol=1e-5)
    sphere = image[5:11, 5:11, 0]
    standard_error = sphere.std(ddof=1) / np.sqrt(sphere.size)   # pixels are independent
    assert abs(sphere.mean() - 0.5) < 4 * standard_error + 1e-4


@pytest.mark.parametrize("kind", ["lab_naive", "lab_nee", "lab_mis"])
def test_ray_counters(kind):
    scene = load_scene("scenes/cornell_box.xml", res=16)
    integrator = make_integrator(kind, {"max_depth": 3})
    _, stats = render(scene, integrator, spp=4)
    rays = stats.rays
    assert rays["camera"] == 16 * 16 * 4
    # max_depth 3: at most 2 extension rays per camera ray; shadow rays only with NEE
    assert 0 < rays["extension"] <= 2 * rays["camera"]
    if kind == "lab_naive":
        assert rays["shadow"] == 0
    else:
        assert 0 < rays["shadow"] <= 3 * rays["camera"]
    assert integrator.ray_counts() == {"camera": 0, "extension": 0, "shadow": 0}    # read resets


def test_counters_can_be_switched_off():
    scene = load_scene("scenes/cornell_box.xml", res=16)
    _, stats = render(scene, make_integrator("lab_mis", {"count_rays": False}), spp=2)
    assert stats.rays == {"camera": 0, "extension": 0, "shadow": 0}


def test_changing_the_seed_reuses_the_kernel():
    # One compiled megakernel per configuration: the seed is not baked into the code.
    scene = load_scene("scenes/cornell_box.xml", res=16)
    integrator = make_integrator("lab_mis", {"max_depth": 4})
    hashes = []
    for seed in (0, 1, 2):
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()
        image = mi.render(scene, integrator=integrator, spp=4, seed=seed)
        dr.eval(image)
        dr.sync_thread()
        hashes.append(sorted(k["hash"] for k in dr.kernel_history() if "hash" in k))
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert hashes[1] == hashes[2] and len(hashes[1]) > 0
    biggest = max(hashes[1])
    assert all(biggest in h for h in hashes)


@pytest.mark.slow
def test_no_nan_inf_or_negative_pixels():
    for name in ("cornell_box.xml", "veach_mis.xml", "glossy_small_light.xml"):
        scene = load_scene(f"scenes/{name}", res=24)
        for kind, params in [("lab_naive", {}), ("lab_nee", {}), ("lab_mis", {"heuristic": "power", "beta": 10.0})]:
            image, _ = render(scene, make_integrator(kind, params), spp=16)
            assert np.isfinite(image).all() and (image >= 0).all(), (name, kind)


@pytest.mark.slow
def test_plugins_follow_a_variant_switch():
    original = mi.variant()
    try:
        mitsuba_lab.use_variant(variant("ad_mono"))
        integrator = mi.load_dict({"type": "lab_mis", "max_depth": 3})
        scene = mi.load_dict(mi.cornell_box())
        image = np.array(mi.render(scene, integrator=integrator, spp=2))
        assert image.shape[-1] == 1 and np.isfinite(image).all() and image.mean() > 0
    finally:
        mitsuba_lab.use_variant(original)
    assert mi.variant() == original
    assert type(mi.load_dict({"type": "lab_mis"})).__name__ == "LabMISIntegrator"


def test_zero_max_depth_renders_black():
    scene = load_scene("scenes/cornell_box.xml", res=8)
    image, _ = render(scene, make_integrator("lab_mis", {"max_depth": 0}), spp=2)
    assert (image == 0).all()


@pytest.mark.parametrize("params, message", [
    ({"max_depth": -2}, "'max_depth' must be -1 (unbounded) or an integer >= 0"),
    ({"rr_depth": 0}, "'rr_depth' must be an integer >= 1"),
])
def test_shared_parameter_errors(params, message):
    from mitsuba_lab.errors import LabError

    with pytest.raises(LabError, match=message.replace("(", r"\(").replace(")", r"\)")):
        make_integrator("lab_nee", params)
