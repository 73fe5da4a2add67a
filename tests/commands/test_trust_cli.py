"""The CLI's answers can be trusted: it renders what the scene says, records what it used,
checks types and configs eagerly, names the cause of every error, and has no small surprises."""
import json
import os
import subprocess
import sys

import pytest

from mitsuba_lab import cli, images

from test_cli import CORNELL, ROOT, run

USER_SCENE = """<scene version="3.0.0">
    <default name="spp" value="16"/>
    <default name="max_depth" value="6"/>
    <integrator type="lab_mis">
        <string name="heuristic" value="balance"/>
        <integer name="max_depth" value="$max_depth"/>
        {extra}
    </integrator>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="{sampler}"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/></film>
    </sensor>
    <shape type="sphere"><bsdf type="diffuse"/></shape>
    <shape type="rectangle">
        <transform name="to_world"><translate x="0" y="3" z="0"/><rotate x="1" angle="90"/></transform>
        <emitter type="area"><rgb name="radiance" value="10"/></emitter>
    </shape>
    {lights}
</scene>
"""
POINT_LIGHT = '<emitter type="point"><point name="position" x="0" y="3" z="2"/><rgb name="intensity" value="20"/></emitter>'


def user_scene(tmp_path, extra='<integer name="emitter_samples" value="2"/>', sampler="independent",
               lights="", name="user.xml"):
    path = tmp_path / name
    path.write_text(USER_SCENE.format(extra=extra, sampler=sampler, lights=lights))
    return str(path)


def header(path):
    meta = images.read_exr(str(path))[1]
    return (json.loads(meta["mitsuba_lab.params"]), json.loads(meta["mitsuba_lab.sampler"]),
            json.loads(meta["mitsuba_lab.stats"]), meta["mitsuba_lab.integrator"])


def test_render_uses_the_scenes_integrator_sampler_and_defaults(tmp_path):
    scene = user_scene(tmp_path)
    code, out, err = run(["render", scene, "-D", "spp=4", "-D", "max_depth=2", "-o", str(tmp_path / "a.exr")])
    assert code == 0, err
    params, sampler, stats, kind = header(tmp_path / "a.exr")
    assert kind == "lab_mis"
    assert (params["heuristic"], params["max_depth"], params["emitter_samples"]) == ("balance", 2, 2)
    assert sampler == {"type": "independent", "params": {"sample_count": 4}}
    assert stats["spp"] == 4 and stats["rays"]["camera"] == 24 * 16 * 4
    assert "integrator lab_mis (" in out and "heuristic=balance" in out and "max_depth=2" in out
    # the command line overrides single settings and keeps the rest
    code, out, err = run(["render", scene, "--max-depth", "3", "--spp", "2", "-o", str(tmp_path / "b.exr")])
    params, sampler, stats, _ = header(tmp_path / "b.exr")
    assert (params["heuristic"], params["max_depth"], params["emitter_samples"]) == ("balance", 3, 2)
    assert stats["rays"]["camera"] == 24 * 16 * 2
    # another type keeps the parameters it declares and names the others
    code, out, err = run(["render", scene, "--integrator", "lab_nee", "-o", str(tmp_path / "c.exr")])
    assert code == 0, err
    params, _, stats, kind = header(tmp_path / "c.exr")
    assert kind == "lab_nee" and params["max_depth"] == 6 and "heuristic" not in params
    assert "emitter_samples, heuristic do not apply to lab_nee" in err
    # another sampler keeps sample_count
    code, out, err = run(["render", scene, "--sampler", "lab_halton", "--sampler-param", "randomization=permute_digits",
                          "-o", str(tmp_path / "d.exr")])
    assert code == 0, err
    _, sampler, stats, _ = header(tmp_path / "d.exr")
    assert sampler["type"] == "lab_halton" and sampler["params"]["randomization"] == "permute_digits"
    assert stats["spp"] == 16


@pytest.mark.parametrize("argv, expected", [
    (["--param", "max_depth=abc"], "lab_mis: parameter 'max_depth' expects an integer, got 'abc'"),
    (["--param", "max_depth=8.5"], "lab_mis: parameter 'max_depth' expects an integer, got 8.5"),
    (["--param", "rr_depth=5.5"], "lab_mis: parameter 'rr_depth' expects an integer, got 5.5"),
    (["--param", "heuristc=power"], "unknown parameter 'heuristc'; valid parameters: beta, count_rays"),
    (["--seed", "-1"], "--seed: must be an integer in [0, 2^32), got -1"),
    (["--spp", "abc"], "--spp: must be a positive integer, got 'abc'"),
    (["--sampler", "lab_sobl"], "unknown sampler 'lab_sobl' (did you mean 'lab_sobol'?)"),
])
def test_typed_parameters_are_named(argv, expected, tmp_path):
    code, out, err = run(["render", user_scene(tmp_path), *argv, "-o", str(tmp_path / "x.exr")])
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and expected in lines[0], err
    assert not (tmp_path / "x.exr").exists()


def test_a_string_where_the_scene_needs_an_integer(tmp_path):
    scene = user_scene(tmp_path, extra='<string name="rr_depth" value="five"/>')
    code, _, err = run(["render", scene, "-o", str(tmp_path / "x.exr")])
    assert code == 2 and "lab_mis: parameter 'rr_depth' expects an integer, got 'five'" in err
    assert len(err.strip().splitlines()) == 1


