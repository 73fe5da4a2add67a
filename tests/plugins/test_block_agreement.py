"""The block test (tests/agreement.py ``block_test``) on scenes written the way a renderer's
regression suite writes them: 64 renders a side, 6x6-pixel block means, Welch z, Sidak-corrected
alpha 0.01 over the blocks.

The material grid: twelve OBJ unit spheres from one file on a 4 x 3 grid (diffuse, PNG-textured
diffuse, a diamond, smooth plastic, two rough plastics, Beckmann and GGX rough dielectrics, a
smooth and a rough conductor, a one-sided and a two-sided masked diffuse) under a point light,
``max_depth`` 2: every path is camera -> sphere -> light, so Mitsuba's ``direct`` renders
exactly that image and is the reference. Mitsuba's ``path`` is not: it zeroes the radiance a
path gathered wherever its pixel ends up with alpha 0 (``valid_ray``), and a path that gathered
light at a mask's opaque part and then left through its null lobe and escaped is such a path; on
a one-sided masked sphere `path` renders 0.76x `direct` (``test_mitsuba_path_drops_light_...``).
The lab's estimators keep that light (path.py), as ``volpath`` and ``direct`` do.

The instanced scene: a shape group (OBJ sphere, a `sphere` scaled 0.5, a rectangle) used by
two instances, one rotated, scaled and lifted, a point light at the camera, ``max_depth`` 2:
nearly noise-free, so the block test resolves differences of 0.1%.
"""
import os

import pytest

from agreement import assert_blocks_agree, block_test, renders
from mitsuba_lab.scene import make_integrator
from user_scenes import write_assets

pytestmark = pytest.mark.slow      # statistical agreement: the full suite's tier (pytest -m "not slow" leaves it out)

SEEDS = 64
SEEDS_LAB = range(SEEDS)
SEEDS_REF = range(1000, 1000 + SEEDS)
SPP = 32

MATERIALS = (
    '<bsdf type="diffuse"><rgb name="reflectance" value="0.7 0.5 0.3"/></bsdf>',
    '<bsdf type="diffuse"><texture name="reflectance" type="bitmap">'
    '<string name="filename" value="albedo.png"/></texture></bsdf>',
    '<bsdf type="dielectric"><string name="int_ior" value="diamond"/></bsdf>',
    '<bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.2 0.4 0.7"/></bsdf>',
    '<bsdf type="roughplastic"><float name="alpha" value="0.2"/>'
    '<rgb name="diffuse_reflectance" value="0.6 0.2 0.2"/></bsdf>',
    '<bsdf type="roughplastic"><string name="distribution" value="ggx"/><float name="alpha" value="0.4"/></bsdf>',
    '<bsdf type="roughdielectric"><string name="distribution" value="beckmann"/><float name="alpha" value="0.2"/></bsdf>',
    '<bsdf type="roughdielectric"><string name="distribution" value="ggx"/><float name="alpha" value="0.3"/></bsdf>',
    '<bsdf type="conductor"><string name="material" value="Cu"/></bsdf>',
    '<bsdf type="roughconductor"><string name="material" value="Au"/><float name="alpha" value="0.25"/></bsdf>',
    '<bsdf type="mask"><float name="opacity" value="0.5"/><bsdf type="diffuse"/></bsdf>',
    '<bsdf type="mask"><float name="opacity" value="0.5"/><bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf>',
)
ONE_SIDED_MASK = MATERIALS[10]

_SENSOR = """<sensor type="perspective"><float name="fov" value="{fov}"/>
<transform name="to_world"><lookat origin="{origin}" target="{target}" up="0,1,0"/></transform>
<film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/>
<rfilter type="box"/></film></sensor>"""


def _point(position: str, intensity: float) -> str:
    x, y, z = position.split(",")
    return (f'<emitter type="point"><point name="position" x="{x}" y="{y}" z="{z}"/>'
            f'<rgb name="intensity" value="{intensity}"/></emitter>')


def material_grid(materials=MATERIALS) -> str:
    spheres = "".join(
        f'<shape type="obj"><string name="filename" value="sphere.obj"/><transform name="to_world">'
        f'<translate x="{(k % 4 - 1.5) * 3}" y="{(1 - k // 4) * 3}"/></transform>{bsdf}</shape>'
        for k, bsdf in enumerate(materials))
    return ('<scene version="3.0.0">' + _SENSOR.format(fov=45, origin="0,0,24", target="0,0,0", size=48)
            + _point("0,6,4", 300) + spheres + "</scene>")


def instanced_groups() -> str:
    group = ('<shape type="shapegroup" id="group">'
             '<shape type="obj"><string name="filename" value="sphere.obj"/>'
             '<transform name="to_world"><translate x="-1.2"/></transform>'
             '<bsdf type="diffuse"><rgb name="reflectance" value="0.7 0.4 0.3"/></bsdf></shape>'
             '<shape type="sphere"><transform name="to_world"><scale value="0.5"/><translate x="1.2"/></transform>'
             '<bsdf type="roughplastic"><float name="alpha" value="0.3"/></bsdf></shape>'
             '<shape type="rectangle"><transform name="to_world"><scale value="2.5"/><translate z="-1.5"/>'
             '</transform><bsdf type="diffuse"/></shape></shape>')
    instances = ('<shape type="instance"><ref id="group"/></shape>'
                 '<shape type="instance"><ref id="group"/><transform name="to_world"><rotate y="1" angle="45"/>'
                 '<scale value="1.5"/><translate y="2"/></transform></shape>')
    return ('<scene version="3.0.0">' + _SENSOR.format(fov=50, origin="0,1.5,9", target="0,1.5,0", size=64)
            + _point("0,1.5,9", 60) + group + instances + "</scene>")


