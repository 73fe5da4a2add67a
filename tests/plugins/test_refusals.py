"""Scenes a lab plugin cannot render are refused in one line, never rendered silently wrong."""
import mitsuba as mi
import pytest

from mitsuba_lab import cli
from mitsuba_lab.errors import one_line

MEDIUM_SCENE = """<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="2"/></sampler>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
    </sensor>
    <shape type="sphere">
        <bsdf type="null"/>
        <medium type="homogeneous" name="interior"><rgb name="albedo" value="0.8"/><float name="sigma_t" value="2"/></medium>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><translate x="0" y="3" z="0"/><rotate x="1" angle="90"/></transform>
        <emitter type="area"><rgb name="radiance" value="10"/></emitter>
    </shape>
</scene>"""


def render_error(scene, integrator) -> str:
    with pytest.raises(Exception) as err:
        mi.render(scene, integrator=integrator, spp=2)
    return one_line(err.value)


@pytest.mark.parametrize("kind, params", [("lab_naive", {}), ("lab_nee", {}), ("lab_mis", {}),
                                          ("lab_photon", {"photons_per_pass": 1000, "passes": 1})])
def test_participating_media_are_refused(kind, params):
    scene = mi.load_string(MEDIUM_SCENE)
    message = render_error(scene, mi.load_dict({"type": kind, **params}))
    assert message == (f"{kind} does not support participating media (the scene has a medium): "
                       f"use Mitsuba's volpath")


def test_lab_photon_nested_in_a_wrapper_is_refused(tmp_path):
    scene = mi.load_file("scenes/cornell_box.xml", res=8)
    wrapped = mi.load_dict({"type": "aov", "aovs": "dd.y:depth",
                            "integrator": {"type": "lab_photon", "photons_per_pass": 1000, "passes": 1}})
    assert "lab_photon: cannot be nested inside another integrator (such as aov or moment)" in \
        render_error(scene, wrapped)
    lab = mi.load_dict({"type": "lab_photon", "photons_per_pass": 1000, "passes": 1})
    assert mi.render(scene, integrator=lab, spp=1).shape[:2] == (8, 8)       # directly: renders


def test_render_refuses_media_in_one_line(tmp_path, capsys):
    scene = tmp_path / "medium.xml"
    scene.write_text(MEDIUM_SCENE)
    code = cli.main(["render", str(scene), "--integrator", "lab_mis", "-o", str(tmp_path / "x.exr")])
    err = capsys.readouterr().err
    assert code == 2 and err.strip() == ("mitsuba-lab: error: lab_mis does not support participating media "
                                         "(the scene has a medium): use Mitsuba's volpath")
    assert not (tmp_path / "x.exr").exists()
    code = cli.main(["render", str(scene), "--integrator", "path", "-o", str(tmp_path / "p.exr")])
    err = capsys.readouterr().err
    assert code == 0 and "warning: the scene has participating media" in err