def test_errors_inside_dr_jit_name_their_cause(tmp_path):
    """lab_zsobol out of index bits (1025^2 pixels x 2048 spp): raised inside the render's custom op."""
    scene = tmp_path / "big.xml"
    scene.write_text(USER_SCENE.format(extra="", sampler="lab_zsobol", lights="")
                     .replace('name="width" value="24"/><integer name="height" value="16"',
                              'name="width" value="1025"/><integer name="height" value="1025"'))
    code, _, err = run(["render", str(scene), "--spp", "2048", "-o", str(tmp_path / "x.exr")])
    assert code == 2 and "lab_zsobol: 1025x1025 pixels at 2048 spp need 33 > 32 index bits" in err, err
    assert "see above" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("variant, integrator, expected", [
    ("llvm_ad_mono_polarized", "lab_photon", "lab_photon: variant 'llvm_ad_mono_polarized' is not supported"),
    ("scalar_rgb", "lab_mis", "lab_mis: variant 'scalar_rgb' is not supported"),
])
@pytest.mark.slow
def test_unsupported_variants_are_one_line(variant, integrator, expected, tmp_path):
    import mitsuba as mi

    if variant not in mi.variants():
        pytest.skip(f"this Mitsuba build has no {variant}")
    proc = subprocess.run([sys.executable, "-m", "mitsuba_lab", "--variant", variant, "render", CORNELL,
                           "-D", "res=8", "--spp", "1", "--integrator", integrator, "-o", str(tmp_path / "x.exr")],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 2 and expected in proc.stderr, proc.stderr
    assert "see above" not in proc.stderr and "Traceback" not in proc.stderr


def test_outputs_honour_the_umask_and_create_their_folder(tmp_path):
    old = os.umask(0o022)
    try:
        target = tmp_path / "new" / "dir" / "x.exr"
        code, _, err = run(["render", CORNELL, "-D", "res=8", "--spp", "1", "-o", str(target)])
    finally:
        os.umask(old)
    assert code == 0, err
    assert oct(target.stat().st_mode & 0o777) == "0o644"
    assert oct((target.parent / "x.png").stat().st_mode & 0o777) == "0o644"


def test_render_refuses_an_estimator_that_cannot_see_the_light(tmp_path):
    scene = user_scene(tmp_path, lights=POINT_LIGHT)
    code, _, err = run(["render", scene, "--integrator", "lab_naive", "--spp", "1", "-o", str(tmp_path / "x.exr")])
    assert code == 2 and "error: lab_naive cannot reach delta lights (point)" in err, err
    assert "--allow-unsupported" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.exr").exists()
    code, _, err = run(["render", scene, "--integrator", "lab_naive", "--spp", "1", "--allow-unsupported",
                        "-o", str(tmp_path / "x.exr")])
    assert code == 0 and "warning: lab_naive cannot reach delta lights (point)" in err, err
    code, _, err = run(["render", scene, "--spp", "1", "-o", str(tmp_path / "y.exr")])
    assert code == 0 and "warning" not in err


def test_lab_photon_sample_count_is_camera_samples_in_all(tmp_path):
    target = tmp_path / "p.exr"
    code, out, err = run(["render", CORNELL, "-D", "res=8", "--integrator", "lab_photon", "--spp", "4",
                          "--param", "photons_per_pass=2000", "-o", str(target)])
    assert code == 0, err
    params, sampler, stats, _ = header(target)
    assert params["passes"] == 4 and sampler["params"]["sample_count"] == 1          # as in a sweep
    assert stats["spp"] == 4 and stats["rays"]["camera"] == 8 * 8 * 4
    assert stats["samples_per_second"] == pytest.approx(8 * 8 * 4 / stats["wall_s"])
    code, _, err = run(["render", CORNELL, "-D", "res=8", "--integrator", "lab_photon", "--spp", "6",
                        "--param", "passes=4", "-o", str(target)])
    assert code == 2 and "6 camera samples per pixel" in err and "not a multiple of passes = 4" in err


TYPOS = """
[experiment]
spp = [2]
repetitions = 2
[reference]
spp = 8
chunks = 2
cache = "{cache}"
[scenes.box]
path = "{scene}"
resolution = 8
[strategies]
mis = {{ type = "lab_mis", heuristc = "balance" }}
nee = {{ type = "lab_nea" }}
[samplers]
sobol = {{ type = "lab_sobl" }}
ind = {{ type = "independent", sed = 3 }}
"""


@pytest.mark.parametrize("dry_run", [True, False])
def test_sweep_reports_every_config_problem_before_rendering(dry_run, tmp_path):
    config = tmp_path / "typos.toml"
    config.write_text(TYPOS.format(cache=tmp_path / "cache", scene=CORNELL))
    out = tmp_path / "out"
    code, stdout, err = run(["sweep", str(config), "-o", str(out)] + (["--dry-run"] if dry_run else []))
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 4, err
    assert "typos.toml: strategies.mis.heuristc: lab_mis: unknown parameter 'heuristc'; " \
           "valid parameters: beta," in lines[0] and "did you mean 'heuristic'?" in lines[0]
    assert "strategies.nee.type: unknown integrator 'lab_nea' (did you mean 'lab_nee'?)" in lines[1]
    assert "samplers.sobol.type: unknown sampler 'lab_sobl' (did you mean 'lab_sobol'?)" in lines[2]
    assert "samplers.ind.sed: sampler 'independent': unknown parameter 'sed'" in lines[3]
    assert stdout == "" and not out.exists() and not (tmp_path / "cache").exists()     # nothing ran


@pytest.mark.slow
def test_a_closed_pipe_ends_quietly(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "mitsuba_lab", "sweep", "experiments/quick.toml", "--dry-run"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.readline()
    proc.stdout.close()                                  # like `| head -1`
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == cli.EXIT_PIPE
    assert "Broken pipe" not in err and "Traceback" not in err and "error" not in err, err