_scenes = {}


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    return write_assets(str(tmp_path_factory.mktemp("block_assets")))


def load(assets, name: str, xml: str):
    import mitsuba as mi

    key = (name, mi.variant())
    if key not in _scenes:
        path = os.path.join(assets, f"{name}.xml")
        with open(path, "w") as f:
            f.write(xml)
        _scenes[key] = mi.load_file(path)
    return _scenes[key]


def stack(scene, kind, params, seeds, spp=SPP):
    return renders(scene, make_integrator(kind, {"max_depth": 2, **params}), spp, seeds)


_references = {}


def direct_reference(scene, key):
    if key not in _references:
        _references[key] = renders(scene, make_integrator("direct", {}), SPP, SEEDS_REF)
    return _references[key]


#: The material grid's estimators (benchmarks/agreement/test_block_agreement_matrix.py). The suite
#: keeps lab_bdpt (light tracing and every connection over all twelve materials); lab_vcm's bpt mode
#: and lab_mis, and the power proof (lab_bdpt's t = 1 weight x 1.03 fails,
#: ``check_light_tracing_bias_fails``), run in benchmarks (results:
#: experiments/results/2026-11-28-power-proofs.md).
ALL_GRID_CASES = [("lab_bdpt", {}), ("lab_vcm", {"mode": "bpt"}), ("lab_mis", {})]
GRID_CASES = ALL_GRID_CASES[:1]


@pytest.mark.parametrize("kind, params", GRID_CASES)
def test_material_grid_under_a_point_light_agrees_with_direct_lighting(assets, kind, params):
    check_grid(assets, kind, params)


def check_grid(assets, kind, params):
    """The estimator's renders of the material grid pass the block test against `direct`'s."""
    scene = load(assets, "grid", material_grid())
    assert_blocks_agree(stack(scene, kind, params, SEEDS_LAB), direct_reference(scene, "grid"),
                        f"{kind} {params} on the material grid")


def check_light_tracing_bias_fails(assets, monkeypatch):
    """Power: lab_bdpt with its light-tracing (t = 1) weights x 1.03 fails the block test on the
    material grid (a per-pixel z-test at these sample counts does not see it)."""
    from mitsuba_lab.plugins.integrators.bdpt import integrator
    from mitsuba_lab.plugins.integrators.bdpt.weights import BdptWeights

    class Perturbed(BdptWeights):
        def light_to_camera(self, *args, **kwargs):
            return 1.03 * super().light_to_camera(*args, **kwargs)

    monkeypatch.setattr(integrator, "BdptWeights", Perturbed)
    scene = load(assets, "grid", material_grid())
    result = block_test(stack(scene, "lab_bdpt", {}, SEEDS_LAB), direct_reference(scene, "grid"))
    print("t = 1 weight x 1.03:", result.summary())
    assert result.failing


#: The mask's and the instances' cases (issue 41's findings: path drops light gathered on a mask;
#: instanced groups) at 16 seeds a side, not 64 (64: benchmarks/agreement/test_block_agreement_matrix.py,
#: max |z| 1.04 and 2.77).
FINDING_SEEDS_LAB, FINDING_SEEDS_REF = range(16), range(1000, 1016)


def test_mitsuba_path_drops_light_gathered_on_a_mask(assets):
    """Why the grid's reference is `direct`: on a one-sided masked sphere Mitsuba's `path`
    renders about 0.76x `direct` (every path there is camera -> sphere -> light), lab_mis does not."""
    check_mask(assets, FINDING_SEEDS_LAB, FINDING_SEEDS_REF)


def check_mask(assets, seeds_lab, seeds_ref):
    """`path` renders the one-sided masked sphere < 0.85x `direct`; lab_mis passes the block test."""
    scene = load(assets, "mask", material_grid((ONE_SIDED_MASK,)))
    ref = renders(scene, make_integrator("direct", {}), SPP, seeds_ref)
    ratio = stack(scene, "path", {}, seeds_lab).mean() / ref.mean()
    print(f"path / direct on the masked sphere: {ratio:.3f}")
    assert ratio < 0.85, ratio
    assert_blocks_agree(stack(scene, "lab_mis", {}, seeds_lab), ref, "lab_mis on a masked sphere")


def test_instanced_shape_groups_agree_with_mitsuba_path(assets):
    check_instances(assets, FINDING_SEEDS_LAB, FINDING_SEEDS_REF)


def check_instances(assets, seeds_lab, seeds_ref):
    """lab_bdpt on the instanced shape groups passes the block test against `path`."""
    scene = load(assets, "instances", instanced_groups())
    ref = stack(scene, "path", {}, seeds_ref)
    assert_blocks_agree(stack(scene, "lab_bdpt", {}, seeds_lab), ref, "lab_bdpt on instanced shape groups")
