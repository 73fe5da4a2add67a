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


def test_the_path_family_renders_media_without_a_warning(capfd):
    scene = mi.load_string(MEDIUM_SCENE)
    capfd.readouterr()
    for kind, params in (("lab_naive", {}), ("lab_nee", {}), ("lab_mis", {}), ("lab_bdpt", {}),
                         ("lab_photon", {"photons_per_pass": 1000, "passes": 1})):
        mi.render(scene, integrator=mi.load_dict({"type": kind, **params}), spp=2)
    assert "participating media" not in capfd.readouterr().out


def test_lab_photon_nested_in_a_wrapper_is_refused(tmp_path):
    scene = mi.load_file("scenes/cornell_box.xml", res=8)
    wrapped = mi.load_dict({"type": "aov", "aovs": "dd.y:depth",
                            "integrator": {"type": "lab_photon", "photons_per_pass": 1000, "passes": 1}})
    assert "lab_photon: cannot be nested inside another integrator (such as aov or moment)" in \
        render_error(scene, wrapped)
    lab = mi.load_dict({"type": "lab_photon", "photons_per_pass": 1000, "passes": 1})
    assert mi.render(scene, integrator=lab, spp=1).shape[:2] == (8, 8)       # directly: renders


def test_render_refuses_media_in_one_line(tmp_path, capfd):
    scene = tmp_path / "medium.xml"
    scene.write_text(MEDIUM_SCENE)
    # (lab_mmlt: the one lab plugin left that does not render media; lab_photon renders them since issue 46)
    code = cli.main(["render", str(scene), "--integrator", "lab_mmlt", "-o", str(tmp_path / "x.exr")])
    err = capfd.readouterr().err
    refusal = ("mitsuba-lab: error: lab_mmlt does not support participating media (the scene has a medium): "
               "use lab_mis or Mitsuba's volpath")
    assert code == 2 and err.strip() == refusal           # (no --allow-unsupported offered: its render refuses)
    code = cli.main(["render", str(scene), "--integrator", "lab_mmlt", "--allow-unsupported",
                     "-o", str(tmp_path / "x.exr")])
    err = capfd.readouterr().err
    assert code == 2 and err.strip() == refusal
    assert not (tmp_path / "x.exr").exists()
    code = cli.main(["render", str(scene), "--integrator", "path", "-o", str(tmp_path / "p.exr")])
    err = capfd.readouterr().err
    assert code == 0 and "warning: the scene has participating media" in err
    code = cli.main(["render", str(scene), "--integrator", "lab_mis", "-o", str(tmp_path / "m.exr")])
    err = capfd.readouterr().err
    assert code == 0 and "participating media" not in err       # the path family renders them


def test_render_refuses_an_estimator_that_misses_light(tmp_path, capsys):
    """lab_naive on a scene lit only by a point light would render black: refused."""
    code = cli.main(["render", "scenes/stiff/delta_lights_only.xml", "--integrator", "lab_naive",
                     "-D", "res=8", "--spp", "1", "-o", str(tmp_path / "n.exr")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("mitsuba-lab: error: lab_naive cannot reach delta lights")
    assert err.strip().endswith("(--allow-unsupported renders it anyway)") and len(err.splitlines()) == 1
    assert not (tmp_path / "n.exr").exists()
